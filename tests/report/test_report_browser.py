"""The evaluation report as a browser shows it (headless Chromium, 900 and 1400 px wide).

Reports are built from synthetic inputs shaped like a real run's (five variants,
every metric column of colourhs.evaluation.accuracy, the figures colourhs.report.figures writes
at their real pixel sizes), moved away from the results they were built from (as a
user mails the report's folder), and loaded by ``chromium --headless --dump-dom``
with a small script that writes the page's measurements into the DOM on ``load``,
and by ``--screenshot``. Skipped when no Chromium is installed (scripts/setup.sh
installs Debian's ``chromium``).
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path
from urllib.parse import urlsplit
from urllib.request import url2pathname

import cv2
import numpy as np
import open3d as o3d
import pandas as pd
import pytest
from PIL import Image

from colourhs.common.ply import write_ply
from colourhs.report.page import (
    BEST_METRIC,
    REQUIRED_COLUMNS,
    PageOptions,
    ReportInputs,
    build_report,
)
from colourhs.report.tables import EXTRA_COLUMNS, best_rows, read_metrics, summarise_metrics
from colourhs.workflow.variants import VARIANT_ORDER

CHROMIUM = next(
    (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None
)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium on PATH (scripts/setup.sh installs Debian's chromium)"
)
#: The window widths the page must read well at, and the window's height.
WIDTHS, HEIGHT = (900, 1400), 900
#: The page body's widest content box (72 em of 16 px; the template's max-width).
BODY_WIDTH = 1152
_sphere = o3d.geometry.TriangleMesh.create_sphere(0.05, resolution=12)  # 528 triangles
SPHERE = (np.asarray(_sphere.vertices), np.asarray(_sphere.triangles))

# Written into the page on load. As the page opens: its width and height, the
# elements wider than the window (outside the boxes that scroll), the images' state,
# the displayed width of Figure 7, the pixels each 3D view's canvas drew (red below
# 250), the summary table's height and its box's scroll and client sizes, and per
# summary row its cells, whether it is of class best, its variant cell's font
# weight, the content its cells show before their text (the star) and whether an
# ancestor box clips it. Then with every <details> open, in each scene's tab: the
# headers whose content overflows or that break inside a word (a word, a run of
# characters but spaces and underscores, laid out on more than one line), the
# tables whose box scrolls sideways, the page's width and the elements wider than
# the window. Last, every src and href, resolved against the page.
MEASURE = r"""<script>addEventListener("load", () => {
  const d = document.documentElement, imgs = [...document.images];
  const unboxed = e => !e.parentElement.closest(".scroll, pre");
  const wider = () => [...document.querySelectorAll("body *")]
    .filter(e => unboxed(e) && e.getBoundingClientRect().right > innerWidth)
    .map(e => e.tagName + "." + e.className);
  const out = {scrollWidth: d.scrollWidth, height: d.scrollHeight, wide: wider(),
    images: imgs.length, broken: imgs.filter(i => !i.complete || i.naturalWidth === 0)
    .map(i => i.getAttribute("src")), figure7: imgs.filter(i => /figure7/.test(i.src))
    .map(i => i.clientWidth)};
  out.drawn = [...document.querySelectorAll(".viewer canvas")].map(c => c.getContext("2d")
    .getImageData(0, 0, c.width, c.height).data.filter((x, i) => i % 4 == 0 && x < 250).length);
  const summary = document.querySelector("table.summary"), box = summary.parentElement;
  out.summary = {height: summary.getBoundingClientRect().height,
    box: [box.scrollWidth, box.clientWidth, box.scrollHeight, box.clientHeight]};
  const clipped = row => {
    const r = row.getBoundingClientRect();
    for (let a = row.parentElement; a !== document.body; a = a.parentElement) {
      const s = getComputedStyle(a), c = a.getBoundingClientRect();
      const boxed = s.overflowX !== "visible" || s.overflowY !== "visible";
      if (boxed && (r.top < c.top - 0.5 || r.bottom > c.bottom + 0.5 || r.left < c.left - 0.5 ||
          r.right > c.right + 0.5)) return true;
    }
    return r.height === 0;
  };
  out.rows = [...summary.tBodies[0].rows].map(r => ({cells: [...r.cells].map(c => c.textContent),
    best: r.classList.contains("best"), weight: +getComputedStyle(r.cells[1]).fontWeight,
    before: [...r.cells].map(c => getComputedStyle(c, "::before").content)
    .filter(c => c !== "none" && c !== "normal"), clipped: clipped(r)}));
  document.querySelectorAll("details").forEach(e => { e.open = true; });
  const range = document.createRange();
  const brokenWord = th => [...th.childNodes].filter(n => n.nodeType === Node.TEXT_NODE)
    .some(n => [...n.data.matchAll(/[^\s_]+/g)].some(m => {
      range.setStart(n, m.index);
      range.setEnd(n, m.index + m[0].length);
      return range.getClientRects().length !== 1;
    }));
  const split = new Set(), scrolled = new Set(), openWide = new Set();
  out.openWidth = 0;
  for (const tab of document.querySelectorAll(".tabs > input")) {
    tab.checked = true;
    for (const t of document.querySelectorAll("table")) {
      if (!t.getClientRects().length) continue;  /* in a hidden tab */
      for (const th of t.querySelectorAll("th"))
        if (th.scrollWidth > th.clientWidth || th.scrollHeight > th.clientHeight || brokenWord(th))
          split.add(th.textContent);
      const b = t.closest(".scroll");
      if (b && b.scrollWidth > b.clientWidth)
        scrolled.add(t.className + ": " + t.rows[0].textContent);
    }
    out.openWidth = Math.max(out.openWidth, d.scrollWidth);
    wider().forEach(e => openWide.add(e));
  }
  Object.assign(out, {split: [...split], scrolled: [...scrolled], openWide: [...openWide]});
  out.links = [...document.querySelectorAll("[src], [href]")].map(e =>
    new URL(e.getAttribute("src") ?? e.getAttribute("href"), document.baseURI).href);
  d.dataset.measure = JSON.stringify(out);
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
        ReportInputs(metrics, sorted(calib.iterdir()), figures, [], config),
        PageOptions(views=True),
        extra={"note": long_value},
        results_dir=root / "results" / "demo",
    )


def _mail(page: Path, to: Path) -> Path:
    """Move the report folder of ``page`` to ``to`` and delete what it was built from
    (the results beside ``reports/``), as a user who mails the folder; the moved page."""
    root = page.parents[2]
    to.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(page.parent, to)
    shutil.rmtree(root)
    return to / page.name


def _start(page: Path, width: int, screenshot: Path | None = None) -> subprocess.Popen:
    """Load ``page`` (a copy with :data:`MEASURE` added, beside it) in headless Chromium."""
    probe = page.with_name("_measure.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", MEASURE + "</body>"))
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        f"--window-size={width},{HEIGHT}",
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


def _outside(links: list[str], folder: Path) -> list[str]:
    """The links (absolute URLs) that are neither data URIs nor files inside ``folder``."""
    bad = []
    for link in links:
        url = urlsplit(link)
        if url.scheme == "data":
            continue
        path = Path(url2pathname(url.path)).resolve() if url.scheme == "file" else None
        if path is None or not path.is_relative_to(folder.resolve()) or not path.is_file():
            bad.append(link)
    return bad


def _best(metrics_csv: Path) -> list[list[str]]:
    """[scene, variant] of each scene's best variants, from the metrics table itself."""
    summary = summarise_metrics(read_metrics(metrics_csv))
    return summary.loc[best_rows(summary, BEST_METRIC), ["scene", "variant"]].values.tolist()


@pytest.mark.parametrize("width", WIDTHS)
def test_report_reads_at_width_and_stands_alone(tmp_path, width):
    """At ``width`` px: no horizontal overflow, even with every <details> open; every
    table fits its box without scrolling sideways and no header breaks inside a word;
    every summary row shows (no inner scroll box), each scene's best variant marked
    (bold, a star); the report's folder, moved away from the results, has every image
    and every link inside it; a height that grows with scenes only by the summary's
    rows (one scene's tab at a time) and with frames only by the per-frame plot and
    the animation."""
    sizes = {"s2f1": (2, 1), "s6f1": (6, 1), "s6f30": (6, 30)}
    pages = {
        k: _mail(_make_report(tmp_path / k, *n), tmp_path / "mailed" / k) for k, n in sizes.items()
    }
    shot = tmp_path / "report.png"
    runs = {k: _start(p, width, shot if k == "s2f1" else None) for k, p in pages.items()}
    m = {k: _measurements(r) for k, r in runs.items()}
    content = min(width - 32, BODY_WIDTH)  # the body's content box: 1 em padding each side
    for k, (n_scenes, n_frames) in sizes.items():
        page = m[k]
        assert page["scrollWidth"] <= width and not page["wide"], page["wide"]
        assert page["openWidth"] <= width and not page["openWide"], page["openWide"]
        assert page["scrolled"] == [], page["scrolled"]  # no table needs a sideways scroll
        assert page["split"] == [], page["split"]  # headers wrap between words only
        # the summary: every row shown, none clipped by a box
        rows = page["rows"]
        assert len(rows) == n_scenes * len(VARIANT_ORDER)
        assert not [r["cells"][:2] for r in rows if r["clipped"]]
        sw, cw, sh, ch = page["summary"]["box"]
        assert sw <= cw and sh <= ch, page["summary"]
        # each scene's best variant marked, bold with a star, and no other row
        marked = [r for r in rows if r["best"]]
        assert [r["cells"][:2] for r in marked] == _best(pages[k].with_name("metrics.csv"))
        assert {r["cells"][0] for r in marked} == {r["cells"][0] for r in rows}
        assert all(r["weight"] >= 600 and any("\u2605" in c for c in r["before"]) for r in marked)
        assert all(r["weight"] < 600 and not r["before"] for r in rows if not r["best"])
        # the folder stands alone: every image loaded, every link a file inside it
        assert page["broken"] == []  # every <img> loaded, those of hidden tabs too
        # 5 wide figures, a depth and a normal map per variant, the animation
        per_scene = 5 + 2 * len(VARIANT_ORDER) + (n_frames > 1)
        assert page["images"] == 2 + n_scenes * per_scene
        assert _outside(page["links"], pages[k].parent) == []
        assert any("/assets/" in link for link in page["links"])  # the calibration figures
        # one scene shown: its Figure 7 full width, not a ~100 px tile; the other
        # scenes' are in hidden tabs
        shown = [w for w in page["figure7"] if w > 0]
        assert len(shown) == 1 and content - 10 <= shown[0] <= content, page["figure7"]
        # every scene's 3D view drew its mesh (hidden tabs' too): a sphere of 0.1 m
        # filling 0.9 of the 520 px canvas' height
        assert len(page["drawn"]) == n_scenes and min(page["drawn"]) > 150_000, page["drawn"]
    assert Image.open(shot).size == (width, HEIGHT)
    h = {k: v["height"] for k, v in m.items()}
    rows = {k: v["summary"]["height"] for k, v in m.items()}
    assert max(h.values()) < 9000, h
    # scenes: the summary's rows and little else; frames: the plot and the animation, once
    assert -2 < (h["s6f1"] - h["s2f1"]) - (rows["s6f1"] - rows["s2f1"]) < 100, (h, rows)
    assert 0 < h["s6f30"] - h["s6f1"] < 800, h
