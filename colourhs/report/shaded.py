"""Shaded renders of triangle meshes from a pinhole camera (ray cast with open3d, no OpenGL).

:func:`shaded_render` is what the report's Figure 7 and Hausdorff figures show
(:mod:`colourhs.report.figures`, which re-exports it).
"""

from __future__ import annotations

import numpy as np

from colourhs.common.geometry import vertex_normals

__all__ = ["BACKGROUND", "shaded_render"]

#: Colour of pixels with no value (NaN) in the image figures and renders.
BACKGROUND = (1.0, 1.0, 1.0)


def shaded_render(
    vertices: np.ndarray,
    triangles: np.ndarray,
    K: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    width: int,
    height: int,
    vertex_rgb: np.ndarray | None = None,
    dist: np.ndarray | None = None,
    ambient: float = 0.1,
) -> np.ndarray:
    """Shaded image of a triangle mesh seen by a pinhole camera (ray cast, no OpenGL).

    One ray per pixel centre (open3d ``RaycastingScene``, via
    :func:`colourhs.common.raycast.cast_pixels`); Lambertian shading from a
    headlight at the camera centre, ``ambient + (1 - ambient) |n . ray|``
    with the interpolated (area-weighted) vertex normal ``n``.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
        World points, metres.
    triangles : ndarray of int, shape (T, 3)
        Vertex indices.
    K, R, t : ndarray
        Intrinsics (3, 3), world-to-camera rotation (3, 3) and translation (3,), metres.
    width, height : int
        Image size, pixels.
    vertex_rgb : ndarray, shape (V, 3), optional
        Per-vertex albedo, floats in [0, 1] or uint8; interpolated with the
        hit's barycentric coordinates. Default light grey.
    dist : ndarray, optional
        OpenCV distortion coefficients; default none.
    ambient : float
        Ambient term in [0, 1].

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)
        The render, white where no ray hits the mesh: all white for a mesh without
        triangles (the empty mesh of a frame with nothing reconstructed).
    """
    from colourhs.capture import Camera
    from colourhs.common.raycast import cast_pixels

    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(triangles) == 0:  # nothing to hit: the background alone
        return np.full((height, width, 3), np.round(np.multiply(BACKGROUND, 255.0)), np.uint8)
    camera = Camera(
        name="render",
        K=np.asarray(K, float),
        dist=np.zeros(5) if dist is None else np.asarray(dist, float),
        R=np.asarray(R, float),
        t=np.asarray(t, float).reshape(3),
        light_colour="red",
        light_offset=np.zeros(3),
    )
    normals = vertex_normals(vertices, triangles)
    hits = cast_pixels(vertices, triangles, normals, camera, width, height)
    hit, points, n = hits.hit, hits.points, hits.normals
    ray = points - camera.centre
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    cos = np.nan_to_num(np.abs(np.sum(n * ray, axis=1)), nan=1.0)
    shade = ambient + (1.0 - ambient) * np.clip(cos, 0.0, 1.0)
    if vertex_rgb is None:
        albedo = np.full((len(points), 3), 0.8)
    else:
        rgb = np.asarray(vertex_rgb)
        rgb = rgb / 255.0 if np.issubdtype(rgb.dtype, np.integer) else rgb.astype(np.float64)
        if rgb.shape != vertices.shape:
            raise ValueError(f"vertex_rgb must be (V, 3) = {vertices.shape}, got {rgb.shape}")
        albedo = np.einsum("mk,mkj->mj", hits.barycentric, rgb[triangles[hits.triangles]])
    image = np.empty((height * width, 3))
    image[:] = BACKGROUND
    image[hit] = np.clip(albedo, 0.0, 1.0) * shade[:, None]
    return np.round(image.reshape(height, width, 3) * 255.0).astype(np.uint8)
