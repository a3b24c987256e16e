"""The colour HS constraint, equations (3) and (5), in plain NumPy: the tests' oracle.

The renderer's output satisfies it (:func:`pair_rows` at the ground truth), and
the compiled data term is checked against :func:`numpy_data_term`, the same
quantity written the obvious way. ``benchmarks/bench_reconstruct.py`` times the
compiled kernel against it too.
"""

from __future__ import annotations

import h5py
import numpy as np
import open3d as o3d

from colourhs.capture import Camera, load_rig, read_image
from colourhs.common.geometry import project
from colourhs.common.ply import load_mesh
from colourhs.common.raycast import cast_pixels
from colourhs.common.sampling import sample_bilinear
from colourhs.synth.image_formation import SHADOW_EPS_M


def constraint_vector(
    x: np.ndarray,
    c_a: np.ndarray,
    c_b: np.ndarray,
    i_a: np.ndarray,
    i_b: np.ndarray,
    mu_a: np.ndarray | float = 1.0,
    mu_b: np.ndarray | float = 1.0,
    p_ba: np.ndarray | float = 1.0,
    p_ab: np.ndarray | float = 1.0,
) -> np.ndarray:
    """One row w of the colour HS constraint w . n = 0, equation (5).

    ``w = p_ba mu_a i_a / |c_a - x|^2 v_a - p_ab mu_b i_b / |c_b - x|^2 v_b``
    with v_k the unit vector from x towards Helmholtz camera k.

    Parameters
    ----------
    x : (..., 3) surface points, metres.
    c_a, c_b : (3,) or (..., 3) centres of the two Helmholtz cameras of the
        reciprocal pair (camera and its collocated light), metres.
    i_a : (...,) intensity recorded by camera a lit by camera b's light
        (camera a's channel of b's light colour), linear units.
    i_b : (...,) the reciprocal intensity: camera b lit by camera a's light.
    mu_a, mu_b : radiance/sensitivity ratios of the two Helmholtz cameras
        along their rays, eq. (2) (1 = uncalibrated).
    p_ba : chromaticity seen by camera b under a's light colour, p_{b,a}.
    p_ab : chromaticity seen by camera a under b's light colour, p_{a,b}.

    Returns
    -------
    (..., 3) constraint vectors w; with white chromaticity and mu = 1 this
    is the white-light constraint of equation (3).
    """
    x = np.asarray(x, float)
    da = np.asarray(c_a, float) - x
    db = np.asarray(c_b, float) - x
    ra2 = np.sum(da**2, axis=-1)
    rb2 = np.sum(db**2, axis=-1)
    va = da / np.sqrt(ra2)[..., None]
    vb = db / np.sqrt(rb2)[..., None]
    sa = np.asarray(p_ba * mu_a * i_a, float) / ra2
    sb = np.asarray(p_ab * mu_b * i_b, float) / rb2
    return sa[..., None] * va - sb[..., None] * vb


def constraint_residual(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Normalised residual |w . n| / |w| of constraint rows ``w`` (..., 3) for normals ``n``.

    NaN where a row is NaN or zero (no measurement).
    """
    w = np.asarray(w, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(np.sum(w * n, axis=-1)) / np.linalg.norm(w, axis=-1)


def pair_rows(
    points: np.ndarray,
    images: dict,
    cameras: dict,
    pairs,
    mu: dict | None = None,
    chromaticity=None,
) -> np.ndarray:
    """Constraint rows (N, P, 3) of every reciprocal pair at world ``points`` (N, 3), eq. (5).

    Parameters
    ----------
    points : (N, 3) world points, metres.
    images : camera name -> (H, W, 3) linear image, channels R, G, B.
    cameras : camera name -> :class:`colourhs.capture.Camera`.
    pairs : reciprocal pairs (:meth:`colourhs.capture.Rig.reciprocal_pairs`).
    mu : optional ``"<camera>/<colour>"`` -> (H, W) mu map (eq. 2); 1 if absent.
    chromaticity : optional callable (camera name, pixel positions (N, 2)) ->
        (N, 3) chromaticity p per light band; white if absent.

    Returns
    -------
    (N, P, 3) rows w, NaN where a point projects outside an image.
    """
    from colourhs.capture import COLOURS
    from colourhs.common.geometry import project

    rows = []
    for pr in pairs:
        ca, cb = cameras[pr.cam_a], cameras[pr.cam_b]
        uva = project(points, ca.K, ca.dist, ca.R, ca.t)
        uvb = project(points, cb.K, cb.dist, cb.R, cb.t)
        i_a = sample_bilinear(images[pr.cam_a][..., pr.channel_a], uva)
        i_b = sample_bilinear(images[pr.cam_b][..., pr.channel_b], uvb)
        mu_a = mu_b = 1.0
        if mu is not None:
            mu_a = sample_bilinear(mu[f"{pr.cam_a}/{COLOURS[pr.channel_a]}"], uva)
            mu_b = sample_bilinear(mu[f"{pr.cam_b}/{COLOURS[pr.channel_b]}"], uvb)
        p_ba = p_ab = 1.0
        if chromaticity is not None:
            # p_{b,a}: camera b under a's light colour, which is b's channel_b.
            p_ba = chromaticity(pr.cam_b, uvb)[:, pr.channel_b]
            p_ab = chromaticity(pr.cam_a, uva)[:, pr.channel_a]
        rows.append(
            constraint_vector(
                points, ca.light_centre, cb.light_centre, i_a, i_b, mu_a, mu_b, p_ba, p_ab
            )
        )
    return np.stack(rows, axis=1)


def numpy_data_term(
    rays: np.ndarray,
    c_ref: np.ndarray,
    depths: np.ndarray,
    cameras,
    prepared,
    pairs,
) -> tuple[np.ndarray, np.ndarray]:
    """The data term of every pixel and depth hypothesis in plain NumPy (the oracle of
    :func:`colourhs.reconstruct.dataterm.data_term`: same arguments, same validity rules).

    sigma_3 / sigma_2 of the 3 x 3 matrix W of the reciprocal pairs' rows
    (:func:`constraint_vector`) at the points ``c_ref + z rays``, and W's null
    vector as the normal: vectorised over pixels and hypotheses, the projection
    of :func:`colourhs.common.geometry.project`, :func:`sample_bilinear` on the
    :class:`~colourhs.reconstruct.dataterm.Prepared` images, ``numpy.linalg.eigh``
    of W^T W in float64. No numba, no float32 arithmetic, no attempt at speed.
    A hypothesis is valid where every sample lies inside its image and is usable
    (positive), every p is known (a camera's own, else, where its footprint has
    none and ``prepared.borrow``, the reference pixel's: the rays leave a
    camera's centre), W has rank 2 at least, and the normal faces every light by
    more than ``MIN_FACING_COS``.

    Returns
    -------
    cost : (N, K) float32, ``INVALID_COST`` where invalid.
    normal : (N, K, 3) float32 unit normals towards the reference camera, 0 where invalid.
    """
    from colourhs.reconstruct.dataterm import ALL_UNKNOWN, INVALID_COST, MIN_FACING_COS

    pair_cams, pair_ch = pairs
    rays = np.asarray(rays, float)
    z = np.asarray(depths, float)
    X = np.asarray(c_ref, float) + rays[:, None, :] * z[None, :, None]  # (N, K, 3)
    ns = int(prepared.slots.max()) + 1
    samples, ok = [], np.ones(X.shape[:2], bool)
    for cam, S in zip(cameras, prepared.S, strict=True):
        samples.append(sample_bilinear(S, project(X, cam.K, cam.dist, cam.R, cam.t)))
        ok &= np.all(np.isfinite(samples[-1]), axis=-1)  # NaN outside the image
    p_ref = np.full((len(rays), 1, 3), -1.0)  # the reference pixel's p, where known
    at = [i for i, c in enumerate(cameras) if np.linalg.norm(c.centre - c_ref) < 1e-9]
    if prepared.use_p and prepared.borrow and at:
        cam = cameras[at[0]]
        uv = project(np.asarray(c_ref, float) + rays, cam.K, cam.dist, cam.R, cam.t)
        p_ref[:, 0] = sample_bilinear(prepared.P[at[0]], uv)[:, :3]
    Wm = np.zeros(X.shape[:2] + (3, 3))
    for p, (a, b) in enumerate(pair_cams):
        ja, jb = prepared.slots[p]
        Ja, Jb = samples[a][..., ja], samples[b][..., jb]
        ok &= (Ja > 0) & (Jb > 0)
        if prepared.use_p:
            # A p unknown over the whole footprint (J = mu i undivided there) is the
            # reference's; a footprint that mixes known and unknown p is invalid.
            pa, pb = samples[a][..., ns + ja], samples[b][..., ns + jb]
            qa, qb = p_ref[..., pair_ch[p, 0]], p_ref[..., pair_ch[p, 1]]
            ea = np.where(pa > 0, pa, np.where(pa < ALL_UNKNOWN, qa, 0.0))
            eb = np.where(pb > 0, pb, np.where(pb < ALL_UNKNOWN, qb, 0.0))
            ok &= (ea > 0) & (eb > 0)
            Ja = np.where(pa > 0, Ja, Ja / np.where(ea > 0, ea, 1.0))
            Jb = np.where(pb > 0, Jb, Jb / np.where(eb > 0, eb, 1.0))
            pp = ea * eb
        else:
            pp = 1.0
        Wm[..., p, :] = constraint_vector(
            X, cameras[a].light_centre, cameras[b].light_centre, Ja, Jb, p_ba=pp, p_ab=pp
        )
    Wm = np.where(ok[..., None, None], Wm, 0.0)
    lam, vec = np.linalg.eigh(np.einsum("nkpi,nkpj->nkij", Wm, Wm))
    n = vec[..., 0]
    n = np.where((np.sum(n * rays[:, None, :], axis=-1) > 0)[..., None], -n, n)
    ok &= lam[..., 1] > 0
    for cam in cameras:
        d = np.asarray(cam.light_centre, float) - X
        ok &= np.sum(n * d, axis=-1) > MIN_FACING_COS * np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.sqrt(np.clip(lam[..., 0] / lam[..., 1], 0.0, 4.0))
    cost = np.where(ok, cost, INVALID_COST).astype(np.float32)
    return cost, np.where(ok[..., None], n, 0.0).astype(np.float32)


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
    hits = cast_pixels(vertices, triangles, normals, reference, width, height)
    scene, hit, points, n = hits.scene, hits.hit, hits.points, hits.normals
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


def frame_images(root, scene, frame="000000"):
    """The rig, and each camera's image and saturation mask of one frame of a dataset."""
    rig = load_rig(root)
    images, saturated = {}, {}
    for cam in rig.camera_names:
        path = root / "scenes" / scene / "frames" / frame / f"{cam}.png"
        images[cam], saturated[cam] = read_image(path, rig.image)
    return rig, images, saturated


def gt_points(root, scene, rig, saturated):
    """Ground-truth surface points and normals seen by the reference camera, without those
    near a saturated pixel in any camera."""
    v, t, n = load_mesh(root / "scenes" / scene / "gt" / "000000.ply")
    pts, nrm, _ = surface_points(
        v, t, n, rig.cameras[0], rig.cameras, rig.image.width, rig.image.height
    )
    near_sat = np.zeros(len(pts), bool)
    for cam in rig.cameras:
        uv = project(pts, cam.K, cam.dist, cam.R, cam.t)
        near_sat |= sample_bilinear(saturated[cam.name].astype(float), uv) > 0
    return pts[~near_sat], nrm[~near_sat]


def true_calibration(root, scene):
    """The true mu maps ({camera/channel: map}) and chromaticity sampler (or None)."""
    with h5py.File(root / "gt" / "photometric.h5") as f:
        mu = {f"{c}/{k}": f[c][k][()] for c in f for k in f[c]}
    chroma = None
    path = root / "scenes" / scene / "gt" / "chromaticity.h5"
    if path.exists():
        with h5py.File(path) as f:
            maps = {c: f[c][()] for c in f}
        chroma = lambda cam, uv: sample_bilinear(maps[cam], uv)  # noqa: E731
    return mu, chroma
