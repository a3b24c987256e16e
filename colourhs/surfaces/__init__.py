"""Surfaces from the reconstructions: silhouettes, the visual hull and Poisson meshes.

:mod:`.silhouettes`, :mod:`.carving` (the voxel field), :mod:`.hull` and
:mod:`.hull_mesh` (the visual hull), :mod:`.poisson` (oriented points and
Poisson meshes, paper section IV-A).
"""
