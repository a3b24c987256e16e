"""Visual hull: silhouettes, voxel carving, the hull mesh, and depth bounds from it.

The visual hull is the largest shape consistent with every camera's
silhouette: the intersection of the silhouette cones. It bounds the object
(a true surface point is never outside it), so it gives the HS
reconstruction its depth range per pixel, seeds the Poisson stage, and is
itself the ``vh`` variant of the ablation (results contract).

Pipeline (all lengths in metres, world frame of ``rig.json``):

1. :func:`colourhs.silhouettes.silhouettes` - one boolean mask per camera, from ``masks/`` or by
   thresholding the frame (the rig has no ambient light: background is dark).
2. :func:`working_volume` - an axis-aligned box around the hull, found by a
   coarse carve of a generous box around the rig's fixation point
   (:func:`axes_centre`), or given by the caller.
3. :func:`carve_field` / :func:`carve` - a voxel grid over the box. Voxel
   ``(i, j, k)`` has its centre at ``lo + (index + 0.5) * voxel_m``.
4. :func:`hull_surface` - a closed triangle mesh by marching cubes.
5. :func:`depth_bounds` and :func:`hull_depth` - the hull seen from a camera.
6. :func:`visual_hull` - the Snakemake rule's function: all of the above for
   one frame, writing the PLY (and the ``vh`` depth HDF5) atomically.

The carving evaluates a field rather than a yes/no per voxel: at each voxel
centre, the largest over the cameras of the signed distance (metres, at the
voxel's depth) outside that camera's silhouette, from a distance transform of
the mask interpolated bilinearly (:func:`carve_field`). Its zero level is the
hull's surface to a fraction of a pixel, so marching cubes gives a smooth mesh
rather than voxel steps; :func:`carve` thresholds it at the voxel's
circumradius for a conservative occupancy.

Visibility rule (conservative): a camera votes on a voxel only if the voxel's
centre lies in front of it and projects onto its image. A voxel is kept iff
at least ``min_views`` cameras vote and every voting camera's silhouette
contains its projection. A camera never carves what it cannot see. The
default ``min_views = 2``: one view alone does not bound depth, so space that
only one camera sees is not part of the hull.

With a narrow-baseline rig (the synthetic one: three cameras about 20 degrees
apart) the hull is long along the viewing direction (0.65 m deep for a 0.25 m
statue at 0.77 m); the working volume clips it at half the working distance
around the fixation point.
"""

from __future__ import annotations

from time import perf_counter

import numpy as np

from colourhs.capture import (
    Camera,
    CaptureFormatError,
    open_dataset,
)
from colourhs.geometry import (
    backproject,
    fixation_point,
    normalised_coordinates,
    pixel_grid,
    pixels_of,
    vertex_normals,
)
from colourhs.io import sha256_files
from colourhs.ply import write_ply
from colourhs.raycast import raycasting_scene
from colourhs.silhouettes import DEFAULT_THRESHOLD, silhouette_distance, silhouettes_and_sources

__all__ = [
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
        [z, plane(inner[0], x, 1), plane(inner[1], x, -1), plane(inner[2], y, 1),
         plane(inner[3], y, -1)]
    )  # fmt: skip
    outside = np.maximum.reduce(
        [-z, plane(outer[0], x, -1), plane(outer[1], x, 1), plane(outer[2], y, -1),
         plane(outer[3], y, 1)]
    )  # fmt: skip
    return np.maximum(inside, outside)


def _camera_distance(Xc, cam, sdf, box):
    """Silhouette signed distance of points in one camera, metres at their depth.

    Parameters: camera coordinates ``Xc`` (3, N) float32, metres; the
    camera's :func:`silhouette_distance` image (pixels) and :func:`_image_box`.
    Returns (distance (N,) float32, seen (N,) bool): the signed distance
    image interpolated bilinearly at the projection, times the pixel
    footprint z / f at the point's depth. A point is seen when it lies in
    front of the camera and projects onto a pixel of the image.
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
    u0 = np.clip(np.floor(u), 0, W - 2)
    v0 = np.clip(np.floor(v), 0, H - 2)
    fu = np.clip(u - u0, 0, 1).astype(np.float32)
    fv = np.clip(v - v0, 0, 1).astype(np.float32)
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


def _field_grid(shape, views, min_views):
    """The field at every voxel of a grid, in slabs along x."""
    nx, ny, nz = shape
    field = np.empty(shape, np.float32)
    step = max(1, SLAB_VOXELS // (ny * nz))
    for i0 in range(0, nx, step):
        i1 = min(nx, i0 + step)
        index = np.indices((i1 - i0, ny, nz), np.float32).reshape(3, -1)
        index[0] += i0
        field[i0:i1] = _field_at(index, views, min_views).reshape(i1 - i0, ny, nz)
    return field


def carve_field(
    silhouettes: list[np.ndarray],
    cameras: list[Camera],
    lo,
    hi,
    voxel_m: float,
    min_views: int = 2,
    margin_px: float = 0.0,
    block: int = 4,
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

    Returns
    -------
    ndarray of float32, shape :func:`grid_shape` ``(lo, hi, voxel_m)``
        Metres; negative inside the hull, ``+inf`` where too few cameras see.
        Exact (as evaluated per voxel) within a few voxels of the outline.

    Notes
    -----
    Vectorised in batches of :data:`SLAB_VOXELS` voxels (bounded memory).
    """
    if len(silhouettes) != len(cameras):
        raise ValueError(f"{len(silhouettes)} silhouettes for {len(cameras)} cameras")
    if min_views < 1:
        raise ValueError(f"min_views must be at least 1, got {min_views}")
    lo = np.asarray(lo, float)
    shape = grid_shape(lo, hi, voxel_m)
    B = int(block)
    if B <= 1 or max(shape) < 4 * B:
        return _field_grid(shape, _views(silhouettes, cameras, lo, voxel_m, margin_px), min_views)
    nb = tuple(-(-n // B) for n in shape)
    # Per camera, at the block centres: the camera's field and whether it sees the centre.
    centre = np.indices(nb, np.float32).reshape(3, -1)
    d, seen = [], []
    for cam, sdf, box, base, step in _views(silhouettes, cameras, lo, B * voxel_m, margin_px):
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
    crossing = np.array([
        _frustum_clearance(
            np.asarray(c.R, float) @ points + np.asarray(c.t, float)[:, None],
            *_image_boxes(c, sil.shape[1], sil.shape[0]),
        ) <= radius
        for sil, c in zip(silhouettes, cameras, strict=True)
    ])  # fmt: skip
    whole = seen & ~crossing  # cameras seeing the whole block
    # Wholly outside: a camera seeing all of the block carves all of it, or too
    # few cameras can see any of it. Wholly inside: every camera sees all of it
    # or none of it, enough see it, and none comes near carving it.
    outside = np.any(whole & (d > radius), axis=0)
    outside |= (whole.sum(0) + crossing.sum(0)) < min_views
    inside = ~crossing.any(0) & (coarse < -radius)
    near = ~(outside | inside).reshape(nb)
    coarse = coarse.reshape(nb)
    field = np.repeat(np.repeat(np.repeat(coarse, B, 0), B, 1), B, 2)
    field = np.ascontiguousarray(field[: shape[0], : shape[1], : shape[2]])
    views = _views(silhouettes, cameras, lo, voxel_m, margin_px)
    offsets = np.indices((B, B, B)).reshape(3, -1).T
    blocks = np.argwhere(near)
    batch = max(1, SLAB_VOXELS // B**3)
    for b0 in range(0, len(blocks), batch):
        idx = (blocks[b0 : b0 + batch, None, :] * B + offsets[None]).reshape(-1, 3)
        idx = idx[np.all(idx < np.asarray(shape), axis=1)]
        field[idx[:, 0], idx[:, 1], idx[:, 2]] = _field_at(
            idx.T.astype(np.float32), views, min_views
        )
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
    axes = [np.asarray(cam.R, float)[2] for cam in cameras]  # optical axes, world frame
    try:
        return fixation_point(axes, [cam.centre for cam in cameras])
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
# Surface


def hull_surface(
    volume: np.ndarray, lo, voxel_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed triangle mesh of a carved volume (marching cubes, scikit-image).

    Parameters
    ----------
    volume : ndarray, shape (nx, ny, nz)
        Either a bool occupancy (:func:`carve`; meshed half-way between
        occupied and empty voxel centres) or a float field (:func:`carve_field`,
        metres, negative inside; meshed at its zero level, by linear
        interpolation: smoother and closer to the exact hull). ``+inf`` counts
        as outside.
    lo : array_like, shape (3,)
        Box corner, metres; voxel centres are at ``lo + (index + 0.5) * voxel_m``.
    voxel_m : float
        Voxel edge, metres.

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
        If the volume is empty.
    """
    from skimage.measure import marching_cubes

    vol = np.asarray(volume)
    if vol.dtype == bool:
        f = np.where(vol, -0.5, 0.5).astype(np.float32)
        outside = 0.5
    else:
        f = vol.astype(np.float32)
        finite = f[np.isfinite(f)]
        outside = float(max(finite.max(initial=0.0), voxel_m))
        f = np.where(np.isfinite(f), f, outside)
    if not (f < 0).any():
        raise ValueError("the carved volume is empty: nothing to mesh")
    # Zero padding (outside all round) closes the surface where the hull meets the box.
    padded = np.pad(f, 1, constant_values=outside)
    verts, faces, _, _ = marching_cubes(
        padded, level=0.0, spacing=(voxel_m,) * 3, allow_degenerate=False
    )
    # Padded index 1 is voxel 0, centred at lo + voxel_m / 2.
    verts = verts.astype(float) + np.asarray(lo, float) - 0.5 * voxel_m
    faces = faces.astype(np.int64)
    if mesh_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces, vertex_normals(verts, faces)


def mesh_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume (m^3) of a closed mesh; positive when triangles wind outward."""
    v = np.asarray(vertices, float)[np.asarray(triangles)]
    return float(np.sum(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2]))) / 6.0)


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
    cos = d @ np.asarray(camera.R, float)[2]  # z of the unit ray in the camera frame
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
        raise ValueError(f"visual hull depth range ({lo:.3f}, {hi:.3f}) m is not in front "
                         f"of camera {camera.name}")  # fmt: skip
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
    from colourhs.depthfile import DepthResult
    from colourhs.raycast import render_depth_normals

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


# --------------------------------------------------------------------------------------------
# Files


def visual_hull(
    dataset_dir,
    scene: str,
    frame: str | int,
    out_ply,
    voxel_m: float | None = None,
    threshold: float = DEFAULT_THRESHOLD,
    reference: str | None = None,
    out_depth_h5=None,
    bounds=None,
    min_views: int = 2,
    margin_px: float = 0.5,
) -> dict:
    """Carve one frame's visual hull and write its mesh (and the ``vh`` depth map).

    The Snakemake rule's function. Silhouettes by :func:`silhouettes`, box by
    :func:`working_volume`, field by :func:`carve_field`, mesh of its zero
    level by :func:`hull_surface`. Nothing is written unless everything
    succeeds; each file appears whole or not at all.

    Parameters
    ----------
    dataset_dir : str or Path
    scene : str
    frame : str or int
    out_ply : str or Path
        Hull mesh to write: binary PLY, world frame, metres, outward vertex normals.
    voxel_m : float, optional
        Voxel edge, metres; default :func:`default_voxel_size` (two pixel
        footprints at the working distance: 1.2 mm on the 640 x 480 demo rig).
    threshold : float
        Silhouette threshold when the scene has no masks (:func:`threshold_silhouette`).
    reference : str, optional
        Reference camera of the depth map; default the rig's first camera.
    out_depth_h5 : str or Path, optional
        Where to write the hull's depth map in the reference camera (results
        contract depth HDF5, via :func:`colourhs.depthfile.write_depth`).
    bounds : pair of array_like (3,), optional
        Explicit working volume (lo, hi), metres; default found automatically.
    min_views : int
        Fewest cameras that must see a voxel (see :func:`carve_field`).
    margin_px : float
        Silhouettes are widened by this many pixels (:func:`carve_field`). The
        default half pixel makes the hull conservative: masks sample the
        outline at pixel centres, so the true outline may lie up to half a
        pixel outside them, and every ray through a silhouette pixel's centre
        then meets the hull (it bounds the depth of every silhouette pixel).

    Returns
    -------
    dict
        ``voxel_m``, ``bounds`` ([lo, hi] metres), ``grid``, ``volume_m3``,
        ``n_vertices``, ``n_triangles``, ``silhouettes`` ("masks" or "threshold"),
        ``reference``, ``seconds``.

    Raises
    ------
    CaptureFormatError
        A silhouette is empty (naming its file), or the hull carves to nothing
        (naming the frame folder).
    """
    t0 = perf_counter()
    ds = open_dataset(dataset_dir, check_images=False, scenes=[scene])
    cams = list(ds.rig.cameras)
    ref = ds.rig.camera(reference) if reference else cams[0]
    sils, files, source = silhouettes_and_sources(ds, scene, frame, threshold)
    frame_dir = ds.frame_image(scene, frame, cams[0].name).parent
    sil_list = [sils[c.name] for c in cams]
    voxel_m = default_voxel_size(cams) if voxel_m is None else float(voxel_m)
    if bounds is not None:
        lo, hi = working_volume(sil_list, cams, voxel_m, bounds)
    else:
        try:
            lo, hi = working_volume(sil_list, cams, voxel_m, None, min_views)
        except ValueError as err:
            raise CaptureFormatError(frame_dir, f"visual hull: {err}") from None
    field = carve_field(sil_list, cams, lo, hi, voxel_m, min_views, margin_px)
    if not (field < 0).any():
        raise CaptureFormatError(
            frame_dir,
            f"the visual hull carves to nothing in the box {np.round(lo, 4).tolist()} - "
            f"{np.round(hi, 4).tolist()} m (silhouettes inconsistent with the calibration?)",
        )
    v, t, n = hull_surface(field, lo, voxel_m)
    info = {
        "voxel_m": voxel_m,
        "bounds": [lo.tolist(), hi.tolist()],
        "grid": list(field.shape),
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
        depth = hull_depth(v, t, n, ref, spec.width, spec.height, sils[ref.name])
        depth.info.update(info)
    write_ply(out_ply, v, t, n)
    if depth is not None:
        from colourhs.depthfile import write_depth

        attrs = {"method": "visual_hull", "params": depth.info, "silhouettes": source,
                 "inputs_sha256": sha256_files(files)}  # fmt: skip
        write_depth(out_depth_h5, depth, ref, attrs)
    info["seconds"] = perf_counter() - t0
    return info
