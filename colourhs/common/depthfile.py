"""The results contract's depth file (``<scene>/<variant>/depth/<frame>.h5``).

One module for both ends: :func:`write_depth` writes a reconstruction
(:class:`DepthResult`, from :mod:`colourhs.reconstruct.frame` or the visual
hull), :func:`read_depth` reads and checks any file in the contract's layout
(:class:`DepthMap`). Datasets ``depth`` (H, W) z-depth in metres along the
reference camera (NaN = none), ``normal`` (H, W, 3) world unit normals,
``confidence`` and ``mask``, optionally ``depth_sigma`` (H, W) the depth's
1-sigma uncertainty in metres, ``uncertain`` (H, W) the pixels left out of
``mask`` for too large a sigma and ``dropped`` (H, W) uint8 why each pixel has
no depth (:data:`DROP_REASONS`); attributes ``camera``, ``K``, ``R``, ``t``,
``dist``, ``method`` and ``params`` (JSON).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from colourhs.capture import Camera
from colourhs.common.files import atomic_output, note_read
from colourhs.common.geometry import camera_centre
from colourhs.common.metrics_csv import DROP_REASONS

__all__ = [
    "DATASETS",
    "DROP_REASONS",
    "DepthMap",
    "DepthResult",
    "as_depth_map",
    "read_depth",
    "write_depth",
]

# DROP_REASONS: why a pixel of the reference camera has no depth, code k + 1 of dataset
# ``dropped`` naming DROP_REASONS[k] and code 0 a pixel with a depth. Defined, each
# reason with its meaning, in colourhs.common.metrics_csv, where the metrics' columns
# (``dropped_<reason>``) are named after it without importing h5py.


@dataclass
class DepthResult:
    """A reconstructed frame in the reference camera.

    Attributes
    ----------
    depth : ndarray of float32, shape (H, W)
        z-depth along the reference camera, metres; NaN = none.
    normal : ndarray of float32, shape (H, W, 3)
        World-frame unit normals; NaN = none.
    confidence : ndarray of float32, shape (H, W)
        Per-pixel confidence in [0, 1].
    mask : ndarray of bool, shape (H, W)
        Reconstructed pixels.
    info : dict
        The method's diagnostics.
    depth_sigma : ndarray of float32, shape (H, W), optional
        1-sigma uncertainty of ``depth``, metres; NaN where none. None: the method
        gives no uncertainty (nothing is written).
    uncertain : ndarray of bool, shape (H, W), optional
        Pixels whose ``depth_sigma`` exceeded the configured tolerance: left out of
        ``mask`` and flagged here. None: nothing is written.
    dropped : ndarray of uint8, shape (H, W), optional
        Why each pixel has no depth: code ``k + 1`` is ``DROP_REASONS[k]``, 0 a pixel
        with a depth. None: nothing is written.
    """

    depth: np.ndarray
    normal: np.ndarray
    confidence: np.ndarray
    mask: np.ndarray
    info: dict
    depth_sigma: np.ndarray | None = None
    uncertain: np.ndarray | None = None
    dropped: np.ndarray | None = None


def write_depth(path, result: DepthResult, camera: Camera, attrs: dict) -> None:
    """Write the results contract's depth HDF5 atomically.

    Datasets ``depth``, ``normal``, ``confidence`` and ``mask``, and ``depth_sigma``
    (float32, metres), ``uncertain`` (bool) and ``dropped`` (uint8 codes, with the
    attribute ``reasons``: :data:`DROP_REASONS` as a JSON list, code ``k + 1`` naming
    ``reasons[k]``) where ``result`` has them (gzip); attributes the camera's
    (``camera``, ``K``, ``R``, ``t``, ``dist``), ``units`` and ``attrs`` (non-scalars
    as JSON).
    """
    with atomic_output(path) as tmp, h5py.File(tmp, "w") as f:
        f.create_dataset("depth", data=result.depth, compression="gzip")
        f.create_dataset("normal", data=result.normal, compression="gzip")
        f.create_dataset("confidence", data=result.confidence, compression="gzip")
        f.create_dataset("mask", data=result.mask, compression="gzip")
        if result.depth_sigma is not None:
            sigma = np.asarray(result.depth_sigma, np.float32)
            f.create_dataset("depth_sigma", data=sigma, compression="gzip")
        if result.uncertain is not None:
            uncertain = np.asarray(result.uncertain, bool)
            f.create_dataset("uncertain", data=uncertain, compression="gzip")
        if result.dropped is not None:
            codes = np.asarray(result.dropped, np.uint8)
            dropped = f.create_dataset("dropped", data=codes, compression="gzip")
            dropped.attrs["reasons"] = json.dumps(list(DROP_REASONS))
        f.attrs["camera"] = camera.name
        f.attrs["K"] = np.asarray(camera.K, float)
        f.attrs["R"] = np.asarray(camera.R, float)
        f.attrs["t"] = np.asarray(camera.t, float)
        f.attrs["dist"] = np.asarray(camera.dist, float)
        f.attrs["units"] = "metres; depth is z along the reference camera"
        for key, value in attrs.items():
            f.attrs[key] = value if isinstance(value, str | int | float) else json.dumps(value)


@dataclass(frozen=True)
class DepthMap:
    """One results-contract depth file (``results/NAME/<scene>/<variant>/depth/<frame>.h5``).

    Attributes
    ----------
    depth : ndarray of float32, shape (H, W)
        z-depth along the reference camera's optical axis, metres; NaN = none.
    normal : ndarray of float32, shape (H, W, 3)
        World-frame unit normals; NaN = none.
    confidence : ndarray of float32, shape (H, W)
        Per-pixel confidence in [0, 1] (ones where the file has none).
    mask : ndarray of bool, shape (H, W)
        Pixels the method considered (finite depth where the file has none).
    depth_sigma : ndarray of float32, shape (H, W), or None
        1-sigma uncertainty of ``depth``, metres, NaN where none; None where the file
        has no ``depth_sigma`` (files written before it, the visual hull).
    uncertain : ndarray of bool, shape (H, W), or None
        Pixels left out of ``mask`` because their sigma exceeded the configured
        tolerance; None where the file has no ``uncertain``.
    dropped : ndarray of uint8, shape (H, W), or None
        Why each pixel has no depth: code ``k + 1`` is ``DROP_REASONS[k]``, 0 a pixel
        with a depth; None where the file has no ``dropped`` (files written before
        it, the visual hull).
    camera : str
        Reference camera name.
    K : ndarray, shape (3, 3)
        Intrinsics, pixels.
    dist : ndarray, shape (n,)
        OpenCV distortion coefficients (zeros for files written without them).
    R, t : ndarray, shapes (3, 3) and (3,)
        World-to-camera pose, ``x_cam = R X + t`` (t in metres).
    method : str
        Reconstruction method (``"bayes"``, ``"ml"``, ``"vh"``, ...; ``""`` if absent).
    params : dict
        The method's parameters and diagnostics (``{}`` if absent).
    path : str
        File it was read from.
    """

    depth: np.ndarray
    normal: np.ndarray
    confidence: np.ndarray
    mask: np.ndarray
    camera: str
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    method: str = ""
    params: dict | None = None
    path: str = ""
    depth_sigma: np.ndarray | None = None
    uncertain: np.ndarray | None = None
    dropped: np.ndarray | None = None

    @property
    def height(self) -> int:
        return int(self.depth.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth.shape[1])

    @property
    def centre(self) -> np.ndarray:
        """Reference camera centre in the world frame, metres, shape (3,)."""
        return camera_centre(self.R, self.t)


#: The contract's datasets of a depth file (``depth`` and ``normal`` are required).
DATASETS = ("depth", "normal", "confidence", "mask", "depth_sigma", "uncertain", "dropped")


def _attr_array(attrs: dict, name, shape, path):
    if name not in attrs:
        raise ValueError(f"{path}: missing attribute {name!r}")
    a = np.asarray(attrs[name], float)
    if a.shape != shape:
        raise ValueError(f"{path}: attribute {name!r} has shape {a.shape}, expected {shape}")
    return a


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _contents(path: Path) -> tuple[dict, dict]:
    """The contract's datasets (:data:`DATASETS`) and every attribute of depth file
    ``path``, read in full; with ``dropped``, its attribute ``reasons`` too (as
    ``dropped_reasons`` among the attributes; None where it has none).

    Raises
    ------
    ValueError
        Naming the file and what does not read (the file itself, its list of datasets
        or attributes, or one dataset or attribute: a truncated file, a corrupt chunk),
        with h5py's reason.
    """

    def read(what: str, get):
        try:
            return get()
        except (OSError, RuntimeError, KeyError) as err:
            raise ValueError(
                f"{path}: {what} does not read ({' '.join(str(err).split())})"
            ) from err

    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise ValueError(f"{path}: not a readable HDF5 depth file ({err})") from err
    with f:
        names = read("the list of datasets", lambda: [n for n in f if n in DATASETS])
        data = {n: read(f"dataset {n!r}", lambda n=n: f[n][()]) for n in names}
        keys = read("the list of attributes", lambda: list(f.attrs))
        attrs = {k: read(f"attribute {k!r}", lambda k=k: f.attrs[k]) for k in keys}
        if "dropped" in data:
            attrs["dropped_reasons"] = read(
                "attribute 'reasons' of dataset 'dropped'",
                lambda: f["dropped"].attrs.get("reasons"),
            )
    return data, attrs


def _drop_codes(codes: np.ndarray, reasons, path) -> np.ndarray:
    """A file's ``dropped`` codes in :data:`DROP_REASONS`' numbering.

    Parameters
    ----------
    codes : ndarray of int
        The dataset ``dropped``: code ``k + 1`` names ``reasons[k]``, 0 a pixel with a depth.
    reasons : str, bytes or None
        Its attribute ``reasons`` (a JSON list of names); None: :data:`DROP_REASONS`.
    path : Path
        The file, for the messages.

    Returns
    -------
    ndarray of uint8
        The codes, renumbered by name where the file lists its reasons in another order.

    Raises
    ------
    ValueError
        On a reason this version does not know, or a code naming no reason.
    """
    try:
        names = DROP_REASONS if reasons is None else tuple(json.loads(_text(reasons)))
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: dataset 'dropped' has unreadable reasons ({err})") from err
    unknown = [n for n in names if n not in DROP_REASONS]
    if unknown:
        raise ValueError(f"{path}: dataset 'dropped' names unknown reasons {unknown}")
    codes = np.asarray(codes)
    if codes.size and (codes.min() < 0 or codes.max() > len(names)):
        raise ValueError(
            f"{path}: dataset 'dropped' has codes {int(codes.min())} to {int(codes.max())}, "
            f"expected 0 to {len(names)} (its reasons)"
        )
    table = np.array([0, *(DROP_REASONS.index(n) + 1 for n in names)], np.uint8)
    return table[codes.astype(np.intp)]


def read_depth(path: str | Path) -> DepthMap:
    """Read and check a results-contract depth file.

    Parameters
    ----------
    path : str or Path
        HDF5 file with datasets ``depth`` (H, W), ``normal`` (H, W, 3) and optionally
        ``confidence``, ``mask``, ``depth_sigma``, ``uncertain`` and ``dropped`` (H, W);
        attributes ``camera``, ``K``, ``R``, ``t`` and optionally ``dist``, ``method``,
        ``params`` (JSON).

    Returns
    -------
    DepthMap

    Raises
    ------
    ValueError
        Naming the file, when it or one of its datasets or attributes does not read
        (truncated, a corrupt chunk: which one, with h5py's reason), a required dataset
        or attribute is missing, a shape is wrong, ``dropped`` has a code or reason
        this version does not know, or the depth map has no pixel at all ("no
        reconstructed pixels"). A map of the right shape without a single finite depth
        reads: a frame where nothing was reconstructed is a result (coverage 0).
    """
    path = Path(path)
    note_read(path)
    data, attrs = _contents(path)
    for name in ("depth", "normal"):
        if name not in data:
            raise ValueError(f"{path}: missing dataset {name!r}")
    depth = np.asarray(data["depth"], np.float32)
    if depth.ndim != 2:
        raise ValueError(f"{path}: dataset 'depth' has shape {depth.shape}, expected (H, W)")
    if depth.size == 0:
        raise ValueError(f"{path}: no reconstructed pixels (empty depth map {depth.shape})")
    h, w = depth.shape
    normal = np.asarray(data["normal"], np.float32)
    if normal.shape != (h, w, 3):
        raise ValueError(f"{path}: dataset 'normal' has shape {normal.shape}, expected {(h, w, 3)}")
    finite = np.isfinite(depth)
    confidence = np.asarray(data.get("confidence", finite), np.float32)
    mask = np.asarray(data.get("mask", finite), bool)
    sigma = np.asarray(data["depth_sigma"], np.float32) if "depth_sigma" in data else None
    uncertain = np.asarray(data["uncertain"], bool) if "uncertain" in data else None
    dropped = np.asarray(data["dropped"]) if "dropped" in data else None
    optional = (("depth_sigma", sigma), ("uncertain", uncertain), ("dropped", dropped))
    for name, a in (("confidence", confidence), ("mask", mask), *optional):
        if a is not None and a.shape != (h, w):
            raise ValueError(f"{path}: dataset {name!r} has shape {a.shape}, expected {(h, w)}")
    if dropped is not None:
        dropped = _drop_codes(dropped, attrs.get("dropped_reasons"), path)
    if "camera" not in attrs:
        raise ValueError(f"{path}: missing attribute 'camera'")
    camera = _text(attrs["camera"])
    K = _attr_array(attrs, "K", (3, 3), path)
    R = _attr_array(attrs, "R", (3, 3), path)
    t = _attr_array(attrs, "t", (3,), path).reshape(3)
    dist = np.asarray(attrs["dist"], float).ravel() if "dist" in attrs else np.zeros(5)
    method = _text(attrs.get("method", ""))
    params = attrs.get("params", "{}")
    try:
        params = json.loads(params) if isinstance(params, str | bytes) else {}
    except json.JSONDecodeError:
        params = {}
    return DepthMap(
        depth,
        normal,
        confidence,
        mask,
        camera,
        K,
        dist,
        R,
        t,
        method,
        params,
        str(path),
        depth_sigma=sigma,
        uncertain=uncertain,
        dropped=dropped,
    )


def as_depth_map(depth: str | Path | DepthMap) -> DepthMap:
    """A stage's depth input as a :class:`DepthMap`, read once.

    Parameters
    ----------
    depth : str, Path or DepthMap
        A results-contract depth file, or the :class:`DepthMap` already read from it
        (the command line reads every depth file to check it before a stage starts,
        :func:`colourhs.cli.parser._check_inputs`, and passes the map on).

    Returns
    -------
    DepthMap
        ``depth`` itself, or :func:`read_depth` of the file.

    Raises
    ------
    ValueError
        As :func:`read_depth`, naming the file.
    """
    return depth if isinstance(depth, DepthMap) else read_depth(depth)
