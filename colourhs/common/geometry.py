"""Rig geometry: projection, back-projection, rays, planes and triangulation.

Every function takes plain arrays (intrinsics ``K`` (3, 3) in pixels, OpenCV
distortion coefficients ``dist`` (k1, k2, p1, p2[, k3, ...]), world-to-camera
rotation ``R`` (3, 3) and translation ``t`` (3,) in metres, so that a world
point X maps to camera coordinates ``R @ X + t``) and is vectorised over
leading dimensions. Pixel coordinates follow OpenCV: (u, v) = (column, row),
and pixel (0, 0) is the *centre* of the top-left pixel.

The camera model, one for the whole package: OpenCV's distortion with up to
12 coefficients (k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4: radial,
rational, tangential and thin prism; :func:`distort`), then ``K`` with its
skew ``K[0, 1]`` (which ``cv2.projectPoints`` and ``cv2.undistortPoints``
ignore: :func:`project` and :func:`normalised_coordinates` apply it
themselves). The tilted-sensor model (14 coefficients with a non-zero tau)
is refused (:func:`model_coefficients`). The compiled kernels inline the same
formulas (:func:`colourhs.reconstruct.dataterm.to_pixel`; a test pins them
to :func:`project`).
"""

from __future__ import annotations

import cv2
import numpy as np

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
_UNDISTORT_FAST = (cv2.TERM_CRITERIA_COUNT, 20, 0.0)
UNDISTORT_TOL_PX = 1e-9
"""Reprojection error (pixels) above which :func:`normalised_coordinates` iterates
to ``_UNDISTORT_CRITERIA``: far below any measurement, so its result is that
of the strict iteration."""


def camera_centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera centre in world coordinates, c = -R^T t (metres), shape (3,)."""
    return -np.asarray(R, float).T @ np.asarray(t, float)


def light_centre(R: np.ndarray, t: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """World position (metres) of a light at ``offset`` in the camera's coordinates."""
    R = np.asarray(R, float)
    return R.T @ (np.asarray(offset, float) - np.asarray(t, float))


def half_vector_defect(
    X: np.ndarray, c_a: np.ndarray, l_a: np.ndarray, c_b: np.ndarray, l_b: np.ndarray
) -> np.ndarray:
    """Angle (radians) between the half-vectors of a reciprocal pair's two readings at ``X``.

    Beyond the paper. Camera a lit by b's light sees the point ``X`` (..., 3)
    at the half-vector ``h_ab = unit(unit(l_b - X) + unit(c_a - X))``, camera b
    lit by a's light at ``h_ba = unit(unit(l_a - X) + unit(c_b - X))`` (``c``
    the camera centres, ``l`` the light centres, metres). Helmholtz
    reciprocity (eq. 3) makes the two BRDF values equal only when each light
    sits at its camera's centre (the paper's collocated lights): then the
    angle is 0. With lights beside the lenses a glossy lobe, a function of the
    half-vector, is read at two half-vectors this far apart, and the two
    readings differ by a share that no calibration can remove; a matte
    (Lambertian) surface is unaffected.
    """
    X = np.asarray(X, float)

    def unit(v):
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def to(p):
        return unit(np.asarray(p, float) - X)

    h_ab = unit(to(l_b) + to(c_a))
    h_ba = unit(to(l_a) + to(c_b))
    # atan2 of the cross and dot products: accurate for the tiny angles of small offsets
    cross = np.linalg.norm(np.cross(h_ab, h_ba), axis=-1)
    return np.arctan2(cross, np.sum(h_ab * h_ba, axis=-1))


def world_to_camera(X: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera coordinates R X + t of world points ``X`` (..., 3), metres."""
    return np.asarray(X, float) @ np.asarray(R, float).T + np.asarray(t, float)


def look_at(
    centre: np.ndarray, target: np.ndarray, down: np.ndarray = (0.0, 1.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation of a camera at ``centre`` looking at ``target``.

    The camera's y axis (image rows, pointing down) is as close as possible to
    the world direction ``down``.

    Returns
    -------
    R : (3, 3) world-to-camera rotation.
    t : (3,) translation (metres), so that ``R @ centre + t == 0``.
    """
    c = np.asarray(centre, float)
    f = np.asarray(target, float) - c
    f /= np.linalg.norm(f)
    x = np.cross(np.asarray(down, float), f)
    x /= np.linalg.norm(x)
    y = np.cross(f, x)
    R = np.stack([x, y, f])
    return R, -R @ c


N_COEFFICIENTS = 12  # k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4


def model_coefficients(dist) -> np.ndarray:
    """The 12 distortion coefficients of the package's camera model (zero-padded).

    Raises ValueError for a tilted sensor (coefficients 13-14, tau_x and
    tau_y, not zero): no stage models it.
    """
    d = np.zeros(0) if dist is None else np.asarray(dist, float).ravel()
    if d.size > N_COEFFICIENTS and np.any(d[N_COEFFICIENTS:] != 0):
        raise ValueError(
            f"tilted-sensor distortion (tau_x, tau_y = {d[N_COEFFICIENTS:].tolist()}) "
            "is not supported: give at most 12 coefficients"
        )
    out = np.zeros(N_COEFFICIENTS)
    out[: min(d.size, N_COEFFICIENTS)] = d[:N_COEFFICIENTS]
    return out


def distort(x: np.ndarray, y: np.ndarray, dist) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's distortion of normalised coordinates (x/z, y/z): radial k1-k3
    over the rational k4-k6, tangential p1, p2 and thin prism s1-s4."""
    # Python floats keep float32 coordinates float32 (the hull's millions of points).
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = map(float, model_coefficients(dist))
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy2 = 2 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2 * y * y) + p2 * xy2 + s3 * r2 + s4 * r4
    return xd, yd


def pixels_of(x: np.ndarray, y: np.ndarray, K: np.ndarray, dist) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (u, v) of normalised camera coordinates (x/z, y/z): :func:`distort`, then K."""
    (fx, sk, cx), (_, fy, cy) = np.asarray(K, float)[:2].tolist()
    xd, yd = distort(x, y, dist)
    return fx * xd + sk * yd + cx, fy * yd + cy


def project(
    X: np.ndarray, K: np.ndarray, dist: np.ndarray, R: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """Project world points into pixels with the camera model (module docstring).

    Parameters
    ----------
    X : (..., 3) world points, metres.
    K, dist, R, t : camera intrinsics, distortion and world-to-camera pose.

    Returns
    -------
    (..., 2) pixel coordinates (u, v). Points behind the camera get NaN.
    """
    Xc = world_to_camera(X, R, t)
    z = Xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = pixels_of(Xc[..., 0] / z, Xc[..., 1] / z, K, dist)
    uv = np.stack([u, v], axis=-1)
    uv[z <= 0] = np.nan
    return uv


def normalised_coordinates(uv: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Undistorted normalised image coordinates (x/z, y/z) of pixels ``uv`` (..., 2).

    The inverse of :func:`pixels_of`: the skew is taken off first, then
    ``cv2.undistortPoints`` inverts the distortion: 20 fixed-point
    iterations, then, for the points whose reprojection is more than
    ``UNDISTORT_TOL_PX`` off, iterations to 1e-14 (OpenCV then reprojects
    at every iteration, several times slower, so only those points pay for
    it).
    """
    uv = np.array(uv, float)
    shape = uv.shape[:-1]
    K = np.asarray(K, float)
    flat = uv.reshape(-1, 2).copy()
    uv[..., 0] -= K[0, 1] * (uv[..., 1] - K[1, 2]) / K[1, 1]
    K0 = K.copy()
    K0[0, 1] = 0.0
    pts = uv.reshape(-1, 1, 2)
    coeffs = model_coefficients(dist)
    xy = cv2.undistortPoints(pts, K0, coeffs, criteria=_UNDISTORT_FAST).reshape(-1, 2)
    u, v = pixels_of(xy[:, 0], xy[:, 1], K, dist)
    with np.errstate(invalid="ignore"):
        off = ~(np.hypot(u - flat[:, 0], v - flat[:, 1]) <= UNDISTORT_TOL_PX)
    if off.any():
        strict = cv2.undistortPoints(pts[off], K0, coeffs, criteria=_UNDISTORT_CRITERIA)
        xy[off] = strict.reshape(-1, 2)
    return xy.reshape(*shape, 2)


def backproject(
    uv: np.ndarray, K: np.ndarray, dist: np.ndarray, R: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World rays through pixels ``uv`` (..., 2).

    Returns
    -------
    origin : (3,) camera centre, metres.
    direction : (..., 3) unit ray directions in the world frame.
    """
    return camera_centre(R, t), ray_directions(normalised_coordinates(uv, K, dist), R)


def ray_directions(xy: np.ndarray, R: np.ndarray, unit_length: bool = True) -> np.ndarray:
    """World directions (..., 3) of the rays through normalised camera coordinates
    ``xy`` (..., 2): R^T (x, y, 1), of unit length, or (``unit_length`` False) scaled
    to unit z-depth (a point at z-depth z lies at the centre + z d)."""
    xy = np.asarray(xy, float)
    d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    d = d @ np.asarray(R, float)  # R^T d for row vectors
    if unit_length:
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d


def axial_cosine(directions: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Cosine (...,) of unit world ``directions`` (..., 3) to the camera's optical axis
    (their z in the camera frame): the z-depth of a point at distance s along a ray is
    s times it."""
    return np.asarray(directions, float) @ np.asarray(R, float)[2]


def pixel_grid(width: int, height: int, supersample: int = 1) -> np.ndarray:
    """Pixel sample positions (height, width, s*s, 2) of an image.

    ``supersample`` s places s x s samples on a regular grid inside each pixel
    footprint (pixel centres are integers, a pixel spans +-0.5). With s = 1 the
    single sample is the pixel centre.
    """
    s = int(supersample)
    offs = (np.arange(s) + 0.5) / s - 0.5
    ou, ov = np.meshgrid(offs, offs)
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    grid = np.empty((height, width, s * s, 2))
    grid[..., 0] = u[..., None] + ou.ravel()
    grid[..., 1] = v[..., None] + ov.ravel()
    return grid


def ray_plane_intersection(
    origins: np.ndarray, directions: np.ndarray, plane_point: np.ndarray, plane_normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Intersect rays o + s d with the plane through ``plane_point`` with ``plane_normal``.

    Returns
    -------
    points : (..., 3) intersections (NaN where the ray is parallel to the plane).
    s : (...,) ray parameters (metres for unit directions; negative = behind).
    """
    o = np.asarray(origins, float)
    d = np.asarray(directions, float)
    n = np.asarray(plane_normal, float)
    denom = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = ((np.asarray(plane_point, float) - o) @ n) / denom
    s = np.where(np.abs(denom) < 1e-12, np.nan, s)
    return o + s[..., None] * d, s


def triangulate(uvs: np.ndarray, Ks, dists, Rs, ts) -> np.ndarray:
    """Linear multi-view triangulation (DLT on undistorted coordinates).

    Parameters
    ----------
    uvs : (V, N, 2) pixel observations of N points in V views; NaN where a
        view does not see the point.
    Ks, dists, Rs, ts : per-view camera parameters (sequences of length V).

    Returns
    -------
    (N, 3) world points, metres; NaN where fewer than two views see a point.
    """
    uvs = np.asarray(uvs, float)
    V, N = uvs.shape[:2]
    A = np.zeros((N, 2 * V, 4))
    seen = np.all(np.isfinite(uvs), axis=-1)  # (V, N)
    for k in range(V):
        xy = np.zeros((N, 2))
        if seen[k].any():
            xy[seen[k]] = normalised_coordinates(uvs[k, seen[k]], Ks[k], dists[k])
        P = np.hstack([np.asarray(Rs[k], float), np.asarray(ts[k], float)[:, None]])
        w = seen[k][:, None].astype(float)
        A[:, 2 * k] = w * (xy[:, :1] * P[2] - P[0])
        A[:, 2 * k + 1] = w * (xy[:, 1:] * P[2] - P[1])
    _, _, vt = np.linalg.svd(A)
    Xh = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:]
    X[seen.sum(0) < 2] = np.nan
    return X


def axis_angle(axis, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle`` radians about ``axis`` (any length, not zero)."""
    from scipy.spatial.transform import Rotation  # here: an evaluation imports no scipy

    k = np.asarray(axis, float)
    return Rotation.from_rotvec(angle * k / np.linalg.norm(k)).as_matrix()


def fixation_point(axes: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """The point nearest (least squares) to every camera's optical axis, metres (3,).

    ``axes`` (N, 3) unit optical axes (the third row of each R) and
    ``centres`` (N, 3) camera centres, world frame. ValueError with fewer
    than two cameras or (nearly) parallel axes.
    """
    A, b = np.zeros((3, 3)), np.zeros(3)
    for a, c in zip(np.asarray(axes, float), np.asarray(centres, float), strict=True):
        P = np.eye(3) - np.outer(a, a)
        A += P
        b += P @ c
    w = np.linalg.eigvalsh(A)
    if len(axes) < 2 or w[0] < 1e-4 * w[-1]:
        raise ValueError("the optical axes do not converge")
    return np.linalg.solve(A, b)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) of a triangle mesh (0 for unused vertices)."""
    tv = vertices[triangles]
    face = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    n = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        np.add.at(n, triangles[:, k], face)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def mesh_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Signed volume (m^3) of a closed mesh; positive when triangles wind outward."""
    v = np.asarray(vertices, float)[np.asarray(triangles)]
    return float(np.sum(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2]))) / 6.0)


def outward_triangles(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``triangles`` (T, 3) of a closed mesh wound outward: reversed (a copy) when
    the signed volume (:func:`mesh_volume`) is negative, else as given."""
    return triangles[:, ::-1].copy() if mesh_volume(vertices, triangles) < 0 else triangles
