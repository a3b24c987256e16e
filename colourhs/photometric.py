"""Photometric calibration of the Helmholtz cameras, paper section III-C.

Each camera's channel that records another camera's light, together with the
camera's own collocated light, is a Helmholtz camera with a
radiance/sensitivity ratio map mu (eq. 2); three cameras give six. The board
poses of ``photometric/`` calibrate them:

1. For a reciprocal pair (a, b) and a board point x on plane Pi_j, kappa of
   eq. (6) is p_ba mu_a(v_a) / (p_ab mu_b(v_b)), measured from the two
   reciprocal intensities (white board: p_ba = p_ab).
2. Transferring x along the ray v_b of camera b to the plane Pi_k of another
   pose gives x' seen by the same pixel of b, so the ratio of the two kappas
   is mu_a(v_a) / mu_a(v_a') (eq. 7): a constraint on the map of a alone.
3. The log-ratio constraints on control points of a regular grid, with
   bilinear interpolation, form the sparse least-squares system of eq. (8),
   solved with a weak first-difference smoothness regulariser. Each
   Helmholtz camera is observed through both reciprocal pairs its camera
   takes part in: the two maps of one camera share its light's radiance, so
   a weak penalty on the gradient of their difference lets the constraints
   of one pair (along its epipolar lines) support the other (along other
   epipolar lines), as the paper argues.
4. Each map is so far known up to a constant (the gauge, fixed explicitly:
   mean log mu over control points = 0). Eq. (6) then fixes the relative
   scale of the two maps of a pair; one scale per pair stays free.

Images are unmixed (see :mod:`colourhs.crosstalk`) before calibration when a
cross-talk calibration is given.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from colourhs.capture import COLOURS, Board, Camera, Rig, open_dataset, read_image
from colourhs.crosstalk import load_crosstalk, unmix
from colourhs.geometry import backproject, pixel_grid, project, ray_plane_intersection
from colourhs.helmholtz import sample_bilinear
from colourhs.io import atomic_output, sha256_files


def kappa(
    x: np.ndarray,
    n: np.ndarray,
    c_a: np.ndarray,
    c_b: np.ndarray,
    i_a: np.ndarray,
    i_b: np.ndarray,
) -> np.ndarray:
    """kappa(v_a, v_b | Pi) of equation (6).

    ``kappa = (n . v_b) |c_a - x|^2 i_b / ((n . v_a) |c_b - x|^2 i_a)``,
    which equals ``p_ba mu_a(v_a) / (p_ab mu_b(v_b))``.

    Parameters
    ----------
    x : (..., 3) board points, metres.
    n : (3,) or (..., 3) unit plane normal.
    c_a, c_b : (3,) Helmholtz camera centres (collocated light), metres.
    i_a : (...,) intensity of camera a lit by b's light.
    i_b : (...,) intensity of camera b lit by a's light.

    Returns
    -------
    (...,) dimensionless ratio.
    """
    da = np.asarray(c_a, float) - x
    db = np.asarray(c_b, float) - x
    ra2 = np.sum(da**2, axis=-1)
    rb2 = np.sum(db**2, axis=-1)
    cos_a = np.sum(da * n, axis=-1) / np.sqrt(ra2)
    cos_b = np.sum(db * n, axis=-1) / np.sqrt(rb2)
    return cos_b * ra2 * i_b / (cos_a * rb2 * i_a)


@dataclass(frozen=True)
class Grid:
    """Regular grid of control points over an image, bilinear in between.

    Nodes sit at pixel positions (i * spacing, j * spacing) for
    i < nx, j < ny, covering [0, width - 1] x [0, height - 1].
    """

    width: int
    height: int
    spacing: float

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) node counts."""
        return (
            int(np.ceil((self.height - 1) / self.spacing)) + 1,
            int(np.ceil((self.width - 1) / self.spacing)) + 1,
        )

    @property
    def size(self) -> int:
        ny, nx = self.shape
        return ny * nx

    def weights(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear interpolation: node indices (N, 4) and weights (N, 4) of pixels ``uv``."""
        ny, nx = self.shape
        gx = np.clip(np.asarray(uv[:, 0], float) / self.spacing, 0, nx - 1)
        gy = np.clip(np.asarray(uv[:, 1], float) / self.spacing, 0, ny - 1)
        x0 = np.minimum(np.floor(gx).astype(int), nx - 2)
        y0 = np.minimum(np.floor(gy).astype(int), ny - 2)
        fx, fy = gx - x0, gy - y0
        idx = np.stack(
            [y0 * nx + x0, y0 * nx + x0 + 1, (y0 + 1) * nx + x0, (y0 + 1) * nx + x0 + 1], 1
        )
        w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
        return idx, w

    def interpolate(self, values: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Values of the bilinear surface through node ``values`` (ny, nx) at ``uv`` (N, 2)."""
        idx, w = self.weights(uv)
        return np.sum(values.ravel()[idx] * w, axis=1)

    def dense(self, values: np.ndarray) -> np.ndarray:
        """The bilinear surface on every pixel centre, (height, width)."""
        uv = pixel_grid(self.width, self.height).reshape(-1, 2)
        return self.interpolate(values, uv).reshape(self.height, self.width)


def white_board_mask(xy_board: np.ndarray, board: Board, margin_m: float) -> np.ndarray:
    """True where board-frame points (N, 2) lie on the white calibration surface.

    Points within ``margin_m`` of the board's edge or of a marker are left
    out (the rendered or printed edge blurs over a pixel or two).
    """
    w, h = board.size
    x, y = xy_board[:, 0], xy_board[:, 1]
    ok = (x > margin_m) & (x < w - margin_m) & (y > margin_m) & (y < h - margin_m)
    half = board.marker_length / 2 + margin_m
    for centre in board.markers.values():
        ok &= ~((np.abs(x - centre[0]) < half) & (np.abs(y - centre[1]) < half))
    return ok


@dataclass(frozen=True)
class PoseView:
    """One board pose as the calibration needs it: plane, board pose, images."""

    name: str
    R: np.ndarray  # board to world rotation
    t: np.ndarray  # board to world translation, metres
    images: dict  # camera name -> (H, W, 3) unmixed linear image
    saturated: dict  # camera name -> (H, W) bool

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the white face (towards the cameras), world frame."""
        return self.R @ np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class Samples:
    """Constraint samples of one Helmholtz camera (camera ``cam``, channel ``channel``)."""

    uv: np.ndarray  # (N, 2) pixel in pose j
    uv2: np.ndarray  # (N, 2) pixel in pose k (same ray of the partner camera)
    delta: np.ndarray  # (N,) log kappa_j - log kappa_k = log mu(uv) - log mu(uv2), eq. (7)


def _kappa_at(view: PoseView, board: Board, a: Camera, b: Camera, ch_a, ch_b, uv_b, opts):
    """kappa (eq. 6) at the board points seen by pixels ``uv_b`` of b; NaN if unusable."""
    origin, d = backproject(uv_b, b.K, b.dist, b.R, b.t)
    n = view.normal
    x, s = ray_plane_intersection(origin, d, view.t, n)
    xy = ((x - view.t) @ view.R)[:, :2]
    ok = (s > 0) & white_board_mask(xy, board, opts["margin_m"])
    uv_a = project(x, a.K, a.dist, a.R, a.t)
    i_a = sample_bilinear(view.images[a.name][..., ch_a], uv_a)
    i_b = sample_bilinear(view.images[b.name][..., ch_b], uv_b)
    sat = sample_bilinear(view.saturated[a.name].astype(float), uv_a) > 0
    sat |= sample_bilinear(view.saturated[b.name].astype(float), uv_b) > 0
    for c in (a, b):
        v = c.light_centre - x
        ok &= (v @ n) / np.linalg.norm(v, axis=1) > opts["min_cos"]
    with np.errstate(invalid="ignore"):
        ok &= ~sat & (i_a > opts["min_signal"]) & (i_b > opts["min_signal"])
    k = np.full(len(uv_b), np.nan)
    k[ok] = kappa(x[ok], n, a.light_centre, b.light_centre, i_a[ok], i_b[ok])
    return k, uv_a


def transfer_samples(
    views: list[PoseView], rig: Rig, a: str, b: str, opts: dict
) -> tuple[Samples, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (7) constraints on the Helmholtz camera (a, channel of b's light).

    For every pair of poses (j, k), pixels of the partner camera b on a
    regular grid (step ``opts["step_px"]``) see x_j on Pi_j and x_k on Pi_k
    along the same ray v_b; ``log kappa_j(x_j) - log kappa_k(x_k)`` equals
    ``log mu_a(v_a) - log mu_a(v_a')``.

    Returns
    -------
    samples : the eq. (7) constraints.
    uv_a, uv_b, log_kappa : every single-pose kappa sample (eq. 6), for the
        relative scale of the pair.
    """
    A, B = rig.camera(a), rig.camera(b)
    ch_a, ch_b = B.light_channel, A.light_channel
    W, H = rig.image.width, rig.image.height
    step = opts["step_px"]
    u, v = np.meshgrid(np.arange(0, W, step, dtype=float), np.arange(0, H, step, dtype=float))
    uv_b = np.stack([u.ravel(), v.ravel()], axis=1)
    per_pose = [_kappa_at(view, rig.board, A, B, ch_a, ch_b, uv_b, opts) for view in views]
    uv1, uv2, delta = [], [], []
    for j in range(len(views)):
        for k in range(j + 1, len(views)):
            kj, uvj = per_pose[j]
            kk, uvk = per_pose[k]
            ok = np.isfinite(kj) & np.isfinite(kk)
            uv1.append(uvj[ok])
            uv2.append(uvk[ok])
            delta.append(np.log(kj[ok]) - np.log(kk[ok]))
    single = [(uva[np.isfinite(k)], uv_b[np.isfinite(k)], np.log(k[np.isfinite(k)]))
              for k, uva in per_pose]  # fmt: skip
    samples = Samples(np.concatenate(uv1), np.concatenate(uv2), np.concatenate(delta))
    return samples, *(np.concatenate(x) for x in zip(*single, strict=True))


def _second_difference_operator(grid: Grid) -> sp.csr_matrix:
    """Second differences along rows and columns of the node grid (curvature)."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    triples = np.concatenate(
        [np.stack([idx[:, :-2].ravel(), idx[:, 1:-1].ravel(), idx[:, 2:].ravel()], 1),
         np.stack([idx[:-2].ravel(), idx[1:-1].ravel(), idx[2:].ravel()], 1)]
    )  # fmt: skip
    m = len(triples)
    rows = np.repeat(np.arange(m), 3)
    vals = np.tile([1.0, -2.0, 1.0], m)
    return sp.csr_matrix((vals, (rows, triples.ravel())), shape=(m, grid.size))


def _difference_operator(grid: Grid) -> sp.csr_matrix:
    """First differences between horizontally and vertically adjacent nodes."""
    ny, nx = grid.shape
    idx = np.arange(grid.size).reshape(ny, nx)
    pairs = np.concatenate(
        [np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
         np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)]
    )  # fmt: skip
    m = len(pairs)
    rows = np.repeat(np.arange(m), 2)
    vals = np.tile([1.0, -1.0], m)
    return sp.csr_matrix((vals, (rows, pairs.ravel())), shape=(m, grid.size))


COUPLING_ORDER = 1


def solve_mu_grids(
    samples: dict[tuple[str, int], Samples],
    grid: Grid,
    smoothness: float = 0.05,
    coupling: float = 0.2,
) -> dict[tuple[str, int], np.ndarray]:
    """Solve equation (8) for the log-mu control points of every Helmholtz camera.

    Minimises ``sum_i ((a_i - b_i) lambda - delta_i)^2`` (eq. 8) plus
    ``smoothness^2 N_H |D lambda_H|^2`` for each map (D: first differences of
    adjacent control points, N_H: the map's number of constraints, so the
    weight is relative) and ``coupling^2 N |D (lambda_H1 - lambda_H2)|^2``
    for the two maps of one camera, with the gauge fixed explicitly (mean
    of each map's control points = 0).

    Parameters
    ----------
    samples : (camera, channel) -> its eq. (7) constraints.
    grid : the control grid (shared by all maps).
    smoothness, coupling : relative regulariser weights.

    Returns
    -------
    (camera, channel) -> (ny, nx) log mu at the control points.
    """
    keys = sorted(samples)
    n = grid.size
    blocks, rhs = [], []
    D = _difference_operator(grid)
    C = _second_difference_operator(grid) if COUPLING_ORDER == 2 else D
    for h, key in enumerate(keys):
        s = samples[key]
        i1, w1 = grid.weights(s.uv)
        i2, w2 = grid.weights(s.uv2)
        m = len(s.delta)
        rows = np.repeat(np.arange(m), 4)
        A = sp.csr_matrix((w1.ravel(), (rows, (i1 + h * n).ravel())), shape=(m, n * len(keys)))
        A -= sp.csr_matrix((w2.ravel(), (rows, (i2 + h * n).ravel())), shape=(m, n * len(keys)))
        blocks.append(A)
        rhs.append(s.delta)
        scale = np.sqrt(max(m, 1))
        blocks.append(smoothness * scale * _place(D, h, n, len(keys)))
        rhs.append(np.zeros(D.shape[0]))
        gauge = sp.csr_matrix(
            (np.full(n, 1.0 / n), (np.zeros(n, int), np.arange(n) + h * n)),
            shape=(1, n * len(keys)),
        )
        blocks.append(scale * gauge)
        rhs.append(np.zeros(1))
    for h1, k1 in enumerate(keys):
        for h2 in range(h1 + 1, len(keys)):
            if keys[h2][0] != k1[0]:
                continue
            scale = np.sqrt(len(samples[k1].delta) + len(samples[keys[h2]].delta))
            blocks.append(
                coupling * scale * (_place(C, h1, n, len(keys)) - _place(C, h2, n, len(keys)))
            )
            rhs.append(np.zeros(C.shape[0]))
    M = sp.vstack(blocks).tocsr()
    r = np.concatenate(rhs)
    lam = spsolve((M.T @ M).tocsc(), M.T @ r)
    return {key: lam[h * n : (h + 1) * n].reshape(grid.shape) for h, key in enumerate(keys)}


def _place(D: sp.csr_matrix, h: int, n: int, nmaps: int) -> sp.csr_matrix:
    """Operator D acting on block h of a stacked vector of nmaps blocks of size n."""
    left = sp.csr_matrix((D.shape[0], h * n))
    right = sp.csr_matrix((D.shape[0], (nmaps - h - 1) * n))
    return sp.hstack([left, D, right]).tocsr()


def coverage(grid: Grid, uv: np.ndarray, min_samples: int = 3) -> np.ndarray:
    """Calibrated region (height, width): pixels whose 4 control points all have data.

    A control point has data when at least ``min_samples`` constraint
    samples fall in the cells around it.
    """
    idx, _ = grid.weights(uv)
    counts = np.bincount(idx.ravel(), minlength=grid.size).reshape(grid.shape)
    has = (counts >= min_samples).astype(float)
    return grid.dense(has) > 0.999


DEFAULTS = {"grid_spacing_px": None, "step_px": None, "margin_m": 0.004, "min_cos": 0.3,
            "min_signal": 0.05, "smoothness": 0.001, "coupling": 0.1}  # fmt: skip


def load_views(dataset_dir, poses_csv, crosstalk_json=None) -> tuple[Rig, list[PoseView]]:
    """Read every usable board pose (from the marker poses table) and its images."""
    ds = open_dataset(dataset_dir, check_images=False)
    table = pd.read_csv(poses_csv)
    mixing = load_crosstalk(crosstalk_json) if crosstalk_json else {}
    views = []
    for _, row in table.iterrows():
        pose = str(row["pose"])
        R = np.array([[row[f"R{i}{j}"] for j in range(3)] for i in range(3)], float)
        t = np.array([row["t_x"], row["t_y"], row["t_z"]], float)
        images, saturated = {}, {}
        for cam in ds.rig.camera_names:
            img, sat = read_image(ds.photometric_image(pose, cam), ds.rig.image)
            images[cam] = unmix(img, mixing[cam]) if cam in mixing else img
            saturated[cam] = sat
        views.append(PoseView(pose, R, t, images, saturated))
    if len(views) < 3:
        raise ValueError(f"{poses_csv}: {len(views)} usable board poses, need at least 3")
    return ds.rig, views


def calibrate(rig: Rig, views: list[PoseView], **params) -> dict:
    """Photometric calibration of every Helmholtz camera (eqs. 6-8).

    Parameters (keyword, see ``DEFAULTS``): ``grid_spacing_px`` control
    point spacing (default width / 20), ``step_px`` sample spacing in the
    partner camera (default width / 213), ``margin_m`` white-area margin
    around markers and board edges, ``min_cos`` grazing limit, ``min_signal``
    darkest usable intensity, ``smoothness`` and ``coupling`` regulariser
    weights (see :func:`solve_mu_grids`).

    Returns a dict with ``maps`` ("<camera>/<colour>" -> (H, W) float32 mu),
    ``grids`` (same keys -> (ny, nx) log mu control points), ``calibrated``
    (same keys -> (H, W) bool calibrated region), ``offsets`` (pair ->
    eq. 6 relative log scale applied), ``counts`` (constraints per map) and
    ``residual_rms`` (RMS of the eq. 7 residuals per map, log units).
    """
    opts = DEFAULTS | {k: v for k, v in params.items() if v is not None}
    W = rig.image.width
    # Resolution-relative defaults: 20 grid cells and ~210 samples across the width.
    opts["grid_spacing_px"] = float(opts["grid_spacing_px"] or W / 20)
    opts["step_px"] = int(opts["step_px"] or max(1, round(W / 213)))
    grid = Grid(rig.image.width, rig.image.height, float(opts["grid_spacing_px"]))
    samples, singles = {}, {}
    for pr in rig.reciprocal_pairs():
        for a, b, ch in ((pr.cam_a, pr.cam_b, pr.channel_a), (pr.cam_b, pr.cam_a, pr.channel_b)):
            s, uv_a, uv_b, logk = transfer_samples(views, rig, a, b, opts)
            if len(s.delta) == 0:
                raise ValueError(
                    f"photometric calibration: no usable samples for {a}/{COLOURS[ch]} "
                    "(every board sample masked: markers, saturation, grazing or dark)"
                )
            samples[(a, ch)] = s
            singles[(a, ch)] = (uv_a, uv_b, logk)
    grids = solve_mu_grids(samples, grid, opts["smoothness"], opts["coupling"])
    offsets = {}
    for pr in rig.reciprocal_pairs():
        ka, kb = (pr.cam_a, pr.channel_a), (pr.cam_b, pr.channel_b)
        uv_a, uv_b, logk = singles[ka]
        # eq. (6): log mu_a(u_a) - log mu_b(u_b) = log kappa (white board, p_ab = p_ba).
        resid = logk - (grid.interpolate(grids[ka], uv_a) - grid.interpolate(grids[kb], uv_b))
        off = float(np.median(resid))
        grids[kb] = grids[kb] - off
        offsets[f"{pr.cam_a}/{COLOURS[pr.channel_a]}~{pr.cam_b}/{COLOURS[pr.channel_b]}"] = off
    out = {"maps": {}, "grids": {}, "calibrated": {}, "offsets": offsets, "counts": {},
           "residual_rms": {}}  # fmt: skip
    for (cam, ch), g in grids.items():
        key = f"{cam}/{COLOURS[ch]}"
        s = samples[(cam, ch)]
        pred = grid.interpolate(g, s.uv) - grid.interpolate(g, s.uv2)
        out["maps"][key] = np.exp(grid.dense(g)).astype(np.float32)
        out["grids"][key] = g
        out["calibrated"][key] = coverage(grid, np.concatenate([s.uv, s.uv2]))
        out["counts"][key] = len(s.delta)
        out["residual_rms"][key] = float(np.sqrt(np.mean((pred - s.delta) ** 2)))
    out["grid"] = grid
    out["params"] = opts
    return out


def mu_map_errors(result: dict, truth: dict[str, np.ndarray], rig: Rig) -> pd.DataFrame:
    """RMS log error of recovered mu maps against ground truth, up to one scale per pair.

    For each reciprocal pair, one constant (the pair's free scale) is removed
    from the log maps of both its Helmholtz cameras jointly, over their
    calibrated regions. The row "no calibration" does the same for mu = 1.
    """
    rows = []
    for pr in rig.reciprocal_pairs():
        keys = [f"{pr.cam_a}/{COLOURS[pr.channel_a]}", f"{pr.cam_b}/{COLOURS[pr.channel_b]}"]
        for method in ("calibrated", "no calibration"):
            errs = []
            for key in keys:
                m = result["calibrated"][key]
                est = np.log(result["maps"][key][m]) if method == "calibrated" else 0.0
                errs.append(est - np.log(truth[key][m]))
            shift = np.mean(np.concatenate(errs))
            for key, e in zip(keys, errs, strict=True):
                rms = float(np.sqrt(np.mean((e - shift) ** 2)))
                frac = float(result["calibrated"][key].mean())
                rows.append(
                    {
                        "map": key,
                        "method": method,
                        "rms_log_error": rms,
                        "calibrated_fraction": frac,
                    }
                )
    return pd.DataFrame(rows)


def photometric_maps(
    dataset_dir, poses_csv, out_h5, crosstalk_json=None, figure_png=None, **params
) -> dict:
    """Calibrate and write ``photometric.h5`` (results contract) and a Figure-3-like PNG.

    The HDF5 file holds one float32 (H, W) mu map per Helmholtz camera at
    ``<camera>/<colour>``, its control grid at ``grid/<camera>/<colour>``
    (log mu), the calibrated region at ``calibrated/<camera>/<colour>``, and
    as attributes the parameters, the pair offsets and a hash of the inputs.
    Written atomically: no partial file on error.
    """
    rig, views = load_views(dataset_dir, poses_csv, crosstalk_json)
    result = calibrate(rig, views, **params)
    ds = open_dataset(dataset_dir, check_images=False)
    inputs = [ds.photometric_image(v.name, c) for v in views for c in rig.camera_names]
    inputs += [Path(poses_csv)] + ([Path(crosstalk_json)] if crosstalk_json else [])
    with atomic_output(out_h5) as tmp, h5py.File(tmp, "w") as f:
        for key, mu in result["maps"].items():
            f.create_dataset(key, data=mu, compression="gzip")
            f.create_dataset(f"grid/{key}", data=result["grids"][key].astype(np.float32))
            f.create_dataset(
                f"calibrated/{key}", data=result["calibrated"][key], compression="gzip"
            )
        f.attrs["equations"] = "kappa eq. (6), transfer eq. (7), sparse least squares eq. (8)"
        f.attrs["params"] = json.dumps(result["params"])
        f.attrs["pair_offsets"] = json.dumps(result["offsets"])
        f.attrs["constraints"] = json.dumps(result["counts"])
        f.attrs["residual_rms_log"] = json.dumps(result["residual_rms"])
        f.attrs["poses"] = json.dumps([v.name for v in views])
        f.attrs["inputs_sha256"] = sha256_files(inputs)
        f.attrs["crosstalk_unmixed"] = bool(crosstalk_json)
    if figure_png is not None:
        from colourhs.figures import mu_maps_figure

        mu_maps_figure(result["maps"], result["calibrated"], figure_png)
    return result


def read_mu_maps(path: str | Path) -> dict[str, np.ndarray]:
    """``"<camera>/<colour>"`` -> (H, W) mu from a photometric.h5 (ours or ground truth)."""
    with h5py.File(path) as f:
        return {
            f"{cam}/{colour}": f[cam][colour][()]
            for cam in f
            if cam not in ("grid", "calibrated")
            for colour in f[cam]
        }
