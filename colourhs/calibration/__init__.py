"""The calibrations of a rig from its own captures.

The cameras' intrinsics, distortion and poses from views of a ChArUco target
(:mod:`.geometric`, written into rig.json), marker poses of the board
(:mod:`.markers`), the sensor noise model (:mod:`.noise`), channel cross-talk
(:mod:`.crosstalk`, the filter mixing :mod:`.crosstalk_filter`, the LED factor
:mod:`.crosstalk_led`), the Helmholtz cameras' mu maps (:mod:`.photometric`,
paper section III-C) and the surface chromaticity p (:mod:`.chromaticity`,
section III-D); the printable targets they are captured with, the marker board
of rig.json and a ChArUco target (:mod:`.board`).
"""
