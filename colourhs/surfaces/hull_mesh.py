"""The visual hull as a mesh, and the hull seen from a camera.

:func:`hull_surface` meshes a carved volume (:mod:`colourhs.surfaces.carving`) by
marching cubes into a closed triangle mesh (world frame of ``rig.json``,
metres), wound outward (:func:`colourhs.common.geometry.outward_triangles`). Seen from a camera,
the hull bounds depth: :func:`depth_bounds` gives each pixel's entry and exit
z-depths, :func:`hull_depth_range` the z-depth range that reconstruction's
depth labels must cover, and :func:`hull_depth` the hull's own depth map (the
``vh`` variant of the ablation, results contract).

:mod:`colourhs.surfaces.hull` re-exports these.
"""

from __future__ import annotations

import numpy as np

from colourhs.capture import Camera
from colourhs.common.geometry import (
    axial_cosine,
    backproject,
    outward_triangles,
    pixel_grid,
    vertex_normals,
)
from colourhs.common.raycast import raycasting_scene
from colourhs.surfaces.carving import any_inside, in_slabs

__all__ = [
    "depth_bounds",
    "hull_depth",
    "hull_depth_range",
    "hull_surface",
    "march_surface",
    "outward_mesh",
]


# --------------------------------------------------------------------------------------------
# Surface


def hull_surface(
    volume: np.ndarray, lo, voxel_m: float, padded: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed triangle mesh of a carved volume (marching cubes, scikit-image).

    :func:`march_surface`, then :func:`outward_mesh`.

    Parameters
    ----------
    volume, lo, voxel_m, padded
        As :func:`march_surface`.

    Returns
    -------
    vertices : ndarray, shape (V, 3)
        World points, metres.
    triangles : ndarray of int64, shape (T, 3)
        Counter-clockwise seen from outside.
    normals : ndarray, shape (V, 3)
        Outward unit vertex normals (area-weighted face normals).

    Raises
    ------
    ValueError
        As :func:`march_surface`.
    """
    return outward_mesh(*march_surface(volume, lo, voxel_m, padded))


def march_surface(
    volume: np.ndarray, lo, voxel_m: float, padded: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The closed surface of a carved volume by marching cubes, in either winding.

    Parameters
    ----------
    volume : ndarray, shape (nx, ny, nz)
        Either a bool occupancy (:func:`~colourhs.surfaces.carving.carve`; meshed half-way
        between occupied and empty voxel centres) or a float field
        (:func:`~colourhs.surfaces.carving.carve_field`,
        metres, negative inside; meshed at its zero level, by linear
        interpolation: smoother and closer to the exact hull). ``+inf`` counts
        as outside.
    lo : array_like, shape (3,)
        Box corner, metres; voxel centres are at ``lo + (index + 0.5) * voxel_m``.
    voxel_m : float
        Voxel edge, metres.
    padded : bool
        ``volume`` is a float32 field that already has a one-voxel border of
        ``+inf`` (:func:`~colourhs.surfaces.carving.carve_field` with ``pad=1``; voxel 0
        at index 1, ``lo`` still voxel 0's box corner). It is meshed in place,
        without a copy: its non-finite values are overwritten by the outside
        level. The mesh is the same as for the unpadded field.

    Returns
    -------
    vertices : ndarray, shape (V, 3)
        World points, metres.
    triangles : ndarray of int64, shape (T, 3)
        All wound the same way, inward or outward (:func:`outward_mesh` orients them).

    Raises
    ------
    ValueError
        If the volume is empty, or ``padded`` and it is not a C-contiguous float32 array.
    """
    from skimage.measure import marching_cubes

    vol = np.asarray(volume)
    if padded and (vol.dtype != np.float32 or not vol.flags.c_contiguous):
        raise ValueError(f"a padded volume must be C-contiguous float32, got {vol.dtype}")
    # Zero padding (outside all round) closes the surface where the hull meets the box.
    f = vol if padded else _padded(vol)
    if vol.dtype == bool:
        f[~np.isfinite(f)] = 0.5
    else:
        _fill_outside(f, voxel_m)
    if not any_inside(f):
        raise ValueError("the carved volume is empty: nothing to mesh")
    verts, faces, _, _ = marching_cubes(
        f, level=0.0, spacing=(voxel_m,) * 3, allow_degenerate=False
    )
    # Padded index 1 is voxel 0, centred at lo + voxel_m / 2.
    verts = verts.astype(float) + np.asarray(lo, float) - 0.5 * voxel_m
    return verts, faces.astype(np.int64)


def outward_mesh(
    vertices: np.ndarray, triangles: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed mesh with its triangles wound outward, and its outward unit vertex normals.

    Triangles are reversed when the mesh's signed volume is negative
    (:func:`colourhs.common.geometry.outward_triangles`); normals are area-weighted face
    normals (:func:`~colourhs.common.geometry.vertex_normals`). Returns (vertices,
    triangles, normals).
    """
    triangles = outward_triangles(vertices, triangles)
    return vertices, triangles, vertex_normals(vertices, triangles)


def _padded(vol: np.ndarray) -> np.ndarray:
    """A float32 copy of a volume with a one-voxel ``+inf`` border; a bool one as -0.5 / 0.5."""
    f = np.full(tuple(n + 2 for n in vol.shape), np.inf, np.float32)
    inner = f[1:-1, 1:-1, 1:-1]
    if vol.dtype == bool:
        inner[...] = np.where(vol, np.float32(-0.5), np.float32(0.5))
    else:
        inner[...] = vol
    return f


def _fill_outside(f: np.ndarray, voxel_m: float) -> float:
    """Overwrite a field's non-finite values by the outside level, in place, slab by slab.

    The level is the largest finite value, at least ``voxel_m`` (metres). Returns it.
    """
    top = max(float(np.max(s, where=np.isfinite(s), initial=0.0)) for s in in_slabs(f))
    outside = max(top, voxel_m)
    for s in in_slabs(f):
        s[~np.isfinite(s)] = outside
    return outside


# --------------------------------------------------------------------------------------------
# The hull seen from a camera


def depth_bounds(
    vertices: np.ndarray, triangles: np.ndarray, camera: Camera, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Where each pixel's ray enters and leaves the hull: z-depth bounds for reconstruction.

    Casts the ray through every pixel centre (open3d ``RaycastingScene``):
    forward from the camera for the first hit (entry), and backward from
    beyond the hull for the last hit (exit). Between them lies every surface
    point the pixel can see (the hull contains the object).

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
        Closed hull mesh, world metres.
    triangles : ndarray of int, shape (T, 3)
    camera : Camera
    width, height : int
        Image size, pixels.

    Returns
    -------
    near, far : ndarray of float64, shape (height, width)
        z-depths (metres, along the camera's optical axis) of the entry and
        exit; NaN where the ray misses the hull.

    Notes
    -----
    Where the hull is thinner than about a voxel (near a corner of a
    silhouette, or the rim of a thin plate) marching cubes may drop it, so a
    ray grazing the object there can miss the hull or enter it late (one
    pixel in 10^4 to 10^5 on the synthetic board).
    """
    import open3d as o3d

    scene = raycasting_scene(vertices, triangles)
    grid = pixel_grid(width, height).reshape(-1, 2)
    origin, d = backproject(grid, camera.K, camera.dist, camera.R, camera.t)
    o = np.broadcast_to(origin, d.shape)
    t_in = scene.cast_rays(o3d.core.Tensor(np.hstack([o, d]).astype(np.float32)))["t_hit"]
    span = float(np.linalg.norm(np.asarray(vertices) - origin, axis=1).max()) * 1.01 + 1e-3
    back = np.hstack([o + span * d, -d]).astype(np.float32)
    t_back = scene.cast_rays(o3d.core.Tensor(back))["t_hit"].numpy().astype(float)
    t_in = t_in.numpy().astype(float)
    cos = axial_cosine(d, camera.R)
    hit = np.isfinite(t_in) & np.isfinite(t_back)
    near = np.where(hit, t_in * cos, np.nan)
    far = np.where(hit, (span - t_back) * cos, np.nan)
    return near.reshape(height, width), far.reshape(height, width)


def hull_depth_range(
    vertices: np.ndarray,
    triangles: np.ndarray,
    camera: Camera,
    width: int,
    height: int,
    margin_m: float = 0.005,
) -> tuple[float, float]:
    """The z-depth range of the hull seen from a camera: reconstruction's labels.

    The nearest entry and the farthest exit (:func:`depth_bounds`) over every
    pixel whose ray meets the hull, widened by ``margin_m`` on both sides
    (the hull's voxel tolerance). Every surface point the camera sees lies in
    it, so the depth hypotheses need not span more.

    Parameters
    ----------
    vertices, triangles, camera, width, height
        As for :func:`depth_bounds`.
    margin_m : float
        Added before the entry and after the exit, metres.

    Returns
    -------
    near, far : float
        z-depths in metres along the camera's optical axis, ``0 < near < far``.

    Raises
    ------
    ValueError
        When no pixel's ray meets the hull, or the hull is behind the camera.
    """
    near, far = depth_bounds(vertices, triangles, camera, width, height)
    hit = np.isfinite(near) & np.isfinite(far)
    if not hit.any():
        raise ValueError(f"the visual hull is not seen by camera {camera.name}")
    lo = float(near[hit].min()) - margin_m
    hi = float(far[hit].max()) + margin_m
    if not 0 < lo < hi:
        raise ValueError(
            f"visual hull depth range ({lo:.3f}, {hi:.3f}) m is not in front "
            f"of camera {camera.name}"
        )
    return lo, hi


def hull_depth(
    vertices: np.ndarray,
    triangles: np.ndarray,
    normals: np.ndarray,
    camera: Camera,
    width: int,
    height: int,
    silhouette: np.ndarray | None = None,
):
    """The hull seen from a reference camera, as a depth result (the ``vh`` variant).

    Parameters
    ----------
    vertices, triangles, normals : ndarray
        Hull mesh (:func:`hull_surface`), world metres.
    camera : Camera
        The reference camera.
    width, height : int
        Image size, pixels.
    silhouette : ndarray of bool, shape (height, width), optional
        The reference camera's silhouette: pixels outside it are left out (the
        hull's rim there is carving tolerance, not object).

    Returns
    -------
    DepthResult
        ``depth``: z of the first hit (metres, float32, NaN = none); ``normal``:
        the hull's interpolated normal facing the camera (world, unit);
        ``confidence`` 1 and ``mask`` True where the hull is hit.
    """
    from colourhs.common.depthfile import DepthResult
    from colourhs.common.raycast import render_depth_normals

    depth, nrm = render_depth_normals(vertices, triangles, normals, camera, width, height)
    mask = np.isfinite(depth)
    if silhouette is not None:
        mask &= np.asarray(silhouette, bool)
    depth[~mask] = np.nan
    nrm[~mask] = np.nan
    return DepthResult(
        depth.astype(np.float32),
        nrm.astype(np.float32),
        mask.astype(np.float32),
        mask,
        {"method": "visual_hull", "reference": camera.name, "valid_pixels": int(mask.sum())},
    )
