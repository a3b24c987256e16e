"""Per-frame colour HS: a depth and normal for every pixel of the reference camera.

A frame's inputs (:mod:`.inputs`), the eq. (5) data term over depth hypotheses
(:mod:`.dataterm`, :mod:`.simd`) and its two sides sampled at 3D points
(:mod:`.sides`), ML HS (:mod:`.ml`, paper section III-A), Bayesian HS
(:mod:`.bayes`), the frame's reconstruction and its depth file
(:mod:`.frame`, :mod:`.options`) and why a pixel has no depth (:mod:`.drops`).
"""
