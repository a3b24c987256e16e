"""Image formation of the synthetic colour HS rig, the paper's equation (4).

A camera pixel's channel c sums, over every light l that is on,

    I_c = sum_l  rho_l(v_l) X[c, b_l] sigma_c(v_cam)
                 f_b_l(v_l, v_cam) (n . v_l) / |c_l - x|^2 * visible_l(x)

with rho_l the light's radiance along its ray, b_l its colour (light band), X
the camera's cross-talk matrix (channel response to each light colour; the
chromatic captures use the camera's matrix for the chromatic light's
filters), sigma_c the channel's sensitivity along the camera ray
(vignetting), f_b the reciprocal BRDF of band b and visible_l the shadow
test. For the demo scenes' materials f_b = p_b f_r, the surface's reflectance
p in the light's band times one BRDF (the paper's separable chromaticity);
materials with a white or Fresnel-coloured specular lobe have their own BRDF
per band (see :class:`~colourhs.synth.brdf.Material`).
Visibility from the camera and shadowing from each light use open3d's
``RaycastingScene``. Each pixel averages s x s sub-pixel samples (box
filter), as a sensor integrates over its pixel. There is no ambient light and
no inter-reflection (direct lighting only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from colourhs.common.geometry import normalised_coordinates, pixel_grid, ray_directions
from colourhs.synth.brdf import albedo_factors, evaluate_materials_bands
from colourhs.synth.scenes import SceneGeometry
from colourhs.synth.simulated_rig import COLOURS, CameraModel

SHADOW_EPS_M = 2e-5  # shadow-ray start offset along the geometric normal, metres


@dataclass(frozen=True)
class Hits:
    """First intersections of a camera's sub-pixel rays with a scene.

    ``sample`` indexes the flattened (height, width, s*s) sample grid; all
    other arrays are per hit.
    """

    shape: tuple[int, int, int]  # (height, width, s*s)
    xy: np.ndarray  # (H*W*s*s, 2) normalised image coordinates of every sample
    sample: np.ndarray  # (M,) index of the sample that hit
    points: np.ndarray  # (M, 3) hit points, metres (on the mesh, float64)
    normals: np.ndarray  # (M, 3) smooth shading normals facing the camera
    geometric_normals: np.ndarray  # (M, 3) face normals facing the camera
    triangles: np.ndarray  # (M,) triangle ids
    to_camera: np.ndarray  # (M, 3) unit vectors from the point to the camera
    albedo: np.ndarray  # (M, 3) reflectance p in the R, G, B light bands
    materials: np.ndarray  # (M,) material ids
    band_factor: np.ndarray  # (M, 3) p for "albedo"-tint materials, 1 elsewhere

    def pixel_mean(self, values: np.ndarray) -> np.ndarray:
        """Box-filter per-hit ``values`` (M, ...) into pixels (H, W, ...); misses count 0."""
        H, W, S = self.shape
        full = np.zeros((H * W * S,) + values.shape[1:])
        full[self.sample] = values
        return full.reshape(H, W, S, *values.shape[1:]).mean(axis=2)

    def coverage(self) -> np.ndarray:
        """Fraction (H, W) of each pixel's samples that hit the scene."""
        return self.pixel_mean(np.ones(len(self.sample)))


@dataclass(frozen=True)
class CameraRays:
    """A camera's sub-pixel sample rays, computed once per camera."""

    shape: tuple[int, int, int]  # (height, width, s*s)
    origin: np.ndarray  # (3,) camera centre, metres
    directions: np.ndarray  # (H*W*s*s, 3) unit world directions
    xy: np.ndarray  # (H*W*s*s, 2) undistorted normalised image coordinates


def camera_rays(camera: CameraModel, width: int, height: int, supersample: int = 2) -> CameraRays:
    """Rays through an s x s grid of samples in every pixel (see ``pixel_grid``)."""
    grid = pixel_grid(width, height, supersample).reshape(-1, 2)
    xy = normalised_coordinates(grid, camera.K, camera.dist)
    d = ray_directions(xy, camera.R)
    return CameraRays((height, width, supersample**2), camera.centre, d, xy)


def trace_camera(
    geom: SceneGeometry, scene: o3d.t.geometry.RaycastingScene, rays: CameraRays
) -> Hits:
    """Cast the camera's sub-pixel rays and describe what they hit."""
    origin = rays.origin
    r = np.concatenate([np.broadcast_to(origin, rays.directions.shape), rays.directions], axis=1)
    ans = scene.cast_rays(o3d.core.Tensor(r.astype(np.float32)))
    hit = np.isfinite(ans["t_hit"].numpy())
    sample = np.flatnonzero(hit)
    tri = ans["primitive_ids"].numpy()[hit].astype(np.int64)
    uv = ans["primitive_uvs"].numpy()[hit].astype(float)
    bary = np.stack([1 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    corners = geom.triangles[tri]
    points = np.einsum("mk,mkj->mj", bary, geom.vertices[corners])
    normals = np.einsum("mk,mkj->mj", bary, geom.vertex_normals[corners])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    v = geom.vertices[corners]
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    to_cam = origin - points
    to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
    # Surfaces are two-sided: orient both normals towards the viewer.
    flip = np.sum(fn * to_cam, axis=1) < 0
    fn[flip] *= -1
    normals[flip] *= -1
    albedo = geom.albedo(points, tri)
    material_ids = geom.material_ids[tri]
    return Hits(
        shape=rays.shape,
        xy=rays.xy,
        sample=sample,
        points=points,
        normals=normals,
        geometric_normals=fn,
        triangles=tri,
        to_camera=to_cam,
        albedo=albedo,
        materials=material_ids,
        band_factor=albedo_factors(material_ids, geom.materials, albedo),
    )


def light_transport(
    geom: SceneGeometry,
    scene: o3d.t.geometry.RaycastingScene,
    hits: Hits,
    position: np.ndarray,
    shadows: bool = True,
) -> np.ndarray:
    """Per-hit, per-band f_b(v_l, v_cam) (n . v_l) / d_l^2 * visible for a light at ``position``.

    Everything of equation (4) that depends on the light's position but not
    on its radiance or colour: the BRDF of each light band, the
    foreshortening, the inverse-square falloff and the shadow test. For
    ``"albedo"``-tint materials the band's reflectance p_b is left out (it is
    ``hits.band_factor``, applied by :func:`channel_signal`). A light of colour
    b contributes ``LightModel.radiance(hits.points) * light_transport(...)[:, b]``.

    Returns
    -------
    (M, 3) transport per hit and light band R, G, B.
    """
    to_light = np.asarray(position, float) - hits.points
    d2 = np.sum(to_light**2, axis=1)
    d = np.sqrt(d2)
    lv = to_light / d[:, None]
    cos = np.sum(hits.normals * lv, axis=1)
    lit = (cos > 0) & (np.sum(hits.geometric_normals * lv, axis=1) > 0)
    out = np.zeros((len(d), 3))
    idx = np.flatnonzero(lit)
    if shadows and len(idx):
        start = hits.points[idx] + SHADOW_EPS_M * hits.geometric_normals[idx]
        rays = o3d.core.Tensor(np.concatenate([start, lv[idx]], axis=1).astype(np.float32))
        # Nothing lies beyond a light, so the farthest light distance bounds every ray.
        occluded = scene.test_occlusions(rays, tnear=0.0, tfar=float(d[idx].max())).numpy()
        idx = idx[~occluded]
    f = evaluate_materials_bands(
        hits.materials[idx],
        geom.materials,
        hits.normals[idx],
        lv[idx],
        hits.to_camera[idx],
        hits.albedo[idx],
        factored=True,
    )
    out[idx] = f * cos[idx, None] / d2[idx, None]
    return out


def channel_signal(
    hits: Hits,
    camera: CameraModel,
    transports: dict[str, np.ndarray],
    crosstalk: np.ndarray | None = None,
    sensitivity: np.ndarray | None = None,
) -> np.ndarray:
    """Linear image (H, W, 3) from per-colour light transports, eq. (4).

    Parameters
    ----------
    hits : the camera's ray hits.
    camera : the camera, for its sensitivity sigma_c and cross-talk X.
    transports : light colour -> (M,) radiance times transport, in that light's
        band, of the light of that colour that is on (``LightModel.radiance(points)
        * light_transport(...)[:, band]``); colours absent are off.
    crosstalk : the (3, 3) cross-talk matrix to use (default the camera's LED
        matrix ``camera.crosstalk``; the chromatic captures pass
        ``camera.chromatic_crosstalk``).
    sensitivity : the (M, 3) ``camera.sensitivity`` of the hits, when already
        computed (several signals of one camera's hits).

    Returns
    -------
    (H, W, 3) signal in fractions of full scale, channels R, G, B.
    """
    X = camera.crosstalk if crosstalk is None else np.asarray(crosstalk, float)
    sens = camera.sensitivity(hits.xy[hits.sample]) if sensitivity is None else sensitivity
    per_hit = np.zeros((len(hits.sample), 3))
    for colour, T in transports.items():
        b = COLOURS.index(colour)
        # channel c responds to band b with X[c, b]; the surface reflects f_b.
        per_hit += (T * hits.band_factor[:, b])[:, None] * X[:, b][None, :]
    return hits.pixel_mean(per_hit * sens)
