"""Bayesian colour HS, paper section III-E, then beyond it.

The MRF labelling (:mod:`.mrf`), the initial surface from the HS normals
(:mod:`.integrate`), the depth-normal consistency energy E over a B-spline
surface (:mod:`.surface`, :mod:`.spline`, :mod:`.gram`, minimised by
:mod:`.refine`), each surface's depth along E's valley (:mod:`.valley`) and
the depth's error bar (:mod:`.uncertainty`).
"""
