"""Synthetic datasets in the capture format, with their ground truth.

The simulated rig (:mod:`.simulated_rig`: geometry, photometric model, sensor),
image formation (:mod:`.image_formation`, the paper's eq. 4), BRDFs
(:mod:`.brdf`, :mod:`.brdfmodels`), scenes (:mod:`.scenes`), calibration-board
poses (:mod:`.poses`), the randomised rigs and scenes (:mod:`.randomrig`,
:mod:`.randomranges`, :mod:`.randomgeometry`, :mod:`.randomscenes`), whole
datasets (:mod:`.synthesise`), their ground truth (:mod:`.groundtruth`) and a
second renderer (:mod:`.mitsuba`, optional).
"""
