"""Accuracy against ground truth.

Meshes and depth maps (:mod:`.accuracy`, :mod:`.depth_errors`) and the
photometric calibration on synthetic rigs (:mod:`.photometric_errors`), and the
positions a tracked chromaticity map gives its points (:mod:`.tracking_errors`).
"""
