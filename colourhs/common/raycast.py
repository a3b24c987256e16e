"""Ray casting a triangle mesh into a camera (open3d): depth and normals per pixel
(ground truth for evaluation and tests), the surface points a rig sees and lights,
and the closest point of a mesh to each of many points (evaluation distances).

Meshes are read by :func:`colourhs.common.ply.load_mesh`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from colourhs.capture import Camera
from colourhs.common.geometry import backproject, pixel_grid, world_to_camera


def raycasting_scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    """An open3d ray-casting scene of a triangle mesh (vertices (V, 3) metres, triangles (T, 3))."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(vertices, np.float32).reshape(-1, 3)),
        o3d.core.Tensor(np.asarray(triangles, np.uint32).reshape(-1, 3)),
    )
    return scene


def closest_on_triangles(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Closest point of triangle (a, b, c) to each point, in float64.

    The nearer of the point's projection onto the triangle's plane (when it
    falls inside the triangle) and its closest points on the three edges;
    degenerate (zero-area) triangles reduce to their edges. Compiled
    (numba, :mod:`colourhs.common.closest_point`), one point at a time.

    Parameters
    ----------
    points, a, b, c : ndarray, shape (N, 3)
        Query points and the corners of each point's triangle, metres.

    Returns
    -------
    ndarray, shape (N, 3)
        The closest points, metres.
    """
    from colourhs.common.closest_point import closest_each

    p, a, b, c = (np.ascontiguousarray(x, np.float64).reshape(-1, 3) for x in (points, a, b, c))
    out = np.empty_like(p)
    closest_each(p, a, b, c, out)
    return out


def closest_points(
    vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on a triangle mesh to each of many points, with double-precision distances.

    open3d's bounding-volume search (``RaycastingScene.compute_closest_points``,
    single precision, in coordinates centred on the mesh) finds each point's
    closest triangle; the closest point is then recomputed in float64
    (:func:`closest_on_triangles`' formulas, compiled) on that triangle and
    on every triangle sharing a corner with it, where single precision can
    pick the wrong one of two nearly equidistant neighbours.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
        The mesh's vertices, metres.
    triangles : ndarray, shape (T, 3)
        Its triangles (vertex indices).
    points : ndarray, shape (N, 3)
        Query points, metres.

    Returns
    -------
    closest : ndarray, shape (N, 3)
        The closest point on the mesh to each point, metres.
    distances : ndarray, shape (N,)
        Their distances, metres.
    """
    from colourhs.common.closest_point import closest_near

    v = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
    tri = np.ascontiguousarray(triangles, np.int64).reshape(-1, 3)
    p = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
    origin = 0.5 * (v.min(axis=0) + v.max(axis=0))
    scene = raycasting_scene(v - origin, tri)
    query = o3d.core.Tensor(np.ascontiguousarray(p - origin, np.float32))
    first = scene.compute_closest_points(query)["primitive_ids"].numpy().astype(np.int64)
    # The triangles at each vertex (CSR, in increasing triangle order).
    flat = tri.ravel()
    order = np.argsort(flat, kind="stable")
    around = order // 3
    start = np.searchsorted(flat[order], np.arange(len(v) + 1))
    closest, d = np.empty_like(p), np.empty(len(p))
    closest_near(p, v, tri, first, start, around, closest, d)
    return closest, d


def pixel_rays(camera, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """World rays through every pixel centre of a camera, row-major.

    ``camera``: any object with ``K``, ``dist``, ``R``, ``t`` (a Camera or a
    DepthMap); ``width``, ``height``: the image size, pixels.

    Returns
    -------
    origin : ndarray, shape (3,)
        The camera centre, metres.
    directions : ndarray, shape (height * width, 3)
        Unit ray directions (world frame).
    """
    grid = pixel_grid(width, height).reshape(-1, 2)
    return backproject(grid, camera.K, camera.dist, camera.R, camera.t)


@dataclass(frozen=True)
class PixelHits:
    """A mesh ray cast from every pixel centre of a camera (:func:`cast_pixels`).

    ``hit`` is row-major (height * width,); the other arrays have one row per
    hit, in the same order.
    """

    scene: o3d.t.geometry.RaycastingScene
    origin: np.ndarray  # (3,) the camera centre, metres
    hit: np.ndarray  # (H*W,) bool
    points: np.ndarray  # (M, 3) hit points on the mesh, metres
    normals: np.ndarray | None  # (M, 3) interpolated unit normals facing the camera
    triangles: np.ndarray  # (M,) index of the triangle hit
    barycentric: np.ndarray  # (M, 3) the hit's weights of that triangle's vertices
    width: int
    height: int


def cast_pixels(vertices, triangles, normals, camera, width: int, height: int) -> PixelHits:
    """Ray cast a mesh from every pixel centre of a camera.

    ``vertices`` (V, 3) metres, ``triangles`` (T, 3), ``normals`` (V, 3) unit
    vertex normals or None (then ``PixelHits.normals`` is None); ``camera``:
    any object with ``K``, ``dist``, ``R``, ``t``. One cast serves every use
    of the same mesh and camera (the evaluation's depth errors and its seen
    region).
    """
    vertices = np.asarray(vertices, float)
    triangles = np.asarray(triangles).reshape(-1, 3)
    scene = raycasting_scene(vertices, triangles)
    origin, dirs = pixel_rays(camera, width, height)
    rays = np.concatenate([np.broadcast_to(origin, dirs.shape), dirs], axis=1)
    ans = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    hit = np.isfinite(ans["t_hit"].numpy())
    tri = ans["primitive_ids"].numpy()[hit].astype(np.int64)
    uv = ans["primitive_uvs"].numpy()[hit].astype(float)
    bary = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    points = np.einsum("mk,mkj->mj", bary, vertices[triangles[tri]])
    n = None
    if normals is not None:
        n = np.einsum("mk,mkj->mj", bary, np.asarray(normals, float)[triangles[tri]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        n *= np.sign(np.sum(n * (origin - points), axis=1))[:, None]
    return PixelHits(scene, origin, hit, points, n, tri, bary, int(width), int(height))


def depth_normal_maps(hits: PixelHits, camera) -> tuple[np.ndarray, np.ndarray]:
    """z-depth (H, W) in metres and world unit normals (H, W, 3) of a cast; NaN where none.

    ``camera`` is the one ``hits`` was cast from (its ``R``, ``t`` give z).
    """
    n_px = hits.width * hits.height
    depth = np.full(n_px, np.nan)
    depth[hits.hit] = world_to_camera(hits.points, camera.R, camera.t)[:, 2]
    nrm = np.full((n_px, 3), np.nan)
    if hits.normals is not None:
        nrm[hits.hit] = hits.normals
    return depth.reshape(hits.height, hits.width), nrm.reshape(hits.height, hits.width, 3)


def render_depth_normals(
    vertices: np.ndarray,
    triangles: np.ndarray,
    normals: np.ndarray,
    camera: Camera,
    width: int,
    height: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth in a camera: z-depth (H, W) in metres and world unit normals (H, W, 3).

    Ray casts the mesh from every pixel centre; NaN where a ray misses.
    Normals are the mesh's interpolated vertex normals, facing the camera.
    """
    hits = cast_pixels(vertices, triangles, normals, camera, width, height)
    return depth_normal_maps(hits, camera)
