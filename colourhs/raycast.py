"""Ray casting a triangle mesh into a camera (open3d): depth and normals per pixel
(ground truth for evaluation and tests), and the surface points a rig sees and lights.

Meshes are read by :func:`colourhs.ply.load_mesh`.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from colourhs.capture import Camera
from colourhs.geometry import backproject, pixel_grid

SHADOW_EPS_M = 2e-5


def raycasting_scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    """An open3d ray-casting scene of a triangle mesh (vertices (V, 3) metres, triangles (T, 3))."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(vertices, np.float32).reshape(-1, 3)),
        o3d.core.Tensor(np.asarray(triangles, np.uint32).reshape(-1, 3)),
    )
    return scene


def _cast_pixels(vertices, triangles, normals, camera, width, height):
    """Ray cast a mesh from every pixel centre of a camera.

    Returns the open3d scene, the hit mask (H*W,), the hit points (M, 3) on
    the mesh and their interpolated unit normals facing the camera.
    """
    scene = raycasting_scene(vertices, triangles)
    grid = pixel_grid(width, height).reshape(-1, 2)
    origin, dirs = backproject(grid, camera.K, camera.dist, camera.R, camera.t)
    rays = np.concatenate([np.broadcast_to(origin, dirs.shape), dirs], axis=1)
    ans = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    hit = np.isfinite(ans["t_hit"].numpy())
    tri = ans["primitive_ids"].numpy()[hit].astype(np.int64)
    uv = ans["primitive_uvs"].numpy()[hit].astype(float)
    bary = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    points = np.einsum("mk,mkj->mj", bary, vertices[triangles[tri]])
    n = np.einsum("mk,mkj->mj", bary, normals[triangles[tri]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n *= np.sign(np.sum(n * (origin - points), axis=1))[:, None]
    return scene, hit, points, n


def surface_points(
    vertices: np.ndarray,
    triangles: np.ndarray,
    normals: np.ndarray,
    reference: Camera,
    cameras: tuple[Camera, ...],
    width: int,
    height: int,
    min_cos: float = 0.1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface points seen at the reference camera's pixel centres.

    Casts one ray per pixel centre of ``reference`` onto the mesh and keeps
    the hits that every camera sees and every collocated light lights
    (unoccluded, at more than ``min_cos`` incidence).

    Returns
    -------
    points : (N, 3) world points on the mesh, metres.
    normals : (N, 3) interpolated unit normals facing the reference camera.
    pixels : (N,) flat pixel indices (row * width + column) in the reference camera.
    """
    scene, hit, points, n = _cast_pixels(vertices, triangles, normals, reference, width, height)
    keep = np.ones(len(points), bool)
    for cam in cameras:
        for centre in (cam.centre, cam.light_centre):
            d = centre - points
            dist = np.linalg.norm(d, axis=1)
            d /= dist[:, None]
            keep &= np.sum(d * n, axis=1) > min_cos
            r = np.concatenate([points + SHADOW_EPS_M * d, d], axis=1).astype(np.float32)
            keep &= ~scene.test_occlusions(o3d.core.Tensor(r), tfar=float(dist.min())).numpy()
    return points[keep], n[keep], np.flatnonzero(hit)[keep]


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
    _, hit, points, n = _cast_pixels(vertices, triangles, normals, camera, width, height)
    depth = np.full(width * height, np.nan)
    depth[hit] = (points @ np.asarray(camera.R, float).T + np.asarray(camera.t, float))[:, 2]
    nrm = np.full((width * height, 3), np.nan)
    nrm[hit] = n
    return depth.reshape(height, width), nrm.reshape(height, width, 3)
