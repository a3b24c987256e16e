"""Tests of the surface/evaluation figures in colourhs.figures."""

from __future__ import annotations

import cv2
import matplotlib
import numpy as np
import open3d as o3d
import pytest
from PIL import Image

from colourhs.colours import value_colours
from colourhs.figures import (
    depth_map_figure,
    error_map_figure,
    normal_map_figure,
    render_grid_figure,
    shaded_render,
    write_animation,
)

W, H, F = 80, 60, 100.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
RADIUS, DISTANCE = 0.1, 0.5


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
    assert fg.sum() == pytest.approx(np.pi * rho**2, rel=0.04)
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
    assert fg.sum() > 100
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
    error = rng.random(shape)
    error[0, 0] = np.nan
    aspect = shape[1] / shape[0]
    ratios = [
        _ratio(depth_map_figure(depth, tmp_path / "d.png", title="depth")),
        _ratio(normal_map_figure(normal, tmp_path / "n.png")),
        _ratio(error_map_figure(error, tmp_path / "e.png", "error", unit="deg")),
    ]
    for ratio in ratios:
        # Wide images give wide figures and tall ones tall (a colour bar and title add a margin).
        assert (ratio > 1.5) if aspect > 1 else (ratio < 0.7)
    assert not list(tmp_path.glob(".*"))  # no temporary files left
    nan = np.full(shape, np.nan)
    with pytest.raises(ValueError, match="no finite values"):
        depth_map_figure(nan, tmp_path / "x.png")
    with pytest.raises(ValueError, match="no finite values"):
        normal_map_figure(np.full(shape + (3,), np.nan), tmp_path / "x.png")
    with pytest.raises(ValueError, match="no finite values"):
        error_map_figure(nan, tmp_path / "x.png", "e")
    assert not (tmp_path / "x.png").exists()


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
