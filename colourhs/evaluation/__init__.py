"""Accuracy against ground truth.

Meshes and depth maps (:mod:`.accuracy`, :mod:`.depth_errors`) and the
photometric calibration on synthetic rigs (:mod:`.photometric_errors`).
"""
