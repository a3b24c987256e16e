"""Where a tracked chromaticity map put each point, against the truth (beyond the paper).

The chromaticity tracking (:mod:`colourhs.calibration.chromaticity_tracking`) keeps, per
pixel of a frame, its point's pixel in the chromatic frame (``position``), and samples
the calibrated p there. On a synthetic sequence whose ground-truth meshes share one
triangulation (each vertex a material point, as the renderer writes them) the true
position is known (:func:`true_positions`), so the tracking's own error, in pixels, is
measured apart from the calibration's (:func:`position_summary`): a p that is wrong
because the point was put in the wrong place, or right although it was (inside a
uniform patch).
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from colourhs.common.geometry import project
from colourhs.common.raycast import cast_pixels, raycasting_scene

__all__ = ["HIDDEN_SHARE", "position_summary", "same_triangulation", "true_positions"]

HIDDEN_SHARE = 1e-4
"""A point counts as hidden in the chromatic frame where the camera's ray towards it
first meets the mesh nearer than ``1 - HIDDEN_SHARE`` of its distance: a relative
depth (0.1 mm at 1 m), so the same at any working distance, far above the float32
ray cast's rounding and far below any occluder's distance in front of a surface."""


def same_triangulation(frame_mesh, chromatic_mesh) -> bool:
    """Whether two meshes ``(vertices, triangles, ...)`` share their triangles and vertex
    count, so that a vertex of one is the same material point in the other."""
    (v1, t1), (v0, t0) = frame_mesh[:2], chromatic_mesh[:2]
    return np.shape(v1) == np.shape(v0) and np.array_equal(t1, t0)


def true_positions(frame_mesh, chromatic_mesh, camera, width: int, height: int) -> np.ndarray:
    """Each pixel's point, as a pixel (x, y) of the chromatic frame (height, width, 2).

    The pixel's ray is cast on the frame's mesh; the hit's triangle and barycentric
    weights, put on the chromatic frame's mesh, give the same material point there,
    projected into the same camera. NaN where the ray misses the mesh or the point is
    hidden in the chromatic frame (:data:`HIDDEN_SHARE`).

    Parameters
    ----------
    frame_mesh, chromatic_mesh : ``(vertices (V, 3) metres, triangles (T, 3), ...)`` of
        the frame and of the chromatic frame, one triangulation
        (:func:`same_triangulation`; ValueError otherwise).
    camera : any object with ``K``, ``dist``, ``R``, ``t`` (a rig's Camera).
    width, height : the image size, pixels.
    """
    if not same_triangulation(frame_mesh, chromatic_mesh):
        raise ValueError("the two meshes do not share one triangulation: no point correspondence")
    vf, tri = np.asarray(frame_mesh[0], float), np.asarray(frame_mesh[1]).reshape(-1, 3)
    vc = np.asarray(chromatic_mesh[0], float)
    hits = cast_pixels(vf, tri, None, camera, width, height)
    points = np.einsum("mk,mkj->mj", hits.barycentric, vc[tri[hits.triangles]])
    origin = hits.origin
    towards = points - origin
    dist = np.linalg.norm(towards, axis=1)
    rays = np.concatenate([np.broadcast_to(origin, points.shape), towards / dist[:, None]], 1)
    first = raycasting_scene(vc, tri).cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    seen = first["t_hit"].numpy() >= (1.0 - HIDDEN_SHARE) * dist
    out = np.full((height * width, 2), np.nan)
    where = np.flatnonzero(hits.hit)[seen]
    out[where] = project(points[seen], camera.K, camera.dist, camera.R, camera.t)
    return out.reshape(height, width, 2)


def position_summary(position: np.ndarray, truth: np.ndarray) -> dict:
    """How far a tracked map's positions (..., H, W, 2) are from the true ones (the same
    shape, :func:`true_positions`; leading axes pool cameras), over the pixels with a
    true position, pixels.

    Returns ``position_median_px`` and ``position_p90_px`` (the distance over the pixels
    with both), ``motion_median_px`` (how far the true position is from the pixel
    itself: the motion since the chromatic frame) and ``position_known`` (the share of
    the pixels with a true position that have a tracked one); NaN where none.
    """
    h, w = truth.shape[-3:-1]
    grid = np.broadcast_to(np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1), truth.shape)
    on = np.all(np.isfinite(truth), axis=-1)
    both = on & np.all(np.isfinite(position), axis=-1)
    err = np.linalg.norm(position[both] - truth[both], axis=-1)
    motion = np.linalg.norm(truth[on] - grid[on], axis=-1)
    nan = float("nan")
    return {
        "position_median_px": float(np.median(err)) if both.any() else nan,
        "position_p90_px": float(np.percentile(err, 90)) if both.any() else nan,
        "motion_median_px": float(np.median(motion)) if on.any() else nan,
        "position_known": float(both.sum() / on.sum()) if on.any() else nan,
    }
