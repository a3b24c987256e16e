"""Figures of the pipeline's calibration results (matplotlib, Agg backend, no display)."""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from colourhs.common.colours import value_colours  # noqa: E402
from colourhs.common.progress import bar, stage  # noqa: E402
from colourhs.report.animation import write_animation  # noqa: E402
from colourhs.report.shaded import BACKGROUND, shaded_render  # noqa: E402

log = logging.getLogger(__name__)

__all__ = [
    "chromaticity_figure",
    "chromaticity_rgb",
    "depth_map_figure",
    "error_maps_figure",
    "mu_maps_figure",
    "normal_map_figure",
    "render_grid_figure",
    "shaded_render",
    "shared_scale_images",
    "sigma_maps_figure",
    "write_animation",
    "chromaticity_animation",
    "chromaticity_drift_figure",
]


def chromaticity_rgb(p: np.ndarray) -> np.ndarray:
    """Display image of a chromaticity map: each pixel's ``p / max(p)``, NaN black.

    Parameters
    ----------
    p : ndarray, shape (H, W, 3)
        ``(p_R, p_G, p_B)`` per pixel, NaN where unknown.

    Returns
    -------
    ndarray of float32, shape (H, W, 3)
        R, G, B in [0, 1]: the surface's colour under the rig's white light at full brightness.
    """
    p = np.asarray(p, dtype=np.float64)
    peak = np.max(p, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        rgb = p / peak
    rgb[~np.all(np.isfinite(rgb), axis=-1)] = 0.0
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


def chromaticity_figure(
    intensity: np.ndarray,
    maps: dict[str, np.ndarray],
    out_png: str | Path,
    title: str | None = None,
    intensity_label: str | None = None,
) -> Path:
    """The paper's Figure 6: the object's intensity image and its chromaticity map per camera.

    Parameters
    ----------
    intensity : ndarray, shape (H, W)
        An intensity image of the object (e.g. the sum of its three chromatic captures' matching
        channels in one camera); shown in grey, scaled to its 99.5th percentile.
    maps : dict of str to ndarray, shape (H, W, 3)
        Camera name to chromaticity map, shown by :func:`chromaticity_rgb`.
    out_png : str or Path
        PNG file to write (atomically).
    title : str, optional
        Figure title (e.g. the object's name).
    intensity_label : str, optional
        Camera of the intensity image, for its panel title.

    Returns
    -------
    Path
        ``out_png``.
    """
    intensity = np.asarray(intensity, dtype=np.float64)
    finite = intensity[np.isfinite(intensity)]
    top = np.percentile(finite, 99.5) if finite.size else 1.0
    grey = np.clip(np.nan_to_num(intensity / (top if top > 0 else 1.0)), 0.0, 1.0)
    n = 1 + len(maps)
    h, w = intensity.shape
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.2 * h / w + 0.6), squeeze=False)
    axes = axes[0]
    axes[0].imshow(grey, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
    axes[0].set_title("intensity" + (f" ({intensity_label})" if intensity_label else ""))
    for ax, (camera, p) in zip(axes[1:], maps.items(), strict=True):
        ax.imshow(chromaticity_rgb(p), interpolation="nearest")
        ax.set_title(f"chromaticity {camera}")
    for ax in axes:
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out_png = _save_png(fig, out_png)
    if not os.path.getsize(out_png):
        raise OSError(f"{out_png}: empty figure written")
    return out_png


def mu_maps_figure(
    maps: dict[str, np.ndarray], calibrated: dict[str, np.ndarray], out_png: str | Path
) -> Path:
    """The paper's Figure 3: heat maps of the six Helmholtz cameras' mu maps.

    Each map is shown relative to its median over the calibrated region
    (mu is defined up to one scale per reciprocal pair), on a diverging
    colour map centred at 1 with a labelled bar, the uncalibrated part greyed
    out.

    Parameters
    ----------
    maps : ``"<camera>/<colour>"`` -> (H, W) mu map.
    calibrated : same keys -> (H, W) bool calibrated region.
    out_png : PNG file to write.
    """
    keys = sorted(maps)
    cols = 2
    rows = int(np.ceil(len(keys) / cols))
    h, w = next(iter(maps.values())).shape
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols, 3.4 * rows * h / w + 0.4), squeeze=False
    )
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, key in zip(axes.ravel(), keys, strict=False):
        m = calibrated[key]
        rel = maps[key] / np.median(maps[key][m]) if m.any() else maps[key]
        shown = np.where(m, rel, np.nan)
        im = ax.imshow(shown, cmap="RdBu_r", vmin=0.75, vmax=1.25, interpolation="nearest")
        ax.imshow(np.where(m, np.nan, 0.5), cmap="gray", vmin=0, vmax=1, alpha=0.6)
        ax.set_title(f"mu {key} (relative)")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label="mu / its median", extend="both")
    fig.tight_layout()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.savefig(out_png, dpi=90, format="png")
    finally:
        plt.close(fig)
    return out_png


def _finite_or_raise(a: np.ndarray, what: str) -> np.ndarray:
    """The finite values of ``a``; ValueError when there are none."""
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        raise ValueError(f"{what}: no finite values to show (all NaN or empty)")
    return finite


def _save_png(fig, path: str | Path, dpi: int = 100) -> Path:
    """Save ``fig`` as a PNG at ``path`` atomically and close it."""
    from colourhs.common.files import atomic_output

    path = Path(path)
    try:
        with atomic_output(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png", facecolor="white")
    finally:
        plt.close(fig)
    return path


def _image_axes(h: int, w: int, title: str, colourbar: bool):
    """Figure with one image axes sized to an h x w image (plus room for a colour bar/title)."""
    panel_w = 5.0
    panel_h = panel_w * h / w
    fig_w = panel_w + (1.3 if colourbar else 0.2)
    fig_h = panel_h + (0.5 if title else 0.15)
    fig = plt.figure(figsize=(fig_w, fig_h))
    top = 1.0 - (0.45 if title else 0.075) / fig_h
    bottom = 0.075 / fig_h
    ax = fig.add_axes((0.1 / fig_w, bottom, panel_w / fig_w, top - bottom))
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    cax = (
        fig.add_axes(((panel_w + 0.25) / fig_w, bottom, 0.2 / fig_w, top - bottom))
        if colourbar
        else None
    )
    return fig, ax, cax


def _scalar_map_figure(img, path, title, cmap, vmin, vmax, label) -> Path:
    h, w = img.shape
    fig, ax, cax = _image_axes(h, w, title, colourbar=True)
    cm = matplotlib.colormaps[cmap].with_extremes(bad=BACKGROUND)
    im = ax.imshow(
        np.ma.masked_invalid(img), cmap=cm, vmin=vmin, vmax=vmax, interpolation="nearest"
    )
    fig.colorbar(im, cax=cax, label=label)
    return _save_png(fig, path)


def depth_map_figure(depth_m: np.ndarray, path: str | Path, title: str = "") -> Path:
    """A depth map in millimetres with a colour bar; NaN pixels show as background.

    Parameters
    ----------
    depth_m : ndarray, shape (H, W)
        Depth in metres (z along the camera), NaN where none.
    path : str or Path
        PNG file to write (atomically).
    title : str
        Figure title.

    The colour range spans the 1st to 99th percentile of the finite depths
    (so a few outliers do not wash out the map). A map without a finite depth (a
    frame where nothing was reconstructed) is all background, its title marked
    "(empty)".
    """
    depth_mm = np.asarray(depth_m, dtype=np.float64) * 1000.0
    if depth_mm.ndim != 2:
        raise ValueError(f"depth map must be 2-D (H, W), got shape {depth_mm.shape}")
    finite = depth_mm[np.isfinite(depth_mm)]
    if finite.size == 0:
        title, finite = f"{title} (empty)".strip(), np.zeros(1)
    lo, hi = np.percentile(finite, [1.0, 99.0])
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return _scalar_map_figure(depth_mm, path, title, "viridis", lo, hi, "depth (mm)")


def normal_map_figure(normal: np.ndarray, path: str | Path, title: str = "") -> Path:
    """World-frame unit normals shown as RGB ``(n + 1) / 2``; NaN pixels show as background.

    Parameters
    ----------
    normal : ndarray, shape (H, W, 3)
        Unit normals in the world frame, NaN where none.
    path : str or Path
        PNG file to write (atomically).
    title : str
        Figure title; marked "(empty)" where no pixel has a normal.
    """
    normal = np.asarray(normal, dtype=np.float64)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal map must be (H, W, 3), got shape {normal.shape}")
    valid = np.all(np.isfinite(normal), axis=-1)
    if not valid.any():
        title = f"{title} (empty)".strip()
    rgb = np.clip((np.nan_to_num(normal) + 1.0) / 2.0, 0.0, 1.0)
    rgb[~valid] = BACKGROUND
    h, w = valid.shape
    fig, ax, _ = _image_axes(h, w, title, colourbar=False)
    ax.imshow(rgb, interpolation="nearest")
    return _save_png(fig, path)


def render_grid_figure(
    images: Mapping[str, np.ndarray] | Mapping[str, Mapping[str, np.ndarray]],
    path: str | Path,
    title: str = "",
    ncols: int | None = None,
    colourbar: tuple[str, float, float, str] | None = None,
) -> Path:
    """The paper's Figure 7: shaded renders side by side, labelled by variant.

    Parameters
    ----------
    images : dict
        Either label (variant id) -> image (H, W, 3), shown in one row (or
        wrapped after ``ncols`` panels); or row label (scene) -> {variant ->
        image}, shown as a scenes x variants grid whose columns are the union
        of the variants in first-seen order (a missing image leaves its cell
        empty; ``ncols`` is then ignored).
    path : str or Path
        PNG file to write (atomically).
    title : str
        Figure title.
    colourbar : (cmap, vmin, vmax, label), optional
        One colour bar at the right for every panel (panels coloured on one scale;
        values above ``vmax`` have its colour, shown by the bar's pointed end).
    """
    if not images:
        raise ValueError("render_grid_figure: no images")
    first = next(iter(images.values()))
    if isinstance(first, Mapping):
        rows = {str(r): dict(v) for r, v in images.items()}
        cols: list[str] = []
        for row in rows.values():
            cols += [c for c in row if c not in cols]
        cells = [
            [(row.get(c), c if i == 0 else None) for c in cols]
            for i, row in enumerate(rows.values())
        ]
        row_labels: list[str | None] = list(rows)
    else:
        items = list(images.items())
        n = ncols or len(items)
        cells = [[(img, label) for label, img in items[i : i + n]] for i in range(0, len(items), n)]
        row_labels = [None] * len(cells)
    shown = [c[0] for row in cells for c in row if c[0] is not None]
    if not shown:
        raise ValueError("render_grid_figure: no images")
    h, w = np.asarray(shown[0]).shape[:2]
    nr, nc = len(cells), max(len(r) for r in cells)
    cell_w = 3.0
    bar_w = 1.1 if colourbar else 0.0
    fig, axes = plt.subplots(
        nr,
        nc,
        figsize=(cell_w * nc + 0.2 + bar_w, (cell_w * h / w + 0.35) * nr + (0.4 if title else 0.0)),
        squeeze=False,
    )
    for r, row in enumerate(cells):
        for c in range(nc):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            for spine in ax.spines.values():
                spine.set_visible(False)
            img, label = row[c] if c < len(row) else (None, None)
            if img is not None:
                ax.imshow(np.asarray(img), interpolation="nearest")
            if label is not None and (row_labels[r] is None or r == 0):
                ax.set_title(label)
            if c == 0 and row_labels[r] is not None:
                ax.set_ylabel(row_labels[r])
    if title:
        fig.suptitle(title)
    right = 1.0 - bar_w / fig.get_figwidth()
    fig.tight_layout(rect=(0.0, 0.0, right, 1.0))
    if colourbar:
        cmap, vmin, vmax, label = colourbar
        cax = fig.add_axes(
            (right + 0.15 / fig.get_figwidth(), 0.12, 0.18 / fig.get_figwidth(), 0.7)
        )
        norm = matplotlib.colors.Normalize(vmin, vmax)
        fig.colorbar(matplotlib.cm.ScalarMappable(norm, cmap), cax=cax, label=label, extend="max")
    return _save_png(fig, path)


def _median_p95(values) -> float:
    """The median over arrays of each one's 95th percentile of its finite values."""
    tops = [np.percentile(v[np.isfinite(v)], 95.0) for v in values if np.isfinite(v).any()]
    return float(np.median(tops)) if tops else 1.0


def shared_scale_images(
    errors: Mapping[str, np.ndarray], vmax: float | None = None, cmap: str = "inferno"
) -> tuple[dict[str, np.ndarray], float]:
    """Per-pixel errors of several variants as RGB images on one colour scale.

    Parameters
    ----------
    errors : dict of str to ndarray, shape (H, W)
        Label (variant) -> non-negative error (any unit), NaN where none.
    vmax : float, optional
        Top of the shared scale (0 is the bottom; larger errors get the top colour);
        default the median over the labels of each one's 95th percentile, so that
        one far worse variant (the visual hull's errors beside HS's)
        saturates instead of turning every other map black.
    cmap : str
        Matplotlib colormap name.

    Returns
    -------
    images : dict of str to ndarray of uint8, shape (H, W, 3)
        The same value has the same colour in every image; NaN is the background.
    vmax : float
        The scale's top.
    """
    arrays = {k: np.asarray(e, dtype=np.float64) for k, e in errors.items()}
    finite = _finite_or_raise(np.concatenate([e.ravel() for e in arrays.values()]), "errors")
    if vmax is None:
        vmax = _median_p95(arrays.values())
    if not vmax > 0:
        vmax = float(max(finite.max(), 1e-12))
    images = {}
    for k, e in arrays.items():
        rgb = value_colours(e, 0.0, vmax, cmap).reshape(*e.shape, 3)
        rgb[~np.isfinite(e)] = BACKGROUND
        images[k] = np.round(rgb * 255.0).astype(np.uint8)
    return images, vmax


def error_maps_figure(
    errors: Mapping[str, np.ndarray],
    path: str | Path,
    title: str,
    unit: str = "mm",
    vmax: float | None = None,
    quantity: str = "error",
) -> Path:
    """Every variant's error map side by side on one colour scale, with its colour bar.

    ``errors``: label -> (H, W) error in ``unit``, NaN where none; ``vmax``: top of
    the scale (default: :func:`shared_scale_images`'); ``quantity``: what the colour
    bar names. Up to four panels in a row, else three.
    """
    images, top = shared_scale_images(errors, vmax)
    ncols = len(images) if len(images) <= 4 else 3
    bar_label = f"{quantity} ({unit})"
    return render_grid_figure(
        images, path, title, ncols=ncols, colourbar=("inferno", 0.0, top, bar_label)
    )


def sigma_maps_figure(
    sigmas_mm: Mapping[str, np.ndarray], path: str | Path, vmax: float | None = None
) -> Path:
    """Every variant's depth uncertainty (1 sigma) side by side on one colour scale.

    The figure of :func:`error_maps_figure` (same colour map, layout and colour bar),
    so that it reads beside ``depth_error.png``.

    Parameters
    ----------
    sigmas_mm : dict of str to ndarray, shape (H, W)
        Label (variant) -> ``depth_sigma`` in millimetres, NaN where none.
    path : str or Path
        PNG file to write (atomically).
    vmax : float, optional
        Top of the scale, mm (the depth-error map's, to compare colours; default
        :func:`shared_scale_images`').

    Returns
    -------
    Path
        ``path``.
    """
    title = "depth sigma (1-sigma uncertainty of the depth)"
    return error_maps_figure(sigmas_mm, path, title, "mm", vmax, quantity="sigma")


def _sigma_mm(depth_map) -> np.ndarray | None:
    """A depth map's ``depth_sigma`` in mm on its reconstructed pixels (``mask`` with a
    finite depth), NaN elsewhere; None when it has none or no finite value there."""
    if depth_map.depth_sigma is None:
        return None
    shown = np.asarray(depth_map.mask, bool) & np.isfinite(depth_map.depth)
    sigma = np.where(shown, np.asarray(depth_map.depth_sigma, np.float64) * 1e3, np.nan)
    return sigma if np.isfinite(sigma).any() else None


def scene_figures(
    out_dir: str | Path,
    depths: Mapping[str, str | Path],
    meshes: Mapping[str, str | Path],
    gt_ply: str | Path | None = None,
    animation: Mapping[str, str | Path] | None = None,
    fps: float = 8,
    coloured: Mapping[str, str | Path] | None = None,
    chromaticity: Mapping[str, str | Path] | None = None,
    gt_chromaticity: Mapping[str, str | Path] | None = None,
    calibrated_chromaticity: str | Path | None = None,
) -> list[Path]:
    """A scene's figures, variants side by side (the Snakemake rule's function).

    Writes into ``out_dir``: ``figure7.png`` (shaded renders of every variant's
    mesh, and of the ground truth when given, from the reference camera: the
    paper's Figure 7), and per variant ``<variant>_depth.png``,
    ``<variant>_normal.png`` and, with ground truth, ``depth_error.png``
    (|depth error|, mm) and ``normal_error.png`` (degrees), every variant's map
    on one colour scale with its colour bar (:func:`error_maps_figure`); where a
    variant's depth file has ``depth_sigma``, ``depth_sigma.png``
    (:func:`sigma_maps_figure`: those variants' sigma, mm, on the depth-error
    map's scale when there is ground truth, else on their own); with
    ``animation`` (frame -> mesh of a dynamic scene), ``animation.gif`` of the
    shaded reconstruction over the frames, each labelled with the variant, the
    frame and its place in the sequence (:mod:`colourhs.report.animation`); with
    ``coloured`` (variant -> mesh
    coloured by its Hausdorff distance, from :func:`colourhs.evaluation.accuracy.evaluate_frame`,
    its metrics JSON beside it), ``hausdorff.png``: those meshes rendered, recoloured
    on one scale (viridis, 0 to the median of the variants' 95th percentiles, as
    :func:`shared_scale_images`; distances recovered from the colours by
    :func:`colourhs.common.colours.colour_values`) with its colour bar; with
    ``chromaticity`` (frame -> tracked chromaticity file of a moving coloured
    object), ``chromaticity.gif`` (the reference camera's map over the frames) and
    ``chromaticity_drift.png`` (its sigma, share tracked and, with
    ``gt_chromaticity``, its error and that of ``calibrated_chromaticity`` used
    unchanged; :mod:`colourhs.report.tracking`).

    Shows bars over the variants' maps, the renders and the animation's frames, and
    logs a line at INFO before each error or sigma figure (:mod:`colourhs.common.progress`).
    The empty mesh (a frame with nothing reconstructed) is a blank tile or animation
    frame, its title or label ending in "(empty)".

    Parameters
    ----------
    out_dir : folder to write (created).
    depths, meshes : variant -> results-contract depth file (or the
        :class:`colourhs.common.depthfile.DepthMap` already read from it) / Poisson mesh
        of the frame.
    gt_ply : the frame's ground-truth mesh, or None.
    animation : frame -> mesh PLY, in frame order, or None.
    fps : frames per second of the animation.
    coloured : variant -> error-coloured mesh PLY, or None.
    chromaticity, gt_chromaticity : frame -> tracked / true chromaticity file, in frame
        order, or None.
    calibrated_chromaticity : the object's calibrated maps, or None.

    Returns
    -------
    The PNG/GIF files written.
    """
    from colourhs.common.depthfile import as_depth_map
    from colourhs.common.ply import is_empty_mesh, load_mesh
    from colourhs.evaluation.depth_errors import depth_errors

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    renders, dz_mm, dn_deg, sigma_mm = {}, {}, {}, {}
    gt = load_mesh(gt_ply) if gt_ply is not None else None
    cam = None
    label = "figures: depth and normal maps" + (", depth errors" if gt is not None else "")
    for variant, path in bar(depths.items(), label, len(depths), unit="variant"):
        dm = as_depth_map(path)
        cam = cam or dm
        written.append(depth_map_figure(dm.depth, out / f"{variant}_depth.png", variant))
        written.append(normal_map_figure(dm.normal, out / f"{variant}_normal.png", variant))
        sigma = _sigma_mm(dm)
        if sigma is not None:
            sigma_mm[variant] = sigma
        if gt is not None:
            dz, dn, _ = depth_errors(dm, *gt)
            if np.isfinite(dz).any():
                dz_mm[variant], dn_deg[variant] = np.abs(dz) * 1e3, dn
    top_mm = None  # the depth-error map's scale, which the sigma map shares
    if dz_mm:
        stage(log, "figures: depth and normal error maps")
        top_mm = _median_p95(dz_mm.values())
        title = "|depth error|"
        written.append(error_maps_figure(dz_mm, out / "depth_error.png", title, vmax=top_mm))
        written.append(
            error_maps_figure(dn_deg, out / "normal_error.png", "normal error", unit="deg")
        )
    if sigma_mm:
        stage(log, "figures: depth sigma map")
        written.append(sigma_maps_figure(sigma_mm, out / "depth_sigma.png", top_mm))

    def render(ply):
        v, t, _ = load_mesh(ply, allow_empty=True)  # the empty mesh: a blank tile
        return shaded_render(v, t, cam.K, cam.R, cam.t, cam.width, cam.height, dist=cam.dist)

    def titled(name, ply):  # a blank tile says why
        return f"{name} (empty)" if is_empty_mesh(ply) else name

    if cam is None:
        raise ValueError("scene_figures: no depth files given")
    plys = ({"ground truth": gt_ply} if gt is not None else {}) | dict(meshes)
    for name, ply in bar(plys.items(), "figures: shaded renders", len(plys), unit="mesh"):
        renders[titled(name, ply)] = render(ply)
    written.append(render_grid_figure(renders, out / "figure7.png", "shaded reconstructions"))
    if coloured:
        import open3d as o3d

        from colourhs.common.colours import colour_values
        from colourhs.common.files import note_read

        meshes_mm = {}  # variant -> (vertices, triangles, distance per vertex in mm)
        for variant, ply in coloured.items():
            note_read(ply)
            if is_empty_mesh(ply):  # nothing reconstructed (open3d would report a failed read)
                v, t, _ = load_mesh(ply, allow_empty=True)
                meshes_mm[f"{variant} (empty)"] = (v, t, np.zeros(0))
                continue
            mesh = o3d.io.read_triangle_mesh(str(ply))
            v, t = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
            meta = Path(ply).with_suffix(".json")
            top = json.loads(meta.read_text()).get("colour_vmax_mm") if meta.exists() else None
            if top and mesh.has_vertex_colors():  # the distances, from the colours (to 1/255)
                d = colour_values(np.asarray(mesh.vertex_colors), 0.0, top)
            else:
                d = np.full(len(v), np.nan)
            meshes_mm[variant] = (v, t, d)
        top = _median_p95([d for _, _, d in meshes_mm.values()])
        items = bar(list(meshes_mm.items()), "figures: Hausdorff renders", unit="mesh")
        tiles = {
            variant: shaded_render(
                v,
                t,
                cam.K,
                cam.R,
                cam.t,
                cam.width,
                cam.height,
                vertex_rgb=value_colours(d, 0.0, top),
                dist=cam.dist,
            )
            for variant, (v, t, d) in items
        }
        title = "Hausdorff distance to the ground truth (grey: not evaluated)"
        ncols = 3 if len(tiles) > 4 else None
        scale = ("viridis", 0.0, top, "distance (mm)")
        written.append(render_grid_figure(tiles, out / "hausdorff.png", title, ncols, scale))
    if animation:
        # The animated variant from the results contract's path (<variant>/mesh/<frame>.ply).
        n = len(animation)
        labels = [
            titled(f"{Path(p).parent.parent.name}  frame {f} ({i + 1}/{n})", p)
            for i, (f, p) in enumerate(animation.items())
        ]
        plys = bar(animation.values(), "figures: animation", n, unit="frame")
        frames = (render(ply) for ply in plys)  # one at a time: a long sequence at full size
        written.append(write_animation(frames, out / "animation.gif", fps=fps, labels=labels))
    if chromaticity:
        from colourhs.report.tracking import chromaticity_drift

        stage(log, "figures: chromaticity over the sequence")
        camera = getattr(cam, "camera", None)
        gif = out / "chromaticity.gif"
        written.append(chromaticity_animation(chromaticity, gif, camera, fps=fps))
        drift = chromaticity_drift(chromaticity, gt_chromaticity, calibrated_chromaticity)
        written.append(chromaticity_drift_figure(drift, out / "chromaticity_drift.png"))
    return written


def chromaticity_animation(
    tracked: Mapping[str, str | Path], path: str | Path, camera: str | None = None, fps=8
) -> Path:
    """``chromaticity.gif``: one camera's tracked chromaticity map per frame
    (:func:`colourhs.report.figures.chromaticity_rgb`, unknown black), each frame
    labelled with its name, its place in the sequence and the share of the
    calibrated pixels it still has a p for.

    Parameters
    ----------
    tracked : frame -> tracked chromaticity file (``colourhs track-chromaticity``), in
        frame order.
    path : the GIF to write.
    camera : the camera shown (default: each file's first).
    """
    from colourhs.report.tracking import tracked_maps

    images, labels, n = [], [], len(tracked)
    for i, (frame, h5) in enumerate(tracked.items()):
        cam, f = tracked_maps(h5, camera)
        with f:
            p = f[cam][()]
            share = json.loads(f.attrs.get("tracked", "{}")).get(cam)
            anchor = f.attrs.get("chromatic_frame", "")
        rgb = np.round(255 * chromaticity_rgb(p)).astype(np.uint8)
        # Small maps are enlarged so that the label reads.
        scale = max(1, int(np.ceil(320 / rgb.shape[1])))
        images.append(np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1))
        kept = "" if share is None else f", {share:.0%} tracked"
        chromatic = " (chromatic)" if frame == anchor else ""
        labels.append(f"{cam} frame {frame}{chromatic} ({i + 1}/{n}){kept}")
    return write_animation(images, path, fps=fps, labels=labels)


def chromaticity_drift_figure(drift: Mapping[str, Mapping[str, float]], path: str | Path) -> Path:
    """``chromaticity_drift.png``: :func:`chromaticity_drift` over the frames: the
    errors against the truth (where known) and the tracked maps' median sigma (log p),
    with the share tracked on a second axis."""
    frames = list(drift)
    x = np.arange(len(frames))
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    for key, label, style in (
        ("error", "tracked: RMS log-ratio error", "o-"),
        ("static_error", "calibrated map unchanged (paper)", "s--"),
        ("sigma", "tracked: median sigma of log p", "^:"),
    ):
        y = [drift[f].get(key, np.nan) for f in frames]
        if np.isfinite(y).any():
            ax.plot(x, y, style, label=label, markersize=4)
    ax.set_xlabel("frame")
    ax.set_ylabel("log p")
    ax.set_xticks(x, frames, rotation=60, fontsize=7)
    ax.set_ylim(bottom=0)
    share = ax.twinx()
    share.plot(x, [drift[f].get("tracked", np.nan) for f in frames], color="0.6", lw=1)
    share.set_ylabel("share tracked", color="0.4")
    share.set_ylim(0, 1.05)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("chromaticity over the sequence")
    fig.tight_layout()
    return _save_png(fig, path)
