"""Voxel carving: the field whose zero level is the visual hull, and its occupancy.

The carving evaluates a field rather than a yes/no per voxel: at each voxel
centre, the largest over the cameras of the signed distance (metres, at the
voxel's depth) outside that camera's silhouette, from a distance transform of
the mask interpolated bilinearly (:func:`carve_field`). Its zero level is the
hull's surface to a fraction of a pixel, so marching cubes
(:func:`colourhs.surfaces.hull_mesh.hull_surface`) gives a smooth mesh rather than voxel
steps; :func:`carve` thresholds it at the voxel's circumradius for a
conservative occupancy.

Voxel ``(i, j, k)`` of a box ``[lo, hi]`` (metres, world frame of
``rig.json``) has its centre at ``lo + (index + 0.5) * voxel_m``
(:func:`grid_shape` gives the grid).

Visibility rule (conservative): a camera votes on a voxel only if the voxel's
centre lies in front of it and projects onto its image. A voxel is kept iff
at least ``min_views`` cameras vote and every voting camera's silhouette
contains its projection. A camera never carves what it cannot see. The
default ``min_views = 2``: one view alone does not bound depth, so space that
only one camera sees is not part of the hull.

The rest of the visual hull (working volume, mesh, depth bounds, the
Snakemake rule's function) is :mod:`colourhs.surfaces.hull`, which re-exports these.
"""

from __future__ import annotations

import logging

import numpy as np

from colourhs.capture import Camera
from colourhs.common.geometry import normalised_coordinates, pixels_of
from colourhs.common.progress import bar, stage
from colourhs.common.sampling import bilinear_footprint
from colourhs.surfaces.silhouettes import silhouette_distance

log = logging.getLogger(__name__)

__all__ = ["SLAB_VOXELS", "any_inside", "carve", "carve_field", "grid_shape", "in_slabs"]

SLAB_VOXELS = 1 << 20
"""Voxels projected at once by the carving (bounds its temporary memory, ~100 MB)."""

_HALF_DIAGONAL = np.sqrt(3.0) / 2.0  # circumradius of a unit cube
_GUARD = 1.25  # normalised-coordinate margin beyond the image before distortion is applied


# --------------------------------------------------------------------------------------------
# Carving


def grid_shape(lo, hi, voxel_m: float) -> tuple[int, int, int]:
    """Voxels (nx, ny, nz) covering the box ``[lo, hi]`` (metres): ``ceil((hi - lo) / voxel_m)``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
        raise ValueError(f"bounds must be two 3-vectors with hi > lo, got lo={lo}, hi={hi}")
    if not voxel_m > 0:
        raise ValueError(f"voxel size must be positive, got {voxel_m}")
    return tuple(int(n) for n in np.maximum(np.ceil((hi - lo) / voxel_m - 1e-9), 1))


def _focal(cam: Camera) -> float:
    return float(np.sqrt(cam.K[0, 0] * cam.K[1, 1]))


def _image_boxes(cam: Camera, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (xmin, xmax, ymin, ymax) in normalised coordinates around the image outline.

    Returns (inner, outer): the outline (undistorted, so slightly curved) lies
    between them.
    """
    u = np.linspace(-0.5, width - 0.5, 33)
    v = np.linspace(-0.5, height - 0.5, 25)
    sides = [
        np.stack([u, np.full_like(u, v[0])], 1),
        np.stack([u, np.full_like(u, v[-1])], 1),
        np.stack([np.full_like(v, u[0]), v], 1),
        np.stack([np.full_like(v, u[-1]), v], 1),
    ]
    top, bottom, left, right = (normalised_coordinates(e, cam.K, cam.dist) for e in sides)
    xy = np.concatenate([top, bottom, left, right])
    outer = np.array([xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()])
    inner = np.array([left[:, 0].max(), right[:, 0].min(), top[:, 1].max(), bottom[:, 1].min()])
    return inner, outer


def _image_box(cam: Camera, width: int, height: int) -> np.ndarray:
    """The outer image box widened by _GUARD about its centre (points beyond are unseen)."""
    _, box = _image_boxes(cam, width, height)
    c = np.array([box[0] + box[1], box[0] + box[1], box[2] + box[3], box[2] + box[3]]) / 2
    return c + (box - c) * _GUARD


def _frustum_clearance(Xc: np.ndarray, inner: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """Distance (metres) of camera-frame points (3, N) from the boundary of what the camera sees.

    Positive when the point is at least that far inside the inner frustum
    (``inner`` box, in front of the camera) or that far outside the outer one;
    zero or less in between.
    """
    x, y, z = Xc

    def plane(a, coord, sign):  # signed distance to the plane coord = a z, positive on `sign` side
        return sign * (coord - a * z) / np.sqrt(1 + a * a)

    inside = np.minimum.reduce(
        [
            z,
            plane(inner[0], x, 1),
            plane(inner[1], x, -1),
            plane(inner[2], y, 1),
            plane(inner[3], y, -1),
        ]
    )
    outside = np.maximum.reduce(
        [
            -z,
            plane(outer[0], x, -1),
            plane(outer[1], x, 1),
            plane(outer[2], y, -1),
            plane(outer[3], y, 1),
        ]
    )
    return np.maximum(inside, outside)


def _camera_distance(Xc, cam, sdf, box):
    """Silhouette signed distance of points in one camera, metres at their depth.

    Parameters: camera coordinates ``Xc`` (3, N) float32, metres; the
    camera's :func:`silhouette_distance` image (pixels) and :func:`_image_box`.
    Returns (distance (N,) float32, seen (N,) bool): the signed distance
    image interpolated bilinearly at the projection, times the pixel
    footprint z / f at the point's depth. A point is seen when it lies in
    front of the camera and projects onto a pixel of the image.

    Its own bilinear lerp, not :func:`colourhs.common.sampling.sample_bilinear`: it runs
    in float32 on blocks of millions of voxels (the hull's memory bound), and a
    silhouette's distance extends half a pixel beyond the image's outer pixel
    centres (clamped), where ``sample_bilinear`` gives NaN. Same weights.
    """
    H, W = sdf.shape
    z = Xc[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = Xc[0] / z, Xc[1] / z
    # Guard before distortion: the distortion polynomial can fold far-off points back in.
    ok = (z > 1e-6) & (x >= box[0]) & (x <= box[1]) & (y >= box[2]) & (y <= box[3])
    dist = np.zeros(z.shape, np.float32)
    idx = np.flatnonzero(ok)
    u, v = pixels_of(x[idx], y[idx], cam.K, cam.dist)
    inside = (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= H - 0.5)
    idx, u, v = idx[inside], u[inside], v[inside]
    ok[:] = False
    ok[idx] = True
    # Within half a pixel of the border: clamped to the border texel's value.
    _, u0, v0, fu, fv = bilinear_footprint(u, v, W, H)
    fu, fv = fu.astype(np.float32), fv.astype(np.float32)
    flat = sdf.ravel()
    i = v0.astype(np.intp) * W + u0.astype(np.intp)
    top = flat[i] + fu * (flat[i + 1] - flat[i])
    bottom = flat[i + W] + fu * (flat[i + W + 1] - flat[i + W])
    dist[idx] = (top + fv * (bottom - top)) * z[idx] * np.float32(1.0 / _focal(cam))
    return dist, ok


def _views(silhouettes, cameras, lo, voxel_m, margin_px=0.0):
    """Per camera: (camera, signed distance image, image box, base, step), for _field_at.

    A voxel index ``n`` (3,) has camera coordinates ``base + step @ n`` (metres).
    The signed distance image is :func:`silhouette_distance` less ``margin_px``.
    """
    views = []
    for sil, cam in zip(silhouettes, cameras, strict=True):
        if min(np.shape(sil)) < 2:
            raise ValueError(f"silhouette of {cam.name} is smaller than 2 x 2 pixels")
        sdf = silhouette_distance(sil) - np.float32(margin_px)
        R = np.asarray(cam.R, float)
        base = R @ (np.asarray(lo, float) + 0.5 * voxel_m) + np.asarray(cam.t, float)
        box = _image_box(cam, sdf.shape[1], sdf.shape[0])
        views.append((cam, sdf, box, base.astype(np.float32), (R * voxel_m).astype(np.float32)))
    return views


def _field_at(index: np.ndarray, views, min_views: int) -> np.ndarray:
    """The carving field (metres) at voxel indices ``index`` (3, N) float32."""
    worst = np.full(index.shape[1], -np.inf, np.float32)
    count = np.zeros(index.shape[1], np.int16)
    for cam, sdf, box, base, step in views:
        d, seen = _camera_distance(base[:, None] + step @ index, cam, sdf, box)
        np.maximum(worst, np.where(seen, d, -np.inf), out=worst)
        count += seen
    worst[count < min_views] = np.inf
    return worst


def _field_grid(field, shape, views, min_views, pad=0):
    """Fill ``field`` with the field at every voxel of a grid, in slabs along x."""
    nx, ny, nz = shape
    step = max(1, SLAB_VOXELS // (ny * nz))
    for i0 in range(0, nx, step):
        i1 = min(nx, i0 + step)
        index = np.indices((i1 - i0, ny, nz), np.float32).reshape(3, -1)
        index[0] += i0
        values = _field_at(index, views, min_views).reshape(i1 - i0, ny, nz)
        field[pad + i0 : pad + i1, pad : pad + ny, pad : pad + nz] = values
    return field


def _empty_field(shape, pad: int) -> np.ndarray:
    """A float32 grid of ``shape`` plus ``pad`` voxels all round, the border ``+inf``."""
    field = np.empty(tuple(n + 2 * pad for n in shape), np.float32)
    if pad:
        field[:pad] = field[-pad:] = np.inf
        field[:, :pad] = field[:, -pad:] = np.inf
        field[:, :, :pad] = field[:, :, -pad:] = np.inf
    return field


def _upsample_into(field, coarse, B: int, shape, pad: int) -> None:
    """Every voxel of ``field`` takes its block's value in ``coarse``, one block row at a time."""
    nx, ny, nz = shape
    for b, row in enumerate(coarse):
        plane = np.repeat(np.repeat(row, B, 0), B, 1)[:ny, :nz]
        i0, i1 = pad + b * B, pad + min(nx, (b + 1) * B)
        field[i0:i1, pad : pad + ny, pad : pad + nz] = plane


def in_slabs(a: np.ndarray, voxels: int = SLAB_VOXELS):
    """Views of ``a`` along its first axis, of about ``voxels`` elements each."""
    step = max(1, voxels // max(1, a[:1].size))
    return (a[i : i + step] for i in range(0, len(a), step))


def any_inside(field: np.ndarray) -> bool:
    """Whether any voxel of a carving field is negative (inside the hull), slab by slab."""
    return any(bool((s < 0).any()) for s in in_slabs(field))


def carve_field(
    silhouettes: list[np.ndarray],
    cameras: list[Camera],
    lo,
    hi,
    voxel_m: float,
    min_views: int = 2,
    margin_px: float = 0.0,
    block: int = 4,
    pad: int = 0,
) -> np.ndarray:
    """Distance of every voxel centre outside the visual hull (the carving's field).

    For each camera that sees a voxel centre (in front of it, projecting onto
    a pixel of its image), the signed distance from the silhouette outline at
    the projection (:func:`silhouette_distance`, pixels, interpolated
    bilinearly, less ``margin_px``) is scaled to metres by the pixel footprint
    ``z / f`` at the voxel's depth ``z``. The field is the
    largest of these over the cameras: about the distance outside the
    silhouette cone farthest away (negative inside all of them), i.e. an
    approximate signed distance to the visual hull. Voxels seen by fewer than
    ``min_views`` cameras get ``+inf``.

    Parameters
    ----------
    silhouettes : list of ndarray of bool, shape (H, W)
        One per camera, same order as ``cameras``.
    cameras : list of Camera
    lo, hi : array_like, shape (3,)
        Box corners, metres (world frame).
    voxel_m : float
        Voxel edge, metres. Voxel ``(i, j, k)`` is centred at
        ``lo + ((i, j, k) + 0.5) * voxel_m``.
    min_views : int
        Fewest cameras that must see a voxel for it to be kept.
    margin_px : float
        Widens every silhouette by this many pixels (0: the field's zero level
        is the best estimate of the exact hull; masks sampled at pixel centres
        place the true outline within half a pixel of it).
    block : int
        Coarse-to-fine block edge, voxels (1: evaluate every voxel). The field
        is first evaluated at the centres of blocks of ``block**3`` voxels; a
        block whose centre lies farther from the hull's outline than the
        block's circumradius (times 1.25 for the field's slope off-axis) plus
        one voxel and three pixel footprints is wholly inside or wholly
        outside, and its voxels take the centre's value (same sign, so the
        same occupancy and the same marching-cubes surface). So is a block
        that a camera seeing all of it carves by that much. Only blocks near
        the outline, or crossed by the edge of a camera's view (where the
        cameras voting change), are evaluated voxel by voxel.
    pad : int
        Voxels of ``+inf`` (outside) added on every side: voxel ``(i, j, k)``
        is then element ``(i + pad, j + pad, k + pad)``. With ``pad=1``,
        :func:`~colourhs.surfaces.hull_mesh.hull_surface` (``padded=True``) meshes the
        field in place instead of a padded copy.

    Returns
    -------
    ndarray of float32, shape :func:`grid_shape` ``(lo, hi, voxel_m)`` (plus ``2 * pad``)
        Metres; negative inside the hull, ``+inf`` where too few cameras see.
        Exact (as evaluated per voxel) within a few voxels of the outline.

    Notes
    -----
    Vectorised in batches of :data:`SLAB_VOXELS` voxels (bounded memory):
    besides the field itself (4 bytes a voxel), the carving holds about
    30 bytes per ``block**3`` voxels and a few hundred MB of temporaries.
    Logs a line at INFO per pass and shows bars over the cameras and the
    voxel-by-voxel batches (:mod:`colourhs.common.progress`).
    """
    if len(silhouettes) != len(cameras):
        raise ValueError(f"{len(silhouettes)} silhouettes for {len(cameras)} cameras")
    if min_views < 1:
        raise ValueError(f"min_views must be at least 1, got {min_views}")
    lo = np.asarray(lo, float)
    shape = grid_shape(lo, hi, voxel_m)
    B, pad = int(block), int(pad)
    if B <= 1 or max(shape) < 4 * B:
        views = _views(silhouettes, cameras, lo, voxel_m, margin_px)
        return _field_grid(_empty_field(shape, pad), shape, views, min_views, pad)
    nb = tuple(-(-n // B) for n in shape)
    stage(log, f"carving: coarse pass over {' x '.join(map(str, nb))} blocks")
    # Per camera, at the block centres: the camera's field and whether it sees the centre.
    centre = np.indices(nb, np.float32).reshape(3, -1)
    d, seen = [], []
    coarse_views = _views(silhouettes, cameras, lo, B * voxel_m, margin_px)
    for cam, sdf, box, base, step in bar(coarse_views, "carving: block centres", unit="camera"):
        dc, sc = _camera_distance(base[:, None] + step @ centre, cam, sdf, box)
        d.append(dc)
        seen.append(sc)
    d, seen = np.array(d), np.array(seen)
    coarse = np.where(seen, d, -np.inf).max(axis=0)
    coarse[seen.sum(0) < min_views] = np.inf
    corners = lo + np.indices((2, 2, 2)).reshape(3, -1).T * (np.asarray(nb) * B * voxel_m)
    footprint = max(
        float(np.max(corners @ np.asarray(c.R, float)[2] + c.t[2])) / _focal(c) for c in cameras
    )
    # Farthest the field can change across a block: its circumradius (times
    # 1.25 for the slope off-axis), one voxel, and the masks' pixel sampling.
    radius = 1.25 * _HALF_DIAGONAL * B * voxel_m + voxel_m + 3 * max(footprint, 0.0)
    # Cameras whose frustum boundary crosses a block see only part of it.
    points = (lo + (centre.T + 0.5) * B * voxel_m).T
    label = "carving: blocks a frustum boundary crosses"
    crossing = np.array(
        [
            _frustum_clearance(
                np.asarray(c.R, float) @ points + np.asarray(c.t, float)[:, None],
                *_image_boxes(c, sil.shape[1], sil.shape[0]),
            )
            <= radius
            for sil, c in bar(list(zip(silhouettes, cameras, strict=True)), label, unit="camera")
        ]
    )
    whole = seen & ~crossing  # cameras seeing the whole block
    # Wholly outside: a camera seeing all of the block carves all of it, or too
    # few cameras can see any of it. Wholly inside: every camera sees all of it
    # or none of it, enough see it, and none comes near carving it.
    outside = np.any(whole & (d > radius), axis=0)
    outside |= (whole.sum(0) + crossing.sum(0)) < min_views
    inside = ~crossing.any(0) & (coarse < -radius)
    near = ~(outside | inside).reshape(nb)
    del d, seen, crossing, whole, outside, inside, points, centre
    stage(
        log,
        f"carving: {int(near.sum())} of {near.size} blocks near the outline; "
        f"the field's {int(np.prod(shape))} voxels",
    )
    field = _empty_field(shape, pad)  # after the coarse pass's temporaries are gone
    _upsample_into(field, coarse.reshape(nb), B, shape, pad)
    views = _views(silhouettes, cameras, lo, voxel_m, margin_px)
    offsets = np.indices((B, B, B)).reshape(3, -1).T
    blocks = np.argwhere(near)
    batch = max(1, SLAB_VOXELS // B**3)
    starts = range(0, len(blocks), batch)
    for b0 in bar(starts, "carving near the outline", unit="batch"):
        idx = (blocks[b0 : b0 + batch, None, :] * B + offsets[None]).reshape(-1, 3)
        idx = idx[np.all(idx < np.asarray(shape), axis=1)]
        values = _field_at(idx.T.astype(np.float32), views, min_views)
        field[idx[:, 0] + pad, idx[:, 1] + pad, idx[:, 2] + pad] = values
    return field


def carve(
    silhouettes: list[np.ndarray],
    cameras: list[Camera],
    lo,
    hi,
    voxel_m: float,
    min_views: int = 2,
) -> np.ndarray:
    """Voxel occupancy of the visual hull, conservative.

    A voxel is kept iff at least ``min_views`` cameras see its centre and, in
    every one of them, the silhouette widened by half a pixel (masks sample
    the outline at pixel centres) comes within the voxel's projected
    circumradius (``sqrt(3)/2 * voxel_m`` at the voxel's depth) of the centre's
    projection: the voxel's bounding sphere meets every silhouette cone
    (:func:`carve_field` with ``margin_px=0.5``, ``<= sqrt(3)/2 * voxel_m``).
    Hence any voxel holding a point that projects inside every silhouette is
    kept: the occupied voxels contain the exact visual hull (up to the depth
    variation across a voxel), and exceed it by at most the voxel's
    circumradius plus about one pixel footprint.

    A camera the voxel projects outside of (or is behind) has no say: it
    cannot see the voxel, so it never carves it.

    Parameters
    ----------
    silhouettes, cameras, lo, hi, voxel_m, min_views
        As :func:`carve_field`.

    Returns
    -------
    ndarray of bool, shape (nx, ny, nz)
        Voxel centres at ``lo + (index + 0.5) * voxel_m``.
    """
    field = carve_field(silhouettes, cameras, lo, hi, voxel_m, min_views, margin_px=0.5)
    return field <= _HALF_DIAGONAL * voxel_m
