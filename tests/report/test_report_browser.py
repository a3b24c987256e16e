"""The evaluation report as a browser shows it (headless Chromium at 1400 x 900).

Reports are built from synthetic inputs shaped like a real run's (five variants,
every metric column of colourhs.evaluation.accuracy, the figures colourhs.report.figures writes
at their real pixel sizes), loaded by ``chromium --headless --dump-dom`` with a
small script that writes the page's measurements into the DOM on ``load``, and
by ``--screenshot``. Skipped when no Chromium is installed (scripts/setup.sh
installs Debian's ``chromium``).
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pandas as pd
import pytest
from PIL import Image

from colourhs.common.ply import write_ply
from colourhs.report.page import REQUIRED_COLUMNS, build_report
from colourhs.report.tables import EXTRA_COLUMNS
from colourhs.workflow.variants import VARIANT_ORDER

CHROMIUM = next(
    (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None
)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium on PATH (scripts/setup.sh installs Debian's chromium)"
)
WIDTH, HEIGHT = 1400, 900
_sphere = o3d.geometry.TriangleMesh.create_sphere(0.05, resolution=12)  # 528 triangles
SPHERE = (np.asarray(_sphere.vertices), np.asarray(_sphere.triangles))

# Written into the page on load: overflow, the images' state, the page height, the
# summary table's scroll and client widths, the displayed width of Figure 7, the pixels
# each 3D view's canvas drew (red below 250).
MEASURE = """<script>addEventListener("load", () => {
  const d = document.documentElement, imgs = [...document.images];
  const f7 = imgs.filter(i => /figure7/.test(i.src)).map(i => i.clientWidth);
  const wide = [...document.querySelectorAll("body *")].filter(e =>
    !e.parentElement.closest(".scroll, pre") && e.getBoundingClientRect().right > innerWidth)
    .map(e => e.tagName + "." + e.className);
  const summary = document.querySelector("#summary + .scroll");
  const drawn = [...document.querySelectorAll(".viewer canvas")].map(c => c.getContext("2d")
    .getImageData(0, 0, c.width, c.height).data.filter((x, i) => i % 4 == 0 && x < 250).length);
  d.dataset.measure = JSON.stringify({scrollWidth: d.scrollWidth, height: d.scrollHeight,
    summary: [summary.scrollWidth, summary.clientWidth],
    images: imgs.length, broken: imgs.filter(i => !i.complete || i.naturalWidth === 0)
    .map(i => i.getAttribute("src")), figure7: f7, wide: wide, drawn: drawn});
});</script>"""


def _png(path: Path, w: int, h: int, value: int) -> None:
    img = np.full((h, w, 3), value, np.uint8)
    img[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] = 255 - value
    assert cv2.imwrite(str(path), img)


def _make_report(root: Path, n_scenes: int, n_frames: int) -> Path:
    """A report of ``n_scenes`` scenes of ``n_frames`` frames, five variants each."""
    rng = np.random.default_rng(n_scenes * 100 + n_frames)
    scenes = ["plane"] + [f"scene{i}" for i in range(1, n_scenes)]  # plane: the paper's column
    frames = [f"{f:06d}" for f in range(n_frames)]
    metric_cols = [*REQUIRED_COLUMNS[3:], *EXTRA_COLUMNS]
    rows = [
        {
            "scene": s,
            "frame": f,
            "variant": v,
            **dict(zip(metric_cols, rng.uniform(0, 9, len(metric_cols)), strict=True)),
        }
        for s in scenes
        for f in frames
        for v in VARIANT_ORDER
    ]
    metrics = root / "reports" / "demo" / "metrics.csv"
    metrics.parent.mkdir(parents=True)
    pd.DataFrame(rows, columns=[*REQUIRED_COLUMNS, *EXTRA_COLUMNS]).to_csv(metrics, index=False)
    figures = {}
    for i, s in enumerate(scenes):
        d = root / "reports" / "demo" / "figures" / s
        d.mkdir(parents=True)
        _png(d / "figure7.png", 1820, 300, 40 * i)  # render_grid_figure's size, 6 panels
        for stem in ("depth_error", "depth_sigma", "normal_error", "hausdorff"):  # 3 x 2 panels
            _png(d / f"{stem}.png", 1030, 560, 60)
        for v in VARIANT_ORDER:
            _png(d / f"{v}_depth.png", 630, 425, 90)  # _image_axes with a colour bar
            _png(d / f"{v}_normal.png", 520, 425, 120)
        if n_frames > 1:
            ims = [Image.fromarray(np.full((480, 640, 3), 30 * k, np.uint8)) for k in range(3)]
            ims[0].save(d / "animation.gif", save_all=True, append_images=ims[1:], loop=0)
        figures[s] = d
        for v in VARIANT_ORDER:  # the error-coloured meshes of the 3D view
            ply = root / "results" / "demo" / s / v / "eval" / "000000.ply"
            ply.parent.mkdir(parents=True)
            write_ply(ply, SPHERE[0], SPHERE[1], colours=np.full(SPHERE[0].shape, 0.5))
    calib = root / "results" / "demo" / "calib"
    calib.mkdir(parents=True)
    _png(calib / "photometric.png", 1080, 720, 100)
    _png(calib / "chromaticity_toy.png", 1200, 400, 200)
    long_value = "/a/very/long/path/without/any/spaces/" * 8  # must wrap, not overflow
    config = {"datasets": {"demo": {"path": long_value}}, "reconstruction": {"params": {}}}
    return build_report(
        root / "reports" / "demo" / "index.html",
        "demo",
        metrics,
        sorted(calib.iterdir()),
        figures,
        [],
        config,
        extra={"note": long_value},
        results_dir=root / "results" / "demo",
        views=True,
    )


def _start(page: Path, screenshot: Path | None = None) -> subprocess.Popen:
    """Load ``page`` (a copy with :data:`MEASURE` added, beside it) in headless Chromium."""
    probe = page.with_name("_measure.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", MEASURE + "</body>"))
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        f"--window-size={WIDTH},{HEIGHT}",
        "--dump-dom",
        probe.as_uri(),
    ]
    if screenshot is not None:
        cmd.insert(-2, f"--screenshot={screenshot}")
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _measurements(run: subprocess.Popen) -> dict:
    """What :data:`MEASURE` wrote, from Chromium's DOM dump."""
    out, err = run.communicate(timeout=120)
    m = re.search(r'data-measure="([^"]*)"', out)
    assert m, f"no measurements from chromium (rc {run.returncode}): {err[-2000:]}"
    return json.loads(html.unescape(m.group(1)))


def test_report_fits_1400px_and_stays_short(tmp_path):
    """No horizontal overflow at 1400 px, every image loaded, and a height that does
    not grow with scenes (one scene's tab at a time, the summary table scrolls past
    36 em) nor with frames beyond the per-frame plot and the animation."""
    sizes = {"s2f1": (2, 1), "s6f1": (6, 1), "s6f30": (6, 30)}
    runs = {
        k: _start(_make_report(tmp_path / k, *n), tmp_path / "report.png" if k == "s2f1" else None)
        for k, n in sizes.items()
    }
    m = {k: _measurements(r) for k, r in runs.items()}
    for k, (n_scenes, n_frames) in sizes.items():
        assert m[k]["scrollWidth"] <= WIDTH, m[k]["wide"]  # measured 1400: nothing wider
        assert not m[k]["wide"]
        assert m[k]["broken"] == []  # every <img> loaded, those of hidden tabs too
        assert m[k]["images"] == 2 + n_scenes * (15 + (n_frames > 1))  # + animation
        summary = m[k]["summary"]
        assert summary[0] <= summary[1], summary  # the summary needs no sideways scrolling
        # one scene shown: its Figure 7 full width (the body's 72 em less padding), not
        # a ~100 px tile; the other scenes' are in hidden tabs
        shown = [w for w in m[k]["figure7"] if w > 0]
        assert len(shown) == 1 and 1050 <= shown[0] <= 1160, m[k]["figure7"]
        # every scene's 3D view drew its mesh (hidden tabs' too): a sphere of 0.1 m
        # filling 0.9 of the 520 px canvas' height, measured 171,372 px of 468,000
        assert len(m[k]["drawn"]) == n_scenes and min(m[k]["drawn"]) > 150_000, m[k]["drawn"]
    shot = Image.open(tmp_path / "report.png")
    assert shot.size == (WIDTH, HEIGHT)
    # height, measured 7,570 px (2 scenes), 7,770 (6: the summary table's scroll box
    # full), 8,326 (6 scenes of 30 frames: + the per-frame plot and the animation); was
    # 8,224 and 20,460 px for 2 and 6 scenes with every scene on the page, 6,330 to
    # 7,085 px before the depth sigma map and the expected-error and sigma tables
    h = {k: v["height"] for k, v in m.items()}
    assert max(h.values()) < 8600, h
    assert 0 <= h["s6f1"] - h["s2f1"] < 300, h  # scenes: only the summary box's growth
    assert 0 < h["s6f30"] - h["s6f1"] < 800, h  # frames: the plot and the animation, once
