"""Visual hull: silhouettes, voxel carving, the hull mesh, and depth bounds from it.

The visual hull is the largest shape consistent with every camera's
silhouette: the intersection of the silhouette cones. It bounds the object
(a true surface point is never outside it), so it gives the HS
reconstruction its depth range per pixel, seeds the Poisson stage, and is
itself the ``vh`` variant of the ablation (results contract).

Pipeline (all lengths in metres, world frame of ``rig.json``):

1. :func:`colourhs.surfaces.silhouettes.silhouettes` - one boolean mask per camera, from
   ``masks/`` or by thresholding the frame (the rig has no ambient light: background is dark).
2. :func:`working_volume` - an axis-aligned box around the hull, found by a
   coarse carve of a generous box around the rig's fixation point
   (:func:`axes_centre`), or given by the caller.
3. :func:`~colourhs.surfaces.carving.carve_field` / :func:`~colourhs.surfaces.carving.carve` - a
   voxel grid over the box (:mod:`colourhs.surfaces.carving`: the carving field and
   the visibility rule). Voxel ``(i, j, k)`` has its centre at
   ``lo + (index + 0.5) * voxel_m``.
4. :func:`~colourhs.surfaces.hull_mesh.hull_surface` - a closed triangle mesh by
   marching cubes (:mod:`colourhs.surfaces.hull_mesh`).
5. :func:`~colourhs.surfaces.hull_mesh.depth_bounds` and
   :func:`~colourhs.surfaces.hull_mesh.hull_depth` - the hull seen from a camera.
6. :func:`visual_hull` - the Snakemake rule's function: all of the above for
   one frame, writing the PLY (and the ``vh`` depth HDF5) atomically.

This module holds steps 2 and 6 and re-exports steps 3 to 5, so
``colourhs.surfaces.hull`` is the whole visual hull's API.

With a narrow-baseline rig (the synthetic one: three cameras about 20 degrees
apart) the hull is long along the viewing direction (several times deeper
than the object); the working volume clips it at half the working distance
around the fixation point.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from time import perf_counter

import numpy as np

from colourhs.capture import (
    Camera,
    CaptureFormatError,
    dataset_of,
)
from colourhs.capture.rig import cameras_fixation_point
from colourhs.common.files import sha256_files
from colourhs.common.geometry import mesh_volume
from colourhs.common.ply import write_ply
from colourhs.common.progress import stage
from colourhs.surfaces.carving import _focal, any_inside, carve, carve_field, grid_shape
from colourhs.surfaces.hull_mesh import (
    depth_bounds,
    hull_depth,
    hull_depth_range,
    hull_surface,
    march_surface,
    outward_mesh,
)
from colourhs.surfaces.silhouettes import DEFAULT_THRESHOLD, silhouettes_and_sources

log = logging.getLogger(__name__)

__all__ = [
    "HullOptions",
    "axes_centre",
    "carve",
    "carve_field",
    "default_voxel_size",
    "depth_bounds",
    "grid_shape",
    "hull_depth",
    "hull_depth_range",
    "hull_surface",
    "mesh_volume",
    "visual_hull",
    "working_volume",
]


VOXEL_PIXELS = 2.0
"""Default voxel edge, in pixel footprints at the working distance."""

COARSE_VOXELS = 64
"""Voxels along each edge of the coarse carve that finds the working volume."""


# --------------------------------------------------------------------------------------------
# Working volume


def axes_centre(cameras: list[Camera]) -> np.ndarray:
    """The point nearest (least squares) to all cameras' optical axes: the rig's fixation point.

    Parameters
    ----------
    cameras : list of Camera

    Returns
    -------
    ndarray, shape (3,)
        World point, metres.

    Raises
    ------
    ValueError
        With fewer than two cameras, or optical axes (nearly) parallel.
    """
    try:
        return cameras_fixation_point(cameras)
    except ValueError as err:
        raise ValueError(f"{err}: pass explicit hull bounds") from None


def _working_distance(cameras: list[Camera]) -> tuple[np.ndarray, float]:
    centre = axes_centre(cameras)
    return centre, float(np.mean([np.linalg.norm(c.centre - centre) for c in cameras]))


def default_voxel_size(cameras: list[Camera], pixels: float = VOXEL_PIXELS) -> float:
    """Voxel edge of ``pixels`` pixel footprints at the rig's working distance, metres.

    The working distance is the mean distance from the cameras to
    :func:`axes_centre`; a pixel's footprint there is that distance over the
    mean focal length (pixels). At two footprints (the default) the carving
    field, interpolated from the masks' distance transforms, still places
    the surface to a fraction of a pixel, at an eighth of the memory and
    work of one footprint; features thinner than a voxel are lost.
    """
    _, dist = _working_distance(cameras)
    return float(pixels * dist / np.mean([_focal(c) for c in cameras]))


def working_volume(
    silhouettes: list[np.ndarray],
    cameras: list[Camera],
    voxel_m: float,
    bounds=None,
    min_views: int = 2,
    extent_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box (lo, hi) holding the visual hull, metres.

    With ``bounds`` given, returns them (checked). Otherwise carves a cube of
    half-edge ``extent_m`` (default: half the working distance) around
    :func:`axes_centre` with :data:`COARSE_VOXELS` voxels per edge, and
    returns the bounding box of the occupied voxels, widened by one coarse
    voxel plus two ``voxel_m`` (the coarse carve is conservative, so the fine
    hull lies inside). A hull reaching the cube's faces (narrow-baseline rigs
    bound depth poorly) is clipped there.

    Parameters
    ----------
    silhouettes, cameras, min_views
        As :func:`carve_field`.
    voxel_m : float
        The fine voxel edge, metres (sets the margin).
    bounds : pair of array_like (3,), optional
        Explicit (lo, hi), metres.
    extent_m : float, optional
        Half-edge of the searched cube, metres.

    Returns
    -------
    lo, hi : ndarray, shape (3,)

    Raises
    ------
    ValueError
        If the coarse carve leaves nothing (silhouettes inconsistent with the
        calibration, or the object outside the searched cube).
    """
    if bounds is not None:
        lo, hi = (np.asarray(b, float).reshape(-1) for b in bounds)
        grid_shape(lo, hi, voxel_m)
        return lo, hi
    centre, dist = _working_distance(cameras)
    half = 0.5 * dist if extent_m is None else float(extent_m)
    lo, hi = centre - half, centre + half
    coarse = 2 * half / COARSE_VOXELS
    occ = carve(silhouettes, cameras, lo, hi, coarse, min_views)
    if not occ.any():
        raise ValueError(
            f"the coarse visual hull in the cube of half-edge {half:.3f} m around "
            f"{np.round(centre, 3).tolist()} is empty: silhouettes inconsistent with the "
            "calibration?"
        )
    idx = np.argwhere(occ)
    margin = coarse + 2 * voxel_m
    new_lo = lo + idx.min(0) * coarse - margin
    new_hi = lo + (idx.max(0) + 1) * coarse + margin
    return np.maximum(new_lo, lo), np.minimum(new_hi, hi)


# --------------------------------------------------------------------------------------------
# Files


@dataclass(frozen=True)
class HullOptions:
    """How :func:`visual_hull` carves: voxel size, silhouettes, views and the box.

    Attributes
    ----------
    voxel_m : voxel edge, metres. Default (None) :func:`default_voxel_size`: two
        pixel footprints at the working distance, so it follows any rig's
        distance and focal length.
    threshold : silhouette threshold when the scene has no masks
        (:func:`colourhs.surfaces.silhouettes.threshold_silhouette`), a fraction
        of full scale on the largest channel. Default
        :data:`colourhs.surfaces.silhouettes.DEFAULT_THRESHOLD`: the rig has no
        ambient light, so the background is dark on any rig.
    min_views : fewest cameras that must see a voxel (see :func:`carve_field`);
        a count. Default 2: the fewest that bound a point in depth, on any rig.
    margin_px : silhouettes are widened by this many pixels (:func:`carve_field`).
        The default half pixel makes the hull conservative on any rig: masks
        sample the outline at pixel centres, so the true outline may lie up to
        half a pixel outside them, and every ray through a silhouette pixel's
        centre then meets the hull (it bounds the depth of every silhouette pixel).
    bounds : explicit working volume (lo, hi), each array_like (3,), metres.
        Default (None) found by :func:`working_volume` around the rig's fixation
        point, at half the working distance: relative to any rig.
    """

    voxel_m: float | None = None
    threshold: float = DEFAULT_THRESHOLD
    min_views: int = 2
    margin_px: float = 0.5
    bounds: tuple | None = None


def visual_hull(
    dataset_dir,
    scene: str,
    frame: str | int,
    out_ply,
    options: HullOptions = HullOptions(),
    reference: str | None = None,
    out_depth_h5=None,
) -> dict:
    """Carve one frame's visual hull and write its mesh (and the ``vh`` depth map).

    The Snakemake rule's function. Silhouettes by :func:`silhouettes`, box by
    :func:`working_volume`, field by :func:`carve_field`, mesh of its zero
    level by :func:`hull_surface`. Nothing is written unless everything
    succeeds; each file appears whole or not at all. Logs one line per stage at
    INFO, with the seconds since the start, and shows bars over the carving
    (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    dataset_dir : str, Path or Dataset
    scene : str
    frame : str or int
    out_ply : str or Path
        Hull mesh to write: binary PLY, world frame, metres, outward vertex normals.
    options : HullOptions
        Voxel edge, silhouette threshold, views, silhouette margin and working
        volume of the carving.
    reference : str, optional
        Reference camera of the depth map; default the rig's first camera.
    out_depth_h5 : str or Path, optional
        Where to write the hull's depth map in the reference camera (results
        contract depth HDF5, via :func:`colourhs.common.depthfile.write_depth`).

    Returns
    -------
    dict
        ``voxel_m``, ``bounds`` ([lo, hi] metres), ``grid``, ``volume_m3``,
        ``n_vertices``, ``n_triangles``, ``silhouettes`` ("masks" or "threshold"),
        ``min_views``, ``margin_px``, ``reference``, ``seconds``.

    Raises
    ------
    CaptureFormatError
        A silhouette is empty (naming its file), or the hull carves to nothing
        (naming the frame folder).
    """
    t0 = perf_counter()
    ds = dataset_of(dataset_dir, scenes=[scene])
    cams = list(ds.rig.cameras)
    ref = ds.rig.camera(reference) if reference else cams[0]
    frame_dir = ds.frame_image(scene, frame, cams[0].name).parent  # an unknown frame: refused
    say = partial(stage, log, start=t0)
    say(f"visual hull {scene}/{frame}: silhouettes of {len(cams)} views")
    sils, files, source = silhouettes_and_sources(ds, scene, frame, options.threshold)
    sil_list = [sils[c.name] for c in cams]
    voxel_m = default_voxel_size(cams) if options.voxel_m is None else float(options.voxel_m)
    min_views, margin_px = options.min_views, options.margin_px
    if options.bounds is not None:
        lo, hi = working_volume(sil_list, cams, voxel_m, options.bounds)
    else:
        say("visual hull: working volume (coarse carve)")
        try:
            lo, hi = working_volume(sil_list, cams, voxel_m, None, min_views)
        except ValueError as err:
            raise CaptureFormatError(frame_dir, f"visual hull: {err}") from None
    shape = grid_shape(lo, hi, voxel_m)
    h, w = sil_list[0].shape
    say(
        f"visual hull: carving {' x '.join(map(str, shape))} voxels of "
        f"{voxel_m * 1e3:.2f} mm from {len(cams)} views of {w} x {h}"
    )
    # One voxel of padding: hull_surface meshes the field in place (no copy of the grid).
    field = carve_field(sil_list, cams, lo, hi, voxel_m, min_views, margin_px, pad=1)
    if not any_inside(field):
        raise CaptureFormatError(
            frame_dir,
            f"the visual hull carves to nothing in the box {np.round(lo, 4).tolist()} - "
            f"{np.round(hi, 4).tolist()} m (silhouettes inconsistent with the calibration?)",
        )
    say("visual hull: marching cubes")
    v, t = march_surface(field, lo, voxel_m, padded=True)
    del field  # before outward_mesh's temporaries (large at paper scale)
    say(f"visual hull: orienting {len(t)} triangles outwards")
    v, t, n = outward_mesh(v, t)
    info = {
        "voxel_m": voxel_m,
        "bounds": [lo.tolist(), hi.tolist()],
        "grid": list(shape),
        "volume_m3": mesh_volume(v, t),
        "n_vertices": len(v),
        "n_triangles": len(t),
        "silhouettes": source,
        "min_views": min_views,
        "margin_px": margin_px,
        "reference": ref.name,
    }
    depth = None
    if out_depth_h5 is not None:
        spec = ds.rig.image
        say(f"visual hull: {len(v)} vertices; depth map in {ref.name}")
        depth = hull_depth(v, t, n, ref, spec.width, spec.height, sils[ref.name])
        depth.info.update(info)
    say(
        f"visual hull: writing {Path(out_ply).name}"
        + (" and its depth map" if depth is not None else "")
    )
    write_ply(out_ply, v, t, n)
    if depth is not None:
        from colourhs.common.depthfile import write_depth

        attrs = {
            "method": "visual_hull",
            "params": depth.info,
            "silhouettes": source,
            "inputs_sha256": sha256_files(files),
        }
        write_depth(out_depth_h5, depth, ref, attrs)
    info["seconds"] = perf_counter() - t0
    say("visual hull: written")
    return info
