"""Accuracy of reconstructions against ground truth: Hausdorff distances, error maps, metrics.

The paper (section IV-A.1) scores a reconstruction by the RMS Hausdorff
distance between the vertices of its Poisson mesh and the overlaid
ground-truth (GT) mesh, and shows the per-vertex distances as heat maps
(Figure 5). A single-view reconstruction only covers the surface its
reference camera sees, so both sides are first restricted to that **seen
region** (:func:`seen_surface`, :func:`evaluated_vertices`):

- GT: the triangles hit by the reference camera's pixel rays or with a
  vertex it sees (the grazing band at a rim that pixel rays miss), and the
  ray hits themselves (one per pixel) as samples of the seen GT;
- reconstruction: the mesh vertices visible from the reference camera that
  project onto pixels where the GT is visible (dilated by a couple of pixels,
  so that surface spilling over the silhouette's edge still counts).

The seen GT triangles are the accuracy's target; unseen sides (the back of
the object, which a one-sided reconstruction cannot have) count in neither
direction.

Reported per frame (:func:`evaluate_frame`, all in millimetres):

``hausdorff_rms_mm``, ``hausdorff_mean_mm``, ``hausdorff_max_mm``
    **Accuracy**, one direction: from each evaluated reconstruction vertex to
    the seen GT surface (the paper's "RMS Hausdorff distance").
``completeness_rms_mm``, ``completeness_mean_mm``, ``completeness_max_mm``
    **Completeness**, the other direction: from the seen GT (one sample per
    reference pixel where the GT is visible) to the whole reconstruction mesh.
``depth_median_mm``, ``depth_rms_mm``, ``depth_p95_mm``, ``normal_median_deg``, ``coverage``
    Per-pixel errors of the depth file against the GT rendered into the
    reference camera (:func:`depth_errors`); ``depth_signed_median_mm`` the
    median of the signed error (reconstructed minus true: the bias).
``depth_sigma_median_mm``, ``sigma_within_1``, ``sigma_within_2``, ``sigma_within_3``
    The depth file's 1-sigma uncertainty (``depth_sigma``) on the same pixels:
    its median, and the share of pixels whose |depth error| is at most 1, 2, 3
    sigma (0.683, 0.954, 0.997 for a calibrated sigma;
    :func:`colourhs.evaluation.depth_errors.sigma_summary`).
``expected_depth_error_mm``, ``uncertain_share``
    Without ground truth too: the median sigma over the reconstructed pixels,
    and the share of pixels flagged ``uncertain`` (sigma over the tolerance)
    among the reconstructed and flagged ones
    (:func:`colourhs.evaluation.depth_errors.uncertainty_summary`).
``reciprocity_defect_deg``
    Without ground truth too: with lights beside the lenses, the angle between
    the half-vectors of a reciprocal pair's two readings (median over the
    reconstructed points, the largest pair's; 0 with collocated lights). Eq. (3)
    then holds for matte surfaces only: on a glossy one the depth can be off by
    more than its sigma (:meth:`colourhs.capture.Rig.reciprocity_defect`).

``dropped_outside``, ``dropped_dark``, ..., ``dropped_rims``, ``dropped_other``
    Where the ground truth's pixels without a depth went: the share of the
    pixels where the ground truth is visible lost to each reason of
    :data:`colourhs.common.metrics_csv.DROP_REASONS` (the depth file's ``dropped``
    codes), and lost without one; with ``coverage`` they add to 1
    (:func:`colourhs.evaluation.depth_errors.drop_summary`).

The sigma columns are empty where the depth file has no ``depth_sigma`` or
``uncertain``, the ``dropped_*`` columns where it has no ``dropped`` (files
written before them, the visual hull).

A frame with nothing reconstructed has the empty mesh
(:func:`colourhs.surfaces.poisson.frame_mesh`): it is scored, with a warning, as
a reconstruction of nothing. Its accuracy, completeness and ``outside_share``
are empty (the distance from nothing, or to nothing, is undefined, not 0 or
infinite), ``hausdorff_samples`` is 0 and the per-pixel metrics come from its
depth file as for any frame (``coverage`` 0 where it has no depth).

Distances are point-to-surface distances from samples of one mesh to the
closest point on the other's triangles (:func:`hausdorff`, the distances of
MeshLab's Hausdorff filter, found by :func:`colourhs.common.raycast.closest_points`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d

from colourhs.common.depthfile import DepthMap, as_depth_map
from colourhs.common.files import write_json
from colourhs.common.geometry import camera_centre, project, world_to_camera
from colourhs.common.metrics_csv import (  # metrics_table: re-exported for callers of this module
    EXTRA_COLUMNS,
    REQUIRED_COLUMNS,
    metrics_table,
)
from colourhs.common.ply import load_mesh, write_ply
from colourhs.common.progress import stage
from colourhs.common.raycast import PixelHits, cast_pixels, depth_normal_maps, raycasting_scene
from colourhs.evaluation.depth_errors import depth_errors, depth_summary, uncertainty_summary

log = logging.getLogger(__name__)

__all__ = [
    "CONTRACT_COLUMNS",
    "EvaluationOptions",
    "FrameKey",
    "depth_errors",
    "depth_summary",
    "evaluate_frame",
    "evaluated_vertices",
    "hausdorff",
    "metrics_table",
    "seen_surface",
    "surface_samples",
    "visible_vertices",
]

#: The results contract's columns of ``reports/NAME/metrics.csv``, in order
#: (one definition, :mod:`colourhs.common.metrics_csv`, which the report reads too).
CONTRACT_COLUMNS = REQUIRED_COLUMNS
#: Offset (metres) of a visibility ray's start from the vertex it tests (avoids self-hits).
VISIBILITY_EPS_M = 1e-4
#: Pixels by which the GT's image mask is grown to select the evaluated vertices
#: (:func:`evaluated_vertices`): surface spilling just past the true silhouette counts.
DILATE_PX = 2


# --------------------------------------------------------------------------- distances


def surface_samples(
    vertices: np.ndarray, triangles: np.ndarray, n: int, seed: int = 0
) -> np.ndarray:
    """``n`` area-uniform random points on a triangle mesh (metres), seeded."""
    tri = np.asarray(vertices, float)[np.asarray(triangles, np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(seed)
    k = rng.choice(len(tri), int(n), p=area / area.sum())
    a, b = rng.random((2, int(n)))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    t = tri[k]
    return t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])


def hausdorff(
    vertices_a: np.ndarray,
    triangles_a: np.ndarray | None,
    vertices_b: np.ndarray,
    triangles_b: np.ndarray,
    sample_vertices: bool = True,
    n_samples: int | None = None,
    seed: int = 0,
) -> dict:
    """One-sided Hausdorff distance from mesh (or point set) a to the surface of mesh b.

    Samples of a, each with its distance to the closest point on b's
    triangles (:func:`colourhs.common.raycast.closest_points`: exact, in double
    precision, with no search radius), as MeshLab's "Hausdorff Distance"
    filter computes them.

    Parameters
    ----------
    vertices_a : ndarray, shape (Na, 3)
        Vertices of a, metres.
    triangles_a : ndarray, shape (Ta, 3), or None
        Triangles of a (None or empty: a is a point set; vertex sampling only).
    vertices_b, triangles_b : ndarray, shapes (Nb, 3), (Tb, 3)
        The target mesh, metres.
    sample_vertices : bool
        True: sample a's vertices (all of them, in order, unless ``n_samples``
        is smaller than their count: then the first ``n_samples``); False:
        ``n_samples`` random area-uniform samples on a's triangles
        (:func:`surface_samples`; default ``max(10 * Na, 10000)``).
    n_samples : int, optional
        Number of samples.
    seed : int
        Random seed of the face samples.

    Returns
    -------
    dict
        ``rms_m``, ``mean_m``, ``max_m``, ``min_m`` (metres), ``n_samples``,
        ``samples`` (n, 3) sample points on a, ``closest`` (n, 3) their
        closest points on b and ``distances`` (n,) metres; with all vertices
        sampled, ``distances[i]`` belongs to ``vertices_a[i]``.
    """
    from colourhs.common.raycast import closest_points

    va = np.asarray(vertices_a, float).reshape(-1, 3)
    if len(va) == 0:
        raise ValueError("hausdorff: mesh a has no vertices")
    if triangles_b is None or len(triangles_b) == 0:
        raise ValueError("hausdorff: target mesh b has no triangles")
    has_faces = triangles_a is not None and len(triangles_a) > 0
    if not sample_vertices and not has_faces:
        raise ValueError("hausdorff: face sampling needs triangles on mesh a")
    if sample_vertices:
        samples = va[: len(va) if n_samples is None else int(n_samples)]
    else:
        n = max(10 * len(va), 10000) if n_samples is None else int(n_samples)
        samples = surface_samples(va, triangles_a, n, seed)
    closest, d = closest_points(vertices_b, triangles_b, samples)
    return {
        "rms_m": float(np.sqrt(np.mean(d**2))),
        "mean_m": float(np.mean(d)),
        "max_m": float(np.max(d)),
        "min_m": float(np.min(d)),
        "n_samples": int(len(samples)),
        "samples": samples,
        "closest": closest,
        "distances": d,
    }


# --------------------------------------------------------------------------- seen region


def visible_vertices(
    vertices: np.ndarray,
    triangles: np.ndarray | None,
    camera,
    width: int,
    height: int,
    eps_m: float = VISIBILITY_EPS_M,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh vertices a camera sees, and the pixels they fall on.

    A vertex is visible when it is in front of the camera, projects inside
    the image and is not hidden by the mesh itself: a ray from ``eps_m`` off
    the vertex towards the camera centre hits no triangle. Unlike pixel ray
    casts this does not thin out at grazing angles (silhouette rims).

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
        World points, metres.
    triangles : ndarray, shape (T, 3), or None
        The occluding mesh (None: no occlusion test).
    camera : object with ``K``, ``dist``, ``R``, ``t``
        A :class:`colourhs.capture.Camera` or :class:`colourhs.common.depthfile.DepthMap`.
    width, height : int
        Image size, pixels.
    eps_m : float
        Start offset of the visibility rays, metres.

    Returns
    -------
    visible : ndarray of bool, shape (V,)
    pixel : ndarray of int, shape (V, 2)
        Nearest pixel (row, column) of each vertex; -1 where not visible.
    """
    v = np.asarray(vertices, float).reshape(-1, 3)
    uv = project(v, camera.K, camera.dist, camera.R, camera.t)
    ok = np.all(np.isfinite(uv), axis=1) & (world_to_camera(v, camera.R, camera.t)[:, 2] > 0)
    pixel = np.full((len(v), 2), -1)
    pixel[ok] = np.rint(uv[ok, ::-1]).astype(int)
    ok &= (pixel[:, 0] >= 0) & (pixel[:, 0] < height) & (pixel[:, 1] >= 0) & (pixel[:, 1] < width)
    if ok.any() and triangles is not None and len(triangles):
        d = camera_centre(camera.R, camera.t) - v[ok]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        rays = np.concatenate([v[ok] + eps_m * d, d], axis=1).astype(np.float32)
        hidden = raycasting_scene(v, triangles).test_occlusions(o3d.core.Tensor(rays)).numpy()
        ok[ok] = ~hidden
    pixel[~ok] = -1
    return ok, pixel


def seen_surface(
    vertices: np.ndarray,
    triangles: np.ndarray,
    camera,
    width: int,
    height: int,
    hits: PixelHits | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a camera sees of a mesh.

    Parameters
    ----------
    vertices, triangles : ndarray, shapes (V, 3), (T, 3)
        The mesh (world frame, metres).
    camera : object with ``K``, ``dist``, ``R``, ``t``
        A :class:`colourhs.capture.Camera` or :class:`colourhs.common.depthfile.DepthMap`.
    width, height : int
        Image size, pixels.
    hits : PixelHits, optional
        This mesh already cast from ``camera``'s pixels
        (:func:`colourhs.common.raycast.cast_pixels`); cast here when None.

    Returns
    -------
    seen_triangles : ndarray of bool, shape (T,)
        Triangles hit by a pixel-centre ray or with a vertex the camera sees
        (:func:`visible_vertices`; this keeps the thin grazing band at a
        silhouette rim that pixel rays miss).
    pixel_mask : ndarray of bool, shape (height, width)
        Pixels whose ray hits the mesh.
    points : ndarray, shape (M, 3)
        The hit points (one per True pixel, row-major), metres.
    """
    tri = np.asarray(triangles).reshape(-1, 3)
    if hits is None:
        hits = cast_pixels(vertices, tri, None, camera, width, height)
    seen = np.zeros(len(tri), bool)
    seen[hits.triangles] = True
    visible, _ = visible_vertices(vertices, tri, camera, width, height)
    seen |= visible[tri].any(axis=1)
    return seen, hits.hit.reshape(height, width), hits.points


def evaluated_vertices(
    vertices: np.ndarray,
    triangles: np.ndarray,
    camera,
    pixel_mask: np.ndarray,
    dilate_px: int = DILATE_PX,
) -> tuple[np.ndarray, np.ndarray]:
    """Reconstruction vertices inside the seen region, and those the camera sees.

    A vertex counts when the camera sees it (:func:`visible_vertices`) on a
    pixel of ``pixel_mask`` (where the GT is visible) dilated by ``dilate_px``
    pixels, so that surface spilling just past the true silhouette counts.

    Parameters
    ----------
    vertices, triangles : ndarray, shapes (V, 3), (T, 3)
        The reconstruction mesh (world frame, metres).
    camera : object with ``K``, ``dist``, ``R``, ``t``
        The reference camera.
    pixel_mask : ndarray of bool, shape (H, W)
        Pixels where the GT is visible (:func:`seen_surface`).
    dilate_px : int
        Dilation of ``pixel_mask``, pixels.

    Returns
    -------
    evaluated, visible : ndarrays of bool, shape (V,). Visible vertices that
    are not evaluated lie outside where the ground truth is seen: surface the
    reconstruction invented (``outside_share`` in the metrics).
    """
    h, w = pixel_mask.shape
    mask = pixel_mask
    if dilate_px > 0:  # 4-connected steps (a cross), as scipy.ndimage.binary_dilation
        cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        mask = cv2.dilate(pixel_mask.astype(np.uint8), cross, iterations=dilate_px) > 0
    visible, pixel = visible_vertices(vertices, triangles, camera, w, h)
    ok = visible.copy()
    ok[ok] = mask[pixel[ok, 0], pixel[ok, 1]]
    return ok, visible


# --------------------------------------------------------------------------- depth maps


def _mm(x):
    return None if x is None or not np.isfinite(x) else float(x) * 1e3


def _empty_metrics() -> dict:
    return {k: None for k in CONTRACT_COLUMNS[3:] + EXTRA_COLUMNS}


@dataclass(frozen=True)
class FrameKey:
    """Which reconstruction a frame's metrics belong to: their row in the metrics table.

    Each defaults to empty, an unlabelled row: labels, which no rig constrains.

    Attributes
    ----------
    scene : the scene's name (a folder of ``scenes/``).
    frame : the frame's name (``000000``...).
    variant : the reconstruction variant (``bayes_full``, ``vh``...).
    """

    scene: str = ""
    frame: str = ""
    variant: str = ""


@dataclass(frozen=True)
class EvaluationOptions:
    """How :func:`evaluate_frame` scores a frame and colours its error mesh.

    Attributes
    ----------
    vmax_mm : top of the coloured mesh's scale, millimetres. Default (None): the
        95th percentile of the frame's distances, which follows the errors of
        any rig.
    dilate_px : pixels by which the GT's image mask is grown (selects evaluated
        vertices, :func:`evaluated_vertices`). Default :data:`DILATE_PX`: in
        pixels, like the silhouette edge it forgives, whatever the rig's scale.
    completeness_samples : at most this many seen-GT samples (every k-th visible
        pixel's hit) for completeness; a count. Part of the metric's definition,
        so scores stay comparable, not a limit of the closest-point search, which
        could take them all.
    """

    vmax_mm: float | None = None
    dilate_px: int = DILATE_PX
    completeness_samples: int = 20000


def evaluate_frame(
    depth_h5: str | Path | DepthMap,
    mesh_ply: str | Path | None,
    gt_ply: str | Path | None,
    out_json: str | Path,
    out_ply: str | Path | None = None,
    key: FrameKey = FrameKey(),
    options: EvaluationOptions = EvaluationOptions(),
) -> dict:
    """Score one reconstructed frame against its ground truth (the Snakemake rule's function).

    Logs a line per step at INFO, with the seconds since the start
    (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    depth_h5 : str, Path or DepthMap
        Results-contract depth file (gives the reference camera and image size), or
        the :class:`DepthMap` already read from it
        (:func:`colourhs.common.depthfile.as_depth_map`: read once).
    mesh_ply : str or Path, optional
        The frame's Poisson mesh (``mesh/<frame>.ply``); None skips the Hausdorff metrics.
        The empty mesh (nothing reconstructed) logs a warning and leaves accuracy,
        completeness and ``outside_share`` empty, with ``hausdorff_samples`` 0.
    gt_ply : str or Path, optional
        GT mesh (``scenes/<scene>/gt/<frame>.ply``); None (a scene without ground
        truth) writes the metrics with empty (null) values.
    out_json : str or Path
        Metrics JSON to write (atomically): scene, frame, variant, the metric
        columns of :data:`CONTRACT_COLUMNS` and :data:`EXTRA_COLUMNS` (see the
        module docstring for their meaning), sizes and inputs.
    out_ply : str or Path, optional
        The reconstruction mesh coloured by each vertex's accuracy distance
        (:func:`colourhs.common.colours.value_colours`, viridis from 0 to
        ``options.vmax_mm``); grey outside the seen region or without ground truth;
        empty too (no vertices, no faces) where the mesh is.
    key : FrameKey
        Scene, frame and variant: identify the row in the metrics table.
    options : EvaluationOptions
        The colour scale's top, the mask's dilation and the completeness samples.

    Returns
    -------
    dict
        What was written to ``out_json``.
    """
    from colourhs.common.colours import value_colours

    t0 = time.perf_counter()
    say = partial(stage, log, start=t0)
    dm = as_depth_map(depth_h5)
    info = {
        "scene": str(key.scene),
        "frame": str(key.frame),
        "variant": str(key.variant),
        "method": dm.method,
        "camera": dm.camera,
    }
    info.update(_empty_metrics())
    info.update(uncertainty_summary(dm))  # needs no ground truth
    # vertices, triangles, normals; the empty mesh: a frame with nothing reconstructed
    mesh = load_mesh(mesh_ply, allow_empty=True) if mesh_ply is not None else None
    empty = mesh is not None and len(mesh[1]) == 0
    if empty:
        log.warning(
            "%s: its mesh %s is empty (nothing reconstructed): no accuracy or completeness",
            dm.path,
            mesh_ply,
        )
    dist_v = None
    if gt_ply is not None:
        say(f"evaluate: casting {dm.camera}'s {dm.width} x {dm.height} pixel rays at the GT mesh")
        gv, gt_tri, gn = load_mesh(gt_ply)
        # One cast of the GT from the reference camera's pixels serves both metrics.
        hits = cast_pixels(gv, gt_tri, gn, dm, dm.width, dm.height)
        truth = depth_normal_maps(hits, dm)
        _, _, depth_metrics = depth_errors(dm, gv, gt_tri, gn, truth=truth)
        info.update(depth_metrics)
        if empty:
            info["hausdorff_samples"] = 0  # no vertex to score
        elif mesh is not None:
            v, tri, _ = mesh
            seen, pixel_mask, gt_points = seen_surface(
                gv, gt_tri, dm, dm.width, dm.height, hits=hits
            )
            if seen.any():
                target = gt_tri[seen]
                evaluated, visible = evaluated_vertices(v, tri, dm, pixel_mask, options.dilate_px)
                dist_v = np.full(len(v), np.nan)
                info["hausdorff_samples"] = int(evaluated.sum())
                # Seen by the reference camera but off the seen ground truth: invented surface.
                info["outside_share"] = float(1.0 - evaluated.sum() / max(int(visible.sum()), 1))
                step = max(1, -(-len(gt_points) // int(options.completeness_samples)))
                say(
                    f"evaluate: accuracy of {int(evaluated.sum())} mesh vertices, "
                    f"completeness of {len(gt_points[::step])} ground-truth points"
                )
                if evaluated.any():  # the evaluated vertices as a point set, in vertex order
                    acc = hausdorff(v[evaluated], None, gv, target)
                    dist_v[evaluated] = acc["distances"]
                    info.update(
                        {
                            "hausdorff_rms_mm": _mm(acc["rms_m"]),
                            "hausdorff_mean_mm": _mm(acc["mean_m"]),
                            "hausdorff_max_mm": _mm(acc["max_m"]),
                            "hausdorff_median_mm": _mm(float(np.median(acc["distances"]))),
                        }
                    )
                comp = hausdorff(gt_points[::step], None, v, tri)
                info.update(
                    {
                        "completeness_rms_mm": _mm(comp["rms_m"]),
                        "completeness_mean_mm": _mm(comp["mean_m"]),
                        "completeness_max_mm": _mm(comp["max_m"]),
                        "completeness_samples": comp["n_samples"],
                    }
                )
    if out_ply is not None and mesh is not None:
        d_mm = np.full(len(mesh[0]), np.nan) if dist_v is None else dist_v * 1e3
        finite = d_mm[np.isfinite(d_mm)]
        top = (
            options.vmax_mm
            if options.vmax_mm is not None
            else (np.percentile(finite, 95) if finite.size else 1)
        )
        info["colour_vmax_mm"] = float(top)
        write_ply(
            out_ply,
            *mesh,
            colours=value_colours(d_mm, 0.0, float(top)),
        )
    info.update(
        {
            "mesh_vertices": None if mesh is None else int(len(mesh[0])),
            "depth_h5": dm.path,
            "mesh_ply": None if mesh_ply is None else str(mesh_ply),
            "gt_ply": None if gt_ply is None else str(gt_ply),
            "dilate_px": int(options.dilate_px),
            "completeness_max_samples": int(options.completeness_samples),
            "units": "mm; hausdorff_* = reconstruction -> seen GT (accuracy), "
            "completeness_* = seen GT -> reconstruction; outside_share = share of the "
            "mesh vertices the reference camera sees that lie off the seen GT; "
            "sigma_within_k = share of the compared pixels with |depth error| <= k "
            "depth_sigma; uncertain_share = flagged / (reconstructed + flagged) pixels; "
            "reciprocity_defect_deg in degrees; "
            "dropped_<reason> = share of the ground truth's pixels without depth for that "
            "reason (dropped_other: for none), which with coverage add to 1",
            "seconds": time.perf_counter() - t0,
        }
    )
    write_json(out_json, info)
    return info
