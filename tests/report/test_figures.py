"""Tests of the surface/evaluation figures in colourhs.report.figures."""

from __future__ import annotations

import cv2
import matplotlib
import numpy as np
import open3d as o3d
import pytest
from PIL import Image

from colourhs.common.colours import colour_values, value_colours
from colourhs.report.animation import label_frame
from colourhs.report.figures import (
    depth_map_figure,
    error_maps_figure,
    mu_maps_figure,
    normal_map_figure,
    render_grid_figure,
    shaded_render,
    shared_scale_images,
    sigma_maps_figure,
    write_animation,
)

W, H, F = 80, 60, 100.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
RADIUS, DISTANCE = 0.1, 0.5


def _seen_sphere():
    """A 30-step sphere (vertices, faces, vertex normals), a camera 0.5 m in front of
    it, and its true depth and normal maps as that camera sees them (and where it
    does)."""
    from colourhs.capture import Camera
    from colourhs.common.geometry import look_at, vertex_normals
    from colourhs.common.raycast import render_depth_normals

    v, f = _sphere(30)
    R, t = look_at(np.array([0.0, 0.0, -0.5]), np.zeros(3))
    cam = Camera("cam1", K, np.zeros(5), R, t, "red", np.zeros(3))
    n = vertex_normals(v, f)
    gd, gn = render_depth_normals(v, f, n, cam, W, H)
    return v, f, n, cam, gd, gn, np.isfinite(gd)


def _sphere(resolution: int = 60):
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=RADIUS, resolution=resolution)
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles)


def _render(**kw):
    v, f = _sphere()
    # Sphere at the origin, camera 0.5 m away looking along +z (x_cam = X + t).
    return shaded_render(v, f, K, np.eye(3), np.array([0.0, 0.0, DISTANCE]), W, H, **kw)


def test_value_colours_endpoints_and_nan():
    rgb = value_colours(np.array([2.0, 5.0, np.nan, 9.0, -1.0]), 2.0, 5.0, cmap="viridis")
    cmap = matplotlib.colormaps["viridis"]
    assert rgb.shape == (5, 3) and rgb.dtype == np.float64
    np.testing.assert_allclose(rgb[0], cmap(0.0)[:3])
    np.testing.assert_allclose(rgb[1], cmap(1.0)[:3])
    np.testing.assert_allclose(rgb[2], [0.5, 0.5, 0.5])
    np.testing.assert_allclose(rgb[3], cmap(1.0)[:3])  # clipped
    np.testing.assert_allclose(rgb[4], cmap(0.0)[:3])


def test_shaded_render_sphere_area_and_brightness():
    img = _render()
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    fg = np.any(img < 255, axis=-1)
    # Silhouette of a sphere on the optical axis: a disc of radius f r / sqrt(D^2 - r^2).
    rho = F * RADIUS / np.sqrt(DISTANCE**2 - RADIUS**2)
    assert fg.sum() == pytest.approx(np.pi * rho**2, rel=0.02)  # measured 1.0 % (13 px)
    grey = img.astype(float).mean(axis=-1)
    centre = grey[H // 2 - 1 : H // 2 + 1, W // 2 - 1 : W // 2 + 1].mean()
    assert grey[fg].max() == pytest.approx(centre, abs=2.0)
    v, u = np.nonzero(fg)
    r = np.hypot(u - (W - 1) / 2, v - (H - 1) / 2)
    assert grey[v[r > 0.9 * rho], u[r > 0.9 * rho]].mean() < centre - 40
    assert np.all(img[~fg] == 255)


def test_shaded_render_vertex_colours():
    v, _ = _sphere()
    red = np.tile([1.0, 0.0, 0.0], (len(v), 1))
    img = _render(vertex_rgb=red).astype(int)
    fg = np.any(img < 255, axis=-1)
    assert fg.sum() > 650  # measured 1296
    assert np.all(img[fg, 0] > img[fg, 1] + 20)
    assert np.all(img[fg, 1] == 0) and np.all(img[fg, 2] == 0)
    # uint8 colours too, and a left/right split comes through in the right halves.
    split = np.where(v[:, [0]] < 0, [0, 0, 255], [0, 255, 0]).astype(np.uint8)
    img = _render(vertex_rgb=split).astype(int)
    left, right = img[H // 2, W // 2 - 8], img[H // 2, W // 2 + 8]
    assert left[2] > 150 and left[1] == 0
    assert right[1] > 150 and right[2] == 0


def _ratio(path):
    png = cv2.imread(str(path))
    assert png is not None
    return png.shape[1] / png.shape[0]


@pytest.mark.parametrize("shape", [(30, 90), (90, 30)])
def test_map_figures_write_png_and_refuse_all_nan(tmp_path, shape):
    rng = np.random.default_rng(0)
    depth = 0.5 + 0.01 * rng.random(shape)
    depth[:5] = np.nan
    normal = rng.normal(size=shape + (3,))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal[:, :5] = np.nan
    aspect = shape[1] / shape[0]
    ratios = [
        _ratio(depth_map_figure(depth, tmp_path / "d.png", title="depth")),
        _ratio(normal_map_figure(normal, tmp_path / "n.png")),
    ]
    for ratio in ratios:
        # Wide images give wide figures and tall ones tall (a colour bar and title add a margin).
        assert (ratio > 1.5) if aspect > 1 else (ratio < 0.7)
    assert not list(tmp_path.glob(".*"))  # no temporary files left
    # A frame with nothing reconstructed: all background, no error.
    nan = np.full(shape, np.nan)
    for png in (
        depth_map_figure(nan, tmp_path / "x.png", "bayes_dyn"),
        normal_map_figure(np.full(shape + (3,), np.nan), tmp_path / "y.png", "bayes_dyn"),
    ):
        img = cv2.imread(str(png))
        centre = img[img.shape[0] // 2, img.shape[1] // 2].astype(int)
        assert np.ptp(centre) == 0 and centre[0] > 200  # background grey-white


def test_normal_map_colours(tmp_path):
    # A constant +z normal map shows (0.5, 0.5, 1) everywhere inside the image.
    normal = np.zeros((40, 40, 3))
    normal[..., 2] = 1.0
    png = cv2.imread(str(normal_map_figure(normal, tmp_path / "n.png")))[..., ::-1]
    centre = png[png.shape[0] // 2, png.shape[1] // 2].astype(int)
    np.testing.assert_allclose(centre, [128, 128, 255], atol=2)


def test_animation_frames(tmp_path):
    frames = [np.full((12, 16, 3), 40 * i, np.uint8) for i in range(5)]
    path = write_animation(frames, tmp_path / "a.gif", fps=5)
    with Image.open(path) as gif:
        assert gif.n_frames == 5
        assert gif.size == (16, 12)
        assert gif.info["duration"] == 200
    with pytest.raises(ValueError, match="no frames"):
        write_animation([], tmp_path / "b.gif")
    with pytest.raises(ValueError, match="shape"):
        write_animation([frames[0], np.zeros((10, 16, 3), np.uint8)], tmp_path / "b.gif")
    assert not (tmp_path / "b.gif").exists()


@pytest.mark.slow
def test_animation_streams_frames_into_the_same_gif(tmp_path):
    """A generator of frames is consumed one frame at a time, each kept as its
    palette image: NumPy never holds more than a frame or two (traced peak
    4.6 MB here; 55 MB before, the 30 frames and their labelled copies as lists),
    and the file is the one Pillow writes from the RGB frames (its own adaptive
    palette)."""
    import tracemalloc

    y, x = np.mgrid[0:480, 0:640]
    base = np.stack([x % 256, (2 * y) % 256, ((x * y) // 97) % 256], -1).astype(np.uint8)
    del x, y

    def frame(i):
        return np.roll(base, 7 * i, axis=1)  # a fresh 0.92 MB array per frame

    labels = [f"bayes_full  frame {i:06d} ({i + 1}/30)" for i in range(30)]
    tracemalloc.start()
    try:
        write_animation((frame(i) for i in range(30)), tmp_path / "a.gif", fps=8, labels=labels)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8e6  # measured 4.6 MB; 30 frames of 0.92 MB each as a list: 27.6 MB
    rgb = [Image.fromarray(label_frame(frame(i), labels[i]), mode="RGB") for i in range(30)]
    rgb[0].save(
        tmp_path / "b.gif", format="GIF", save_all=True, append_images=rgb[1:], duration=125, loop=0
    )
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()


def test_animation_frames_carry_their_labels(tmp_path):
    """Each frame says which variant and frame it shows. The label box is
    drawn into the frame's corner (dark text on a lightened box), the rest of the
    frame untouched; measured on 240x320 grey frames: 6.4 % of the pixels change, all
    in the top 21 rows."""
    frames = [np.full((240, 320, 3), 90, np.uint8) for _ in range(3)]
    labels = [f"bayes_full  frame 00000{i} ({i + 1}/3)" for i in range(3)]
    path = write_animation(frames, tmp_path / "a.gif", fps=5, labels=labels)
    with Image.open(path) as gif:
        assert gif.n_frames == 3  # equal grey frames stay apart: their labels differ
        gif.seek(1)
        img = np.asarray(gif.convert("RGB")).astype(int)
    changed = np.any(img != 90, axis=2)
    rows, cols = np.nonzero(changed)
    assert rows.max() < 25 and cols.max() < 250  # the label box, top left (20, 232)
    assert 0.05 < changed.mean() < 0.08  # measured 0.064
    assert img[rows, cols].min() < 60  # dark text on the box
    with pytest.raises(ValueError, match="labels"):
        write_animation(frames, tmp_path / "b.gif", labels=labels[:2])


def test_render_grid_figure(tmp_path):
    img = np.full((30, 40, 3), 200, np.uint8)
    p1 = render_grid_figure({"vh": img, "bayes_full": img}, tmp_path / "row.png", title="t")
    grid = {"s1": {"vh": img, "bayes_full": img}, "s2": {"vh": img}}
    p2 = render_grid_figure(grid, tmp_path / "grid.png")
    row, full = cv2.imread(str(p1)), cv2.imread(str(p2))
    assert row.shape[1] > row.shape[0]
    assert full.shape[0] > row.shape[0] * 1.5  # two rows
    with pytest.raises(ValueError):
        render_grid_figure({}, tmp_path / "none.png")


def test_shared_scale_and_error_maps_figure(tmp_path):
    a = np.array([[0.0, 1.0], [2.0, np.nan]])
    b = np.array([[2.0, 10.0], [1.0, 0.0]])
    images, vmax = shared_scale_images({"vh": a, "bayes_full": b})
    # the median of each map's 95th percentile: (1.9 + 8.8) / 2 mm
    assert vmax == pytest.approx(5.35)
    # one scale: the same error has the same colour in both maps
    np.testing.assert_array_equal(images["vh"][1, 0], images["bayes_full"][0, 0])  # 2 mm
    np.testing.assert_array_equal(images["vh"][0, 1], images["bayes_full"][1, 0])  # 1 mm
    np.testing.assert_array_equal(images["vh"][1, 1], [255, 255, 255])  # NaN: background
    assert shared_scale_images({"x": b}, vmax=4.0)[1] == 4.0
    # one figure with the panels side by side and a colour bar (wider than without)
    img = np.full((30, 40, 3), 200, np.uint8)
    plain = cv2.imread(str(render_grid_figure({"a": img, "b": img}, tmp_path / "p.png")))
    path = error_maps_figure({"vh": a, "bayes_full": b}, tmp_path / "e.png", "|dz|")
    fig = cv2.imread(str(path))
    assert fig.shape[1] - plain.shape[1] == pytest.approx(110, abs=2)  # 1.1 in at 100 dpi
    with pytest.raises(ValueError, match="no finite values"):
        error_maps_figure({"vh": np.full((2, 2), np.nan)}, tmp_path / "x.png", "e")


def test_colour_values_inverts_value_colours():
    v = np.array([0.0, 0.3, 1.7, 2.5, np.nan, 4.0])
    rgb8 = np.round(value_colours(v, 0.0, 2.5) * 255).astype(np.uint8)  # as a PLY stores them
    back = colour_values(rgb8, 0.0, 2.5)
    finite = np.isfinite(v)
    np.testing.assert_allclose(back[finite], np.clip(v[finite], 0, 2.5), atol=2.5 / 255)
    assert np.isnan(back[4])  # the no-value grey


def test_scene_figures_share_one_scale(tmp_path):
    """Two variants (depth 1 mm and 3 mm behind a sphere's truth): one depth-error and one
    normal-error figure for both, Figure 7, and hausdorff.png from error-coloured meshes
    whose own colour scales differ (2 and 8 mm), recoloured on one scale."""
    import json

    from colourhs.capture import Camera
    from colourhs.common.depthfile import DepthResult, write_depth
    from colourhs.common.geometry import look_at, vertex_normals
    from colourhs.common.ply import write_ply
    from colourhs.common.raycast import render_depth_normals
    from colourhs.report.figures import scene_figures

    v, f = _sphere(30)
    n = vertex_normals(v, f)
    R, t = look_at(np.array([0.0, 0.0, -0.5]), np.zeros(3))
    cam = Camera("cam1", K, np.zeros(5), R, t, "red", np.zeros(3))
    gd, gn = render_depth_normals(v, f, n, cam, W, H)
    gt = write_ply(tmp_path / "gt.ply", v, f, n)
    depths, meshes, coloured = {}, {}, {}
    for variant, dz_mm, top in (("vh", 3.0, 8.0), ("bayes_full", 1.0, 2.0)):
        ok = np.isfinite(gd)
        res = DepthResult(
            (gd + dz_mm / 1e3).astype(np.float32),
            gn.astype(np.float32),
            ok.astype(np.float32),
            ok,
            {},
            # the visual hull has no sigma; bayes_full's is 0.5 mm
            depth_sigma=None if variant == "vh" else np.full(gd.shape, 5e-4, np.float32),
        )
        depths[variant] = tmp_path / f"{variant}.h5"
        write_depth(depths[variant], res, cam, {"method": "test"})
        meshes[variant] = gt
        coloured[variant] = tmp_path / f"{variant}_eval.ply"
        write_ply(coloured[variant], v, f, n, colours=value_colours(np.full(len(v), dz_mm), 0, top))
        coloured[variant].with_suffix(".json").write_text(json.dumps({"colour_vmax_mm": top}))
    written = scene_figures(tmp_path / "figs", depths, meshes, gt, coloured=coloured)
    names = sorted(p.name for p in written)
    assert names == [
        "bayes_full_depth.png",
        "bayes_full_normal.png",
        "depth_error.png",
        "depth_sigma.png",
        "figure7.png",
        "hausdorff.png",
        "normal_error.png",
        "vh_depth.png",
        "vh_normal.png",
    ]
    # one scale, 0 to 2 mm (the median of the variants' 3 and 1 mm): the centre of vh's
    # panel has the top colour (3 mm, saturated), bayes_full's half of it (1 mm), in both
    # figures (each PLY's own scale had 3/8 and 1/2 of its top: vh the darker one)
    for name, cmap in (("hausdorff.png", "viridis"), ("depth_error.png", "inferno")):
        img = cv2.imread(str(tmp_path / "figs" / name))[..., ::-1].astype(float)
        row = img[img.shape[0] // 2]
        cols = np.flatnonzero(np.any(row < 250, axis=-1))
        runs = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)[:2]  # the two panels
        for run, mm in zip(runs, (3.0, 1.0), strict=True):
            want = value_colours(np.array([mm]), 0.0, 2.0, cmap)[0] * 255
            np.testing.assert_allclose(row[run[len(run) // 2]], want, atol=12)  # shaded 0.97
    # the sigma map on the depth error's scale (0 to 2 mm): one panel (bayes_full), 0.5 mm
    img = cv2.imread(str(tmp_path / "figs" / "depth_sigma.png"))[..., ::-1].astype(float)
    assert img.shape[:2] == (300, 430)  # one 80 x 60 panel: (3 + 1.3) x (2.25 + 0.75) in
    row = img[img.shape[0] // 2]
    cols = np.flatnonzero(np.any(row < 250, axis=-1))
    panel = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)[0]
    want = value_colours(np.array([0.5]), 0.0, 2.0, "inferno")[0] * 255
    np.testing.assert_allclose(row[panel[len(panel) // 2]], want, atol=3)


def test_sigma_maps_figure_size_and_scale(tmp_path):
    """Two variants' sigma maps (80 x 60 px) in one figure the size of the depth-error
    figure's: two 3 in panels plus 1.3 in of colour bar and margins, 3 in tall (panel
    2.25 in, label 0.35 in, title 0.4 in), at 100 dpi: 730 x 300 px. Without a given
    scale the top is the median of the maps' 95th percentiles (1 and 3 mm: 2 mm), so the
    1 mm map's centre has the scale's middle colour, the 3 mm map's its top."""
    sigmas = {"bayes_ph": np.full((H, W), 1.0), "bayes_full": np.full((H, W), 3.0)}
    sigmas["bayes_ph"][:5] = np.nan  # no sigma: background
    path = sigma_maps_figure(sigmas, tmp_path / "figs" / "depth_sigma.png")
    img = np.asarray(Image.open(path).convert("RGB")).astype(float)
    assert img.shape == (300, 730, 3)
    row = img[img.shape[0] // 2]
    cols = np.flatnonzero(np.any(row < 250, axis=-1))
    runs = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)[:2]
    for run, mm in zip(runs, (1.0, 3.0), strict=True):
        want = value_colours(np.array([mm]), 0.0, 2.0, "inferno")[0] * 255
        np.testing.assert_allclose(row[run[len(run) // 2]], want, atol=3)
    # a given top (the depth error's) sets the scale
    path = sigma_maps_figure(sigmas, tmp_path / "fixed.png", vmax=4.0)
    row = np.asarray(Image.open(path).convert("RGB")).astype(float)[150]
    cols = np.flatnonzero(np.any(row < 250, axis=-1))
    run = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)[0]
    want = value_colours(np.array([1.0]), 0.0, 4.0, "inferno")[0] * 255
    np.testing.assert_allclose(row[run[len(run) // 2]], want, atol=3)
    with pytest.raises(ValueError, match="no finite values"):
        sigma_maps_figure({"vh": np.full((H, W), np.nan)}, tmp_path / "none.png")


def test_mu_maps_diverge_about_one_and_grey_the_uncalibrated_part(tmp_path):
    """The mu maps on a diverging colour map centred at 1, not a rainbow.
    Maps ramping from 0.7 to 1.3 of their median across the width show red and blue
    ends and no green-dominant pixel (a rainbow's middle is green: with "turbo" this
    test counts 25,071 of them). Measured: 24,814 red, 36,633 blue, 0 green pixels."""
    rel = np.linspace(0.7, 1.3, W) * np.ones((H, 1))
    calibrated = np.ones((H, W), bool)
    calibrated[:, :4] = False  # greyed out
    maps = {"cam0/red": rel * 3.0, "cam1/green": rel * 0.5}
    out = mu_maps_figure(maps, {k: calibrated for k in maps}, tmp_path / "mu.png")
    img = np.asarray(Image.open(out).convert("RGB")).astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    red = (r > 150) & (r - b > 80) & (r - g > 80)
    blue = (b > 100) & (b - r > 60) & (b - g > 20)
    green = (g - r > 40) & (g - b > 40)
    assert red.sum() > 15000 and blue.sum() > 15000
    assert green.sum() == 0


def test_scene_figures_sigma_map_without_ground_truth(tmp_path):
    """A scene without ground truth has no error maps but its sigma map, on its own
    scale (the one variant's 95th percentile: 2 mm, so the 1 mm left half has the
    scale's middle colour)."""
    from colourhs.common.depthfile import DepthResult, write_depth
    from colourhs.common.ply import write_ply
    from colourhs.report.figures import scene_figures

    v, f, n, cam, gd, gn, ok = _seen_sphere()
    sigma = np.where(np.arange(W) < W // 2, 1e-3, 2e-3) * np.ones((H, 1))
    res = DepthResult(
        gd.astype(np.float32),
        gn.astype(np.float32),
        ok.astype(np.float32),
        ok,
        {},
        depth_sigma=sigma.astype(np.float32),
    )
    write_depth(tmp_path / "b.h5", res, cam, {"method": "bayes"})
    mesh = write_ply(tmp_path / "m.ply", v, f, n)
    depths, meshes = {"bayes_full": tmp_path / "b.h5"}, {"bayes_full": mesh}
    written = scene_figures(tmp_path / "figs", depths, meshes)
    assert sorted(p.name for p in written) == [
        "bayes_full_depth.png",
        "bayes_full_normal.png",
        "depth_sigma.png",
        "figure7.png",
    ]
    img = np.asarray(Image.open(tmp_path / "figs" / "depth_sigma.png").convert("RGB"))
    assert img.shape == (300, 430, 3)
    row = img[img.shape[0] // 2].astype(float)
    cols = np.flatnonzero(np.any(row < 250, axis=-1))
    panel = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)[0]
    for at, mm in ((0.3, 1.0), (0.7, 2.0)):  # left and right of the sphere's middle
        want = value_colours(np.array([mm]), 0.0, 2.0, "inferno")[0] * 255
        np.testing.assert_allclose(row[panel[int(at * len(panel))]], want, atol=3)


def test_shaded_render_of_the_empty_mesh_is_blank():
    """The empty mesh (a frame with nothing reconstructed): the background alone."""
    empty = np.zeros((0, 3))
    for rgb in (None, np.zeros((0, 3), np.uint8)):
        img = shaded_render(empty, np.zeros((0, 3), int), K, np.eye(3), np.ones(3), W, H, rgb)
        assert img.shape == (H, W, 3) and img.dtype == np.uint8 and np.all(img == 255)


def test_scene_figures_show_the_empty_mesh_as_a_blank_tile(tmp_path, monkeypatch):
    """A variant whose mesh is the empty mesh: a blank tile titled "(empty)" in Figure 7
    and hausdorff.png (whose scale is then the other variant's: its 2 mm), and a blank
    animation frame labelled so; no error."""
    import json

    from colourhs.common.depthfile import DepthResult, write_depth
    from colourhs.common.ply import write_ply
    from colourhs.report import figures

    shown = {}  # figure -> what it was given

    def grid(tiles, path, *args, **kw):
        shown[path.name] = (dict(tiles), args)
        return render_grid_figure(tiles, path, *args, **kw)

    def animate(images, path, fps, labels):
        shown[path.name] = (list(images), labels)
        return write_animation(shown[path.name][0], path, fps, labels)

    monkeypatch.setattr(figures, "render_grid_figure", grid)
    monkeypatch.setattr(figures, "write_animation", animate)
    v, f, n, cam, gd, gn, ok = _seen_sphere()
    res = DepthResult(gd.astype(np.float32), gn.astype(np.float32), ok.astype(np.float32), ok, {})
    write_depth(tmp_path / "d.h5", res, cam, {"method": "test"})
    empty, no_faces = np.zeros((0, 3)), np.zeros((0, 3), np.int32)
    mesh, coloured = {}, {}
    for variant, frame in (("vh", "000000"), ("bayes_dyn", "000000"), ("bayes_dyn", "000001")):
        (tmp_path / variant / "mesh").mkdir(parents=True, exist_ok=True)
        (tmp_path / variant / "eval").mkdir(exist_ok=True)
        path, eval_ply = (tmp_path / variant / d / f"{frame}.ply" for d in ("mesh", "eval"))
        if (variant, frame) == ("bayes_dyn", "000000"):
            write_ply(path, empty, no_faces, empty)
            write_ply(eval_ply, empty, no_faces, empty, colours=empty)
        else:
            write_ply(path, v, f, n)
            write_ply(eval_ply, v, f, n, colours=value_colours(np.full(len(v), 2.0), 0.0, 4.0))
        eval_ply.with_suffix(".json").write_text(json.dumps({"colour_vmax_mm": 4.0}))
        mesh.setdefault(variant, path)
        coloured.setdefault(variant, eval_ply)
    depths = {"vh": tmp_path / "d.h5", "bayes_dyn": tmp_path / "d.h5"}
    frames = {p.stem: p for p in sorted((tmp_path / "bayes_dyn" / "mesh").glob("*.ply"))}
    written = figures.scene_figures(
        tmp_path / "figs", depths, mesh, animation=frames, coloured=coloured
    )
    assert {"figure7.png", "hausdorff.png", "animation.gif"} <= {p.name for p in written}
    assert all(p.exists() for p in written)
    for name in ("figure7.png", "hausdorff.png"):
        tiles, args = shown[name]
        assert list(tiles) == ["vh", "bayes_dyn (empty)"]
        assert np.all(tiles["bayes_dyn (empty)"] == 255)
        assert np.any(tiles["vh"] < 255, axis=-1).sum() > 500  # the sphere
    scale = shown["hausdorff.png"][1][2]
    assert scale[2] == pytest.approx(2.0, abs=4.0 / 255)  # vh's 2 mm, to a colour step
    images, labels = shown["animation.gif"]
    assert labels == ["bayes_dyn  frame 000000 (1/2) (empty)", "bayes_dyn  frame 000001 (2/2)"]
    assert np.all(images[0] == 255) and np.any(images[1] < 255)
