"""Whether ``rig.json`` agrees with the photometric captures (beyond the paper).

A rig description with a mistake in it (a camera's images under another
camera's name, a transposed R, a camera-to-world pose where OpenCV's
world-to-camera one belongs, a marker length in the wrong unit) makes every
later stage wrong without a single error: the board poses, mu, the depth. The
photometric captures can tell: every board pose shows the same markers to two
or three cameras, and the rig says where each camera is.

For each board pose the board's markers are detected in every camera
(:func:`colourhs.calibration.markers.detect_markers`, corners refined with the
camera's lens), then three checks, each a figure in the same units whatever
the rig:

- **Pairs.** The corners two cameras both see are triangulated from those two
  and reprojected into both: the RMS distance (pixels) is how far the pair's
  rays miss each other, 0 for a consistent pair up to the corners' detection
  noise. A wrong camera spoils both pairs it belongs to and leaves the third
  alone, which names it.
- **Third view.** The same points reprojected into the camera that did not
  triangulate them (where it sees them too): a disagreement along the pair's
  epipolar lines, which the pair alone cannot see.
- **Board.** Every corner seen by two or more cameras triangulated from all of
  them: each marker's side against ``board.marker_length``, the markers'
  centres against the board's layout (a similarity fit, Umeyama: its scale),
  and the corners' distance from their plane, whether the triangulation is
  rigid at all.

:func:`check_rig` returns the figures; :func:`rig_problems` turns those beyond
the tolerances into messages that name the camera (or the board) and the size
of the disagreement.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from itertools import combinations

import numpy as np

from colourhs.calibration.markers import detect_markers
from colourhs.capture import CaptureFormatError, Dataset, read_image
from colourhs.common.geometry import project, triangulate

__all__ = [
    "REPROJECTION_TOL",
    "SCALE_TOL",
    "PLANARITY_TOL",
    "RigCheck",
    "check_rig",
    "rig_problems",
    "validate_rig",
]

REPROJECTION_TOL = 0.005
"""Largest RMS reprojection disagreement, as a fraction of the image diagonal (4 px
at 640 x 480): a pixel error scales with the image (a pose error of a fraction of a
degree moves a point by focal-length pixels), while the mistakes this check is for
move corners by tens of pixels or more on any rig."""

SCALE_TOL = 0.02
"""Largest relative difference between the board's size as triangulated and as
rig.json states it: a relative figure, the same on any rig; a marker length in the
wrong unit, or a board printed at another scale, is far beyond it."""

PLANARITY_TOL = 0.01
"""Largest RMS distance of the triangulated corners from their plane, as a fraction
of the board's diagonal: a rigid, consistent triangulation of a flat board is planar
to well within it on any rig."""


@dataclass(frozen=True)
class RigCheck:
    """What the captures say of a rig description (:func:`check_rig`).

    Attributes
    ----------
    pair_px : {"camA-camB": RMS pixels} two-view reprojection disagreement per pair.
    third_px : {camera: RMS pixels} disagreement of the points triangulated by the
        other two cameras, reprojected into this one.
    marker_scale : the markers' triangulated side over ``board.marker_length``
        (median over markers and poses; 1 when they agree).
    layout_scale : the markers' triangulated centres' spread over the layout's
        (median over poses of the similarity fit's scale; 1 when they agree).
    planarity : RMS distance of the triangulated corners from their plane, as a
        fraction of the board's diagonal.
    corners : {"camA-camB": corners} the corners behind each pair's figure.
    tolerance_px : :data:`REPROJECTION_TOL` in pixels of this rig's images.
    poses : the board poses used.
    """

    pair_px: dict[str, float]
    third_px: dict[str, float]
    marker_scale: float
    layout_scale: float
    planarity: float
    corners: dict[str, int]
    tolerance_px: float
    poses: list[str] = field(default_factory=list)


def _rms(residuals: list[np.ndarray]) -> float:
    """RMS length of 2D residuals (NaN without any)."""
    r = np.concatenate(residuals) if residuals else np.empty((0, 2))
    r = r[np.all(np.isfinite(r), axis=1)]
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan")


def _corner_table(detections, cameras, markers) -> tuple[np.ndarray, np.ndarray]:
    """(V, 4M, 2) pixels of every marker corner in every camera (NaN where unseen),
    and the ids (M,) of the markers seen by any camera."""
    ids = np.array(sorted({m for d in detections.values() for m in d} & set(markers)), int)
    uvs = np.full((len(cameras), 4 * len(ids), 2), np.nan)
    for v, cam in enumerate(cameras):
        for j, m in enumerate(ids):
            if m in detections[cam.name]:
                uvs[v, 4 * j : 4 * j + 4] = detections[cam.name][m]
    return uvs, ids


def _similarity(model: np.ndarray, world: np.ndarray) -> tuple[float, np.ndarray]:
    """Scale s of the similarity world ~ s R model + t (Umeyama), and the
    residuals world - fit (N, 3)."""
    mc, wc = model.mean(axis=0), world.mean(axis=0)
    A, B = model - mc, world - wc
    U, S, Vt = np.linalg.svd(B.T @ A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / np.sum(A**2))
    return s, B - s * A @ R.T


def _plane_rms(points: np.ndarray) -> float:
    """RMS distance of points (N, 3) from their least-squares plane."""
    c = points - points.mean(axis=0)
    return float(np.linalg.svd(c, compute_uv=False)[-1] / np.sqrt(len(points)))


def check_rig(ds: Dataset) -> RigCheck:
    """Check a dataset's rig description against its photometric captures (module docstring).

    Parameters
    ----------
    ds : the opened dataset (:func:`colourhs.capture.open_dataset`); its
        ``photometric/`` poses are read.

    Returns
    -------
    RigCheck
        NaN figures where the captures cannot say (no corner seen by that pair,
        fewer than 4 triangulated markers for the board).
    """
    rig = ds.rig
    cams = rig.cameras
    names = [c.name for c in cams]
    pair_res: dict[str, list] = {f"{a}-{b}": [] for a, b in combinations(names, 2)}
    third_res: dict[str, list] = {n: [] for n in names}
    sides, layouts, plane = [], [], []
    for pose in ds.poses:
        det = {}
        for cam in cams:
            image, _ = read_image(ds.photometric_image(pose, cam.name), rig.image)
            det[cam.name] = detect_markers(image, rig.board, camera=cam)
        uvs, ids = _corner_table(det, cams, rig.board.markers)
        if not len(ids):
            continue
        Ks, ds_, Rs, ts = ([getattr(c, k) for c in cams] for k in ("K", "dist", "R", "t"))
        for (i, a), (j, b) in combinations(enumerate(names), 2):
            X = triangulate(
                uvs[[i, j]], [Ks[i], Ks[j]], [ds_[i], ds_[j]], [Rs[i], Rs[j]], [ts[i], ts[j]]
            )
            ok = np.all(np.isfinite(X), axis=1)
            if not ok.any():
                continue
            for v in (i, j):
                pair_res[f"{a}-{b}"].append(
                    project(X[ok], Ks[v], ds_[v], Rs[v], ts[v]) - uvs[v, ok]
                )
            (k,) = set(range(len(cams))) - {i, j}
            seen = ok & np.all(np.isfinite(uvs[k]), axis=1)
            if seen.any():
                third_res[names[k]].append(
                    project(X[seen], Ks[k], ds_[k], Rs[k], ts[k]) - uvs[k, seen]
                )
        X = triangulate(uvs, Ks, ds_, Rs, ts).reshape(len(ids), 4, 3)
        whole = np.all(np.isfinite(X), axis=(1, 2))  # markers with 4 triangulated corners
        side = np.linalg.norm(X[whole] - np.roll(X[whole], 1, axis=1), axis=2).mean(axis=1)
        sides += list(side / rig.board.marker_length)
        if whole.sum() >= 3:  # three centres span the board's plane
            layout = np.array([rig.board.markers[int(m)] for m in ids[whole]], float)
            layout = np.column_stack([layout, np.zeros(len(layout))])
            layouts.append(_similarity(layout, X[whole].mean(axis=1))[0])
            plane.append(_plane_rms(X[whole].reshape(-1, 3)))
    diagonal = float(np.hypot(*rig.board.size))
    nan = float("nan")
    planarity = float(np.sqrt(np.mean(np.square(plane)))) / diagonal if plane else nan
    return RigCheck(
        pair_px={k: _rms(v) for k, v in pair_res.items()},
        third_px={k: _rms(v) for k, v in third_res.items()},
        marker_scale=float(np.median(sides)) if sides else nan,
        layout_scale=float(np.median(layouts)) if layouts else nan,
        planarity=planarity,
        corners={k: int(sum(len(r) for r in v)) // 2 for k, v in pair_res.items()},
        tolerance_px=REPROJECTION_TOL * float(np.hypot(rig.image.width, rig.image.height)),
        poses=list(ds.poses),
    )


def rig_problems(check: RigCheck) -> list[str]:
    """The disagreements beyond the tolerances, one message each (empty: the rig agrees).

    A camera is named when the pairs it belongs to disagree and the other pair
    does not (or, where every pair agrees, when the points the other two
    triangulate miss it); the board when its size or flatness is off.
    """
    tol = check.tolerance_px
    out = []
    bad = {p for p, r in check.pair_px.items() if r > tol}
    cams = list(check.third_px)
    suspects = [c for c in cams if all((p in bad) == (c in p.split("-")) for p in check.pair_px)]
    figures = ", ".join(f"{p} {r:.2f} px" for p, r in check.pair_px.items())
    if suspects:
        (c,) = suspects
        out.append(
            f"camera {c!r} disagrees with the photometric captures: the board's markers "
            f"seen by {c} and another camera triangulate to points that reproject up to "
            f"{max(check.pair_px[p] for p in bad):.1f} px (RMS) from where they are seen "
            f"(pairs: {figures}; tolerance {tol:.1f} px). Check {c}'s K, R and t (OpenCV's "
            f"world-to-camera pose, metres) and that its images are {c}'s"
        )
    elif bad:
        out.append(
            f"the cameras disagree with the photometric captures: markers seen by two cameras "
            f"triangulate to points that reproject far from where they are seen ({figures}; "
            f"tolerance {tol:.1f} px). Check every camera's K, R and t (OpenCV's "
            "world-to-camera pose, metres) and the images' camera names"
        )
    else:
        for c, r in check.third_px.items():
            if r > tol:
                out.append(
                    f"camera {c!r} disagrees with the photometric captures: the board's markers "
                    f"triangulated by the other two cameras reproject {r:.1f} px (RMS) from where "
                    f"{c} sees them (tolerance {tol:.1f} px). Check {c}'s R and t (OpenCV's "
                    "world-to-camera pose, metres)"
                )
    if not out and abs(check.marker_scale - 1.0) > SCALE_TOL:
        out.append(
            f"board: its markers triangulate {check.marker_scale:.3f} times board.marker_length "
            f"(tolerance {SCALE_TOL:.0%}). Check board.marker_length (metres) against the "
            "printed markers' side, and the cameras' t (metres)"
        )
    if not out and abs(check.layout_scale - 1.0) > SCALE_TOL:
        out.append(
            f"board: its markers' centres triangulate {check.layout_scale:.3f} times as far "
            f"apart as board.markers places them (tolerance {SCALE_TOL:.0%}). Check the "
            "markers' centres (metres) against the printed board"
        )
    if not out and check.planarity > PLANARITY_TOL:
        out.append(
            f"board: its triangulated corners lie {check.planarity:.1%} of its diagonal from "
            f"a plane (RMS; tolerance {PLANARITY_TOL:.0%}): the cameras' poses do not agree"
        )
    return out


def validate_rig(ds: Dataset) -> dict:
    """:func:`check_rig` as a validation: its figures, or an error naming every disagreement.

    Returns
    -------
    dict
        The :class:`RigCheck` as JSON values (NaN as None), for the capture summary.

    Raises
    ------
    CaptureFormatError
        Naming ``rig.json`` and each disagreement of :func:`rig_problems`.
    """
    check = check_rig(ds)
    problems = rig_problems(check)
    if problems:
        raise CaptureFormatError(ds.rig.path, "; ".join(problems))
    return {
        k: (None if isinstance(v, float) and not np.isfinite(v) else v)
        for k, v in asdict(check).items()
    } | {
        "pair_px": {k: _finite(v) for k, v in check.pair_px.items()},
        "third_px": {k: _finite(v) for k, v in check.third_px.items()},
    }


def _finite(x: float) -> float | None:
    """``x`` rounded for a summary, None for NaN."""
    return round(float(x), 4) if np.isfinite(x) else None
