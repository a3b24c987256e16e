"""Tests of the evaluation report colourhs.report.page (small inputs, no pipeline run)."""

from __future__ import annotations

import base64
import html
import math
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from PIL import Image
from report_html import as_dicts, page_tables

from colourhs.report.page import (
    BEST_CAPTION,
    BEST_METRIC,
    PAPER_REFERENCE,
    REQUIRED_COLUMNS,
    PageOptions,
    ReportInputs,
    build_report,
    find_benchmarks,
    format_number,
    read_benchmarks,
    read_metrics,
    software_versions,
    summarise_benchmarks,
    summarise_metrics,
)
from colourhs.report.provenance import arrange_figures, git_provenance, resolve_config
from colourhs.report.tables import (
    EXPECTED_ERROR_COLUMNS,
    EXTRA_COLUMNS,
    best_rows,
    html_table,
    sigma_calibration_table,
)

VARIANTS_3 = ("vh", "bayes_ph", "bayes_full")
HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
VARIANTS = ("bayes_ph", "vh", "bayes_nocalib")  # deliberately not in the paper's order


# --------------------------------------------------------------------------- fixtures


def _metrics_rows() -> list[dict]:
    """Two scenes x two frames x three variants; ``sheet`` has no ground truth."""
    rng = np.random.default_rng(0)
    rows = []
    for frame in ("000000", "000001"):
        for variant in VARIANTS:
            rows.append({"scene": "sheet", "frame": frame, "variant": variant})
            rows.append(
                {
                    "scene": "plane",
                    "frame": frame,
                    "variant": variant,
                    "hausdorff_rms_mm": rng.uniform(1, 9),
                    "hausdorff_mean_mm": rng.uniform(1, 9),
                    "hausdorff_max_mm": rng.uniform(10, 90),
                    "depth_median_mm": rng.uniform(1, 9),
                    "depth_rms_mm": rng.uniform(1, 9),
                    "normal_median_deg": rng.uniform(1, 30),
                    "completeness_rms_mm": rng.uniform(1, 9),
                    "coverage": rng.uniform(0, 1),
                }
            )
    # known values for one cell of each aggregation
    for r in rows:
        if r["scene"] == "plane" and r["variant"] == "bayes_ph":
            first = r["frame"] == "000000"
            r["hausdorff_rms_mm"] = 1.25 if first else 3.75  # mean 2.5
            r["depth_rms_mm"] = 3.0 if first else 4.0  # RMS sqrt(12.5) = 3.5355, mean 3.5
            r["hausdorff_max_mm"] = 41.0 if first else 77.0  # max 77
    return rows


@pytest.fixture
def metrics_csv(tmp_path) -> Path:
    cols = [*REQUIRED_COLUMNS, "completeness_rms_mm", "coverage", "method"]
    df = pd.DataFrame(_metrics_rows(), columns=cols)
    df["method"] = "bayes"
    path = tmp_path / "reports" / "demo" / "metrics.csv"
    path.parent.mkdir(parents=True)
    df.to_csv(path, index=False)
    return path


@pytest.fixture
def images(tmp_path) -> dict:
    d = tmp_path / "results" / "demo" / "figures"
    d.mkdir(parents=True)
    mu = d / "mu_maps.png"
    chroma = d / "chromaticity_monster.png"
    grid = d / "plane_grid.png"
    img = np.zeros((8, 12, 3), np.uint8)
    img[..., 1] = 200
    assert cv2.imwrite(str(mu), img)
    assert cv2.imwrite(str(chroma), img[..., ::-1].copy())
    assert cv2.imwrite(str(grid), 255 - img)
    gif = d / "plane_animation.gif"
    frames = [Image.fromarray(np.full((8, 8, 3), v, np.uint8)) for v in (0, 128, 255)]
    frames[0].save(gif, save_all=True, append_images=frames[1:], duration=100, loop=0)
    return {"calib": [mu, chroma], "plane": [grid, gif]}


@pytest.fixture
def benchmarks(tmp_path) -> list[Path]:
    root = tmp_path / "benchmarks" / "snakemake"
    job = root / "reconstruct" / "demo" / "plane" / "bayes_ph"
    files = {
        root / "photometric" / "demo.tsv": [(6.08, 569.80, 6.05)],
        job / "000000.tsv": [(8.76, 1302.51, 11.93)],
        job / "000001.tsv": [(1.24, 900.0, 2.07)],
    }
    for path, runs in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        lines = [
            f"{s:.2f}\t0:00:{int(s):02d}\t{rss:.2f}\t913.95\t539.49\t553.42\t0.06\t5.50\t91.46\t{cpu:.2f}\n"
            for s, rss, cpu in runs
        ]
        path.write_text(HEADER + "".join(lines))
    return list(files)


# --------------------------------------------------------------------------- html parsing


def per_variant(table: list[list[str]]) -> dict[str, dict[str, str]]:
    """{variant: {metric: cell}} of a scene's metrics table (one column per variant)."""
    header, *rows = table
    assert header[0] == "metric"
    return {v: {r[0]: r[j] for r in rows} for j, v in enumerate(header) if j}


@pytest.fixture
def report(tmp_path, metrics_csv, images, benchmarks) -> Path:
    config = {
        "datasets": {"demo": {"path": Path("data/demo")}},
        "variants": ["vh", "bayes_ph"],
        "mrf": {"lambda": np.float64(0.5), "levels": (3, 2)},
        "note": "<script>alert(1)</script>",
    }
    return build_report(
        tmp_path / "reports" / "demo" / "index.html",
        "demo",
        ReportInputs(
            metrics_csv,
            images["calib"],
            {"plane": images["plane"], "sheet": []},
            benchmarks,
            config,
        ),
        PageOptions(embed_images=True),
        extra={"dataset folder": "data/<demo>"},
    )


# --------------------------------------------------------------------------- tests


def test_format_number():
    assert format_number(2.5) == "2.50"
    assert format_number(2) == "2.00"
    assert format_number(0.012345) == "0.0123"
    assert format_number(123.456) == "123"
    assert format_number(1302.51) == "1303"
    assert format_number(0) == "0"
    assert format_number(float("nan")) == "" and format_number(None) == ""


def test_summarise_metrics_aggregates_and_orders(metrics_csv):
    df = read_metrics(metrics_csv)
    assert df["frame"].tolist()[0] == "000000"  # ids stay strings
    extra = df[df["variant"] == "vh"].assign(variant="zz_custom")
    s = summarise_metrics(pd.concat([df, extra]))
    assert s.columns[:3].tolist() == ["scene", "variant", "frames"]
    assert "method" not in s.columns and {"completeness_rms_mm", "coverage"} <= set(s.columns)
    plane = s[s["scene"] == "plane"].set_index("variant")
    assert plane.index.tolist() == ["vh", "bayes_nocalib", "bayes_ph", "zz_custom"]
    assert (plane["frames"] == 2).all()

    raw = df[df["scene"] == "plane"]
    for variant, g in raw.groupby("variant"):
        row = plane.loc[variant]
        assert row["hausdorff_rms_mm"] == pytest.approx(g["hausdorff_rms_mm"].mean())
        assert row["hausdorff_mean_mm"] == pytest.approx(g["hausdorff_mean_mm"].mean())
        assert row["hausdorff_max_mm"] == pytest.approx(g["hausdorff_max_mm"].max())
        assert row["depth_median_mm"] == pytest.approx(g["depth_median_mm"].median())
        rms = math.sqrt(sum(x * x for x in g["depth_rms_mm"]) / len(g))
        assert row["depth_rms_mm"] == pytest.approx(rms)
        assert row["normal_median_deg"] == pytest.approx(g["normal_median_deg"].median())
        assert row["completeness_rms_mm"] == pytest.approx(g["completeness_rms_mm"].mean())
        assert row["coverage"] == pytest.approx(g["coverage"].mean())
    assert plane.loc["bayes_ph", "depth_rms_mm"] == pytest.approx(math.sqrt(12.5))

    sheet = s[s["scene"] == "sheet"]
    assert len(sheet) == 4 and sheet["hausdorff_rms_mm"].isna().all()
    assert sheet["depth_rms_mm"].isna().all() and (sheet["frames"] == 2).all()


def test_summarise_metrics_skips_missing_frames():
    df = pd.DataFrame(
        {
            "scene": ["a", "a", "a"],
            "frame": ["0", "1", "2"],
            "variant": ["vh"] * 3,
            "depth_rms_mm": [3.0, np.nan, 4.0],
            "hausdorff_rms_mm": [np.nan, 2.0, np.nan],
        }
    )
    row = summarise_metrics(df).iloc[0]
    assert row["frames"] == 3
    assert row["depth_rms_mm"] == pytest.approx(math.sqrt(12.5))
    assert row["hausdorff_rms_mm"] == pytest.approx(2.0)


def test_read_and_summarise_benchmarks(benchmarks):
    b = read_benchmarks(benchmarks)
    assert len(b) == 3 and set(b["rule"]) == {"photometric", "reconstruct"}
    assert b["s"].dtype.kind == "f" and b["max_rss"].dtype.kind == "f"
    s = summarise_benchmarks(b).set_index("rule")
    assert s.index.tolist() == ["reconstruct", "photometric", "sum of jobs"]  # by total time
    assert s.loc["reconstruct", "jobs"] == 2
    assert s.loc["reconstruct", "total_s"] == pytest.approx(10.0)
    assert s.loc["reconstruct", "mean_s"] == pytest.approx(5.0)
    assert s.loc["reconstruct", "max_rss_mb"] == pytest.approx(1302.51)
    assert s.loc["sum of jobs", "total_s"] == pytest.approx(16.08)
    assert s.loc["sum of jobs", "jobs"] == 3
    assert read_benchmarks([]).empty and summarise_benchmarks(read_benchmarks([])).empty


def test_read_benchmarks_rejects_non_benchmark(tmp_path):
    bad = tmp_path / "benchmarks" / "snakemake" / "x" / "a.tsv"
    bad.parent.mkdir(parents=True)
    bad.write_text("a\tb\n1\t2\n")
    with pytest.raises(ValueError, match="a.tsv"):
        read_benchmarks([bad])


def test_report_is_self_contained(report, images):
    text = report.read_text(encoding="utf-8")
    assert report.name == "index.html"
    assert 'src="http' not in text and 'href="http' not in text and "<link" not in text
    assert "<script>alert" not in text  # the config's string is escaped
    assert text.count("<script>") == 1  # the page's own: a #scene-NAME link opens its tab
    assert "&lt;script&gt;" in text and "data/&lt;demo&gt;" in text
    for path in images["calib"] + images["plane"]:
        mime = "image/gif" if path.suffix == ".gif" else "image/png"
        assert f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode()}" in text
    assert text.count("data:image/png;base64,") == 3
    assert "colourhs run DATASET_DIR --name demo" in text
    assert " UTC" in text
    # no temporary files left beside the page
    assert sorted(p.name for p in report.parent.iterdir()) == ["index.html", "metrics.csv"]


def test_report_metric_tables(report, metrics_csv):
    text = report.read_text(encoding="utf-8")
    tables = page_tables(text)
    raw = read_metrics(metrics_csv)
    (plane_table,) = tables["scene-plane"]
    plane = per_variant(plane_table)
    assert list(plane) == ["vh", "bayes_nocalib", "bayes_ph"]  # the paper's order
    for variant in VARIANTS:
        assert variant in text
        g = raw[(raw["scene"] == "plane") & (raw["variant"] == variant)]
        row = plane[variant]
        assert row["frames"] == "2"
        assert row["hausdorff_rms_mm"] == format_number(g["hausdorff_rms_mm"].mean())
        assert row["hausdorff_max_mm"] == format_number(g["hausdorff_max_mm"].max())
        rms = math.sqrt((g["depth_rms_mm"] ** 2).mean())
        assert row["depth_rms_mm"] == format_number(rms)
        assert row["normal_median_deg"] == format_number(g["normal_median_deg"].median())
        assert row["coverage"] == format_number(g["coverage"].mean())
    assert plane["bayes_ph"]["depth_rms_mm"] == "3.54"  # RMS, not the mean 3.50
    assert plane["bayes_ph"]["hausdorff_max_mm"] == "77.0"
    # the paper's numbers beside ours, right after our row
    names = [r[0] for r in plane_table[1:]]
    assert names[names.index("hausdorff_rms_mm") + 1] == "paper hausdorff_rms_mm"
    assert plane["bayes_nocalib"]["paper hausdorff_rms_mm"] == "2.50"
    assert plane["bayes_ph"]["paper hausdorff_rms_mm"] == "2.00"
    assert plane["bayes_ph"]["hausdorff_rms_mm"] == "2.50"
    assert plane["vh"]["paper hausdorff_rms_mm"] == ""
    assert PAPER_REFERENCE["plane"]["bayes_nocalib"]["hausdorff_rms_mm"] == 2.5
    assert PAPER_REFERENCE["plane"]["bayes_ph"]["hausdorff_rms_mm"] == 2.0
    # a scene without ground truth: variants and frame counts, empty metric cells
    (sheet_table,) = tables["scene-sheet"]
    sheet = per_variant(sheet_table)
    assert list(sheet) == ["vh", "bayes_nocalib", "bayes_ph"]
    assert "paper hausdorff_rms_mm" not in [r[0] for r in sheet_table[1:]]
    for row in sheet.values():
        assert row["frames"] == "2"
        assert row["hausdorff_rms_mm"] == "" and row["depth_rms_mm"] == ""


def test_report_timing_and_environment(report):
    tables = page_tables(report.read_text(encoding="utf-8"))
    (timing,) = tables["timing"]
    t = as_dicts(timing)
    assert t["reconstruct"]["jobs"] == "2"
    assert t["reconstruct"]["total_s"] == "10.0"
    assert t["reconstruct"]["mean_s"] == "5.00"
    assert t["reconstruct"]["max_rss_mb"] == "1303"
    assert t["photometric"]["total_s"] == "6.08"
    assert t["sum of jobs"]["total_s"] == "16.1"
    env = {r[0]: r[1] for r in tables["env"][0]}
    for key in ("python", "colourhs", "numpy", "scipy", "open3d", "opencv"):
        assert env[key]
    assert env["h5py"] and env["snakemake"] and env["numba"] and env["CPU count"]
    text = report.read_text(encoding="utf-8")
    assert "lambda: 0.5" in text and "path: data/demo" in text


def test_software_versions_missing_package(monkeypatch):
    from colourhs.report import page as rep

    monkeypatch.setitem(rep.SOFTWARE, "nosuchpkg", ("nosuchpkg_xyz", ("nosuchpkg-xyz",)))
    v = software_versions()
    assert v["nosuchpkg"] == "not installed"
    assert v["numpy"] == np.__version__


def test_report_links_outside_on_request(tmp_path, metrics_csv, images):
    """colourhs report copies the images from outside the report's folder into its
    assets/; with --link-outside it links them and the result files where they are
    instead, and leaves assets/ as it was."""
    from colourhs.cli.parser import main

    mesh = tmp_path / "results" / "demo" / "plane" / "vh" / "mesh" / "000000.ply"
    mesh.parent.mkdir(parents=True)
    mesh.write_text("x")
    out = tmp_path / "reports" / "demo" / "index.html"
    argv = ["report", str(out), "--name", "demo", "--metrics", str(metrics_csv)]
    argv += [
        "--benchmarks",
        str(tmp_path / "none"),
        "--calibration",
        *map(str, images["calib"]),
        "--results",
        str(mesh.parents[3]),
    ]
    assert main(argv) == 0
    text = out.read_text(encoding="utf-8")
    assert 'src="assets/mu_maps.png"' in text and "<code>vh/mesh/000000.ply</code>" in text
    assets = sorted(p.name for p in (out.parent / "assets").iterdir())
    assert assets == ["chromaticity_monster.png", "mu_maps.png"]
    assert main([*argv, "--link-outside"]) == 0
    text = out.read_text(encoding="utf-8")
    assert "base64" not in text and "assets/" not in text
    assert 'src="../../results/demo/figures/mu_maps.png"' in text
    assert '<a href="../../results/demo/plane/vh/mesh/000000.ply">mesh 000000</a>' in text
    assert sorted(p.name for p in (out.parent / "assets").iterdir()) == assets
    assert "No benchmark files." in text


#: A ``src`` or ``href`` attribute's value.
LINK = re.compile(r'\b(?:src|href)="([^"]*)"')


def file_links(text: str) -> list[str]:
    """Every ``src`` and ``href`` of a page but data URIs and links into the page."""
    return [u for u in LINK.findall(text) if not u.startswith(("data:", "#"))]


def test_report_folder_stands_alone(tmp_path, metrics_csv, images):
    """Every src and href of the page is a path inside the report's folder: the images
    from outside it are whole copies in its assets/, those inside linked in place, the
    result files named; the folder moved elsewhere, without results/, still has them."""
    results = tmp_path / "results" / "demo"
    mesh = results / "plane" / "bayes_ph" / "mesh" / "000000.ply"
    mesh.parent.mkdir(parents=True)
    mesh.write_text("x")
    inside = tmp_path / "reports" / "demo" / "figures" / "plane" / "figure7.png"
    inside.parent.mkdir(parents=True)
    assert cv2.imwrite(str(inside), np.zeros((4, 4, 3), np.uint8))
    out = build_report(
        tmp_path / "reports" / "demo" / "index.html",
        "demo",
        ReportInputs(metrics_csv, images["calib"], {"plane": [*images["plane"], inside]}, [], {}),
        results_dir=results,
    )
    text = out.read_text(encoding="utf-8")
    links = file_links(text)
    assert len(set(links)) == 5  # the five images; the result file is named, not linked
    for link in links:
        assert not link.startswith("/") and ":" not in link and ".." not in link.split("/"), link
    assert 'src="figures/plane/figure7.png"' in text
    for source in [*images["calib"], *images["plane"]]:
        assert (out.parent / "assets" / source.name).read_bytes() == source.read_bytes()
    assert "<code>bayes_ph/mesh/000000.ply</code>" in text
    mailed = Path(shutil.move(out.parent, tmp_path / "mail" / "demo"))
    shutil.rmtree(tmp_path / "results")
    assert all((mailed / link).is_file() for link in links)
    assert not [p for p in mailed.rglob(".*")]  # no temporary file or folder left


def test_report_copies_all_or_nothing(tmp_path, metrics_csv, images, monkeypatch):
    """A copy that fails leaves the report's folder as it was (no partial assets/, no
    temporary folder, the earlier page); a build that links fewer images drops the
    copies it no longer links."""
    out = tmp_path / "reports" / "demo" / "index.html"

    def build(calib, plane):
        return build_report(out, "demo", ReportInputs(metrics_csv, calib, {"plane": plane}, [], {}))

    def folder() -> dict:
        return {
            str(p.relative_to(out.parent)): p.read_bytes()
            for p in out.parent.rglob("*")
            if p.is_file()
        }

    build(images["calib"][:1], [])
    before = folder()
    assert sorted(before) == ["assets/mu_maps.png", "index.html", "metrics.csv"]
    copies = []
    copy = shutil.copyfile

    def failing(src, dst, *args, **kwargs):
        copies.append(src)
        if len(copies) == 3:
            raise OSError("disk full")
        return copy(src, dst, *args, **kwargs)

    monkeypatch.setattr(shutil, "copyfile", failing)
    with pytest.raises(OSError, match="disk full"):
        build(images["calib"], images["plane"])
    assert len(copies) == 3 and folder() == before
    monkeypatch.undo()
    build(images["calib"], images["plane"])
    assert len(list((out.parent / "assets").iterdir())) == 4
    build(images["calib"][1:], [])
    assert [p.name for p in (out.parent / "assets").iterdir()] == ["chromaticity_monster.png"]
    build([], [])  # nothing to copy: an empty assets/ (the workflow declares the folder)
    assert sorted(p.name for p in out.parent.iterdir()) == ["assets", "index.html", "metrics.csv"]
    assert not any((out.parent / "assets").iterdir())


def _summary_rows(text: str) -> list[tuple[str, list[tuple[str, str]]]]:
    """The summary table's body rows: (the row's class, [(each cell's class, text)])."""
    table = text[text.index('<table class="summary">') :]
    body = table[table.index("<tbody>") : table.index("</tbody>")]
    row = re.compile(r'<tr(?: class="([^"]*)")?>(.*?)</tr>')
    cell = re.compile(r'<td(?: class="([^"]*)")?>(.*?)</td>')
    return [(rc or "", [(cc or "", v) for cc, v in cell.findall(r)]) for rc, r in row.findall(body)]


def test_html_table_headers_wrap_between_words():
    """Headers break after underscores only (<wbr>); cells: integers as they are, other
    numbers by format_number, text escaped, missing values empty; classes per row and
    per cell."""
    table = pd.DataFrame(
        {"variant": ["vh", "<b>"], "frames": [2, 3], "depth_rms_mm": [1.5, np.nan]}
    )
    cells = pd.DataFrame({"variant": ["", ""], "frames": ["", ""], "depth_rms_mm": ["best", ""]})
    assert html_table(table, "t", row_class=["best", ""], cell_class=cells) == (
        '<table class="t"><thead><tr><th>variant</th><th>frames</th>'
        "<th>depth_<wbr>rms_<wbr>mm</th></tr></thead><tbody>"
        '<tr class="best"><td>vh</td><td>2</td><td class="best">1.50</td></tr>'
        "<tr><td>&lt;b&gt;</td><td>3</td><td></td></tr></tbody></table>"
    )


def test_best_rows_lowest_per_scene_with_ties():
    summary = pd.DataFrame(
        {
            "scene": ["a", "a", "a", "b", "b", "c"],
            "variant": ["vh", "bayes_ph", "bayes_full", "vh", "bayes_ph", "vh"],
            "hausdorff_rms_mm": [3.0, 1.5, 1.5, np.nan, 4.0, np.nan],
        }
    )
    assert best_rows(summary, "hausdorff_rms_mm").tolist() == [
        False,
        True,
        True,
        False,
        True,
        False,
    ]
    assert not best_rows(summary, "depth_median_mm").any()  # no such column


def test_summary_marks_each_scenes_best_variant(tmp_path):
    """The summary's rows of each scene's lowest BEST_METRIC (both of a tie) are of
    class best, with that cell of class best; a scene without values has none; a
    caption says what the mark means."""
    values = {("plane", "vh"): 3.0, ("plane", "bayes_ph"): 1.5, ("plane", "bayes_full"): 1.5}
    values |= {("statue", "vh"): 0.5, ("statue", "bayes_ph"): 0.75}
    rows = [
        {"scene": s, "frame": "000000", "variant": v, BEST_METRIC: values.get((s, v), np.nan)}
        for s, vs in {"plane": VARIANTS_3, "statue": ("vh", "bayes_ph"), "sheet": ("vh",)}.items()
        for v in vs
    ]
    csv = tmp_path / "metrics.csv"
    pd.DataFrame(rows, columns=list(REQUIRED_COLUMNS)).to_csv(csv, index=False)
    text = build_report(
        tmp_path / "index.html", "demo", ReportInputs(csv, [], {}, [], {})
    ).read_text()
    body = _summary_rows(text)
    header = page_tables(text)["summary"][0][0]
    col = header.index(BEST_METRIC)
    marked = [(cells[0][1], cells[1][1]) for rc, cells in body if "best" in rc.split()]
    assert marked == [("plane", "bayes_ph"), ("plane", "bayes_full"), ("statue", "vh")]
    for rc, cells in body:
        best = "best" in rc.split()
        assert [c for c, _ in cells] == [
            "best" if best and j == col else "" for j in range(len(cells))
        ]
    (caption,) = re.findall(r'<p class="note caption">(.*?)</p>', text)
    assert html.unescape(caption) == BEST_CAPTION and BEST_METRIC in BEST_CAPTION


@pytest.mark.parametrize("drop", ["depth_rms_mm", "variant"])
def test_missing_column_raises_and_writes_nothing(tmp_path, metrics_csv, images, drop):
    bad = tmp_path / "bad.csv"
    pd.read_csv(metrics_csv).drop(columns=drop).to_csv(bad, index=False)
    out = tmp_path / "reports" / "demo" / "index.html"
    with pytest.raises(ValueError, match=drop) as err:
        build_report(out, "demo", ReportInputs(bad, images["calib"], {}, [], {}))
    assert "bad.csv" in str(err.value)
    assert not out.exists()
    assert [p.name for p in out.parent.iterdir()] == ["metrics.csv"]  # no temporary file


def test_missing_metrics_file_raises(tmp_path):
    out = tmp_path / "index.html"
    with pytest.raises(ValueError, match="nothere.csv"):
        build_report(out, "demo", ReportInputs(tmp_path / "nothere.csv", [], {}, [], {}))
    assert not out.exists()


def test_missing_figure_raises(tmp_path, metrics_csv):
    out = tmp_path / "index.html"
    with pytest.raises(ValueError, match="gone.png"):
        build_report(out, "demo", ReportInputs(metrics_csv, [tmp_path / "gone.png"], {}, [], {}))
    assert not out.exists()


def test_folders_config_file_and_find_benchmarks(tmp_path, metrics_csv, images, benchmarks):
    other = tmp_path / "benchmarks" / "snakemake" / "reconstruct" / "other" / "s" / "v" / "0.tsv"
    other.parent.mkdir(parents=True)
    other.write_text(HEADER + "99.0\t0:01:39\t1\t1\t1\t1\t0\t0\t1\t99.0\n")
    root = tmp_path / "benchmarks" / "snakemake"
    assert find_benchmarks(root, "demo") == sorted(benchmarks)
    assert len(find_benchmarks(root)) == 4 and find_benchmarks(tmp_path / "none") == []
    config = tmp_path / "config.yaml"
    config.write_text("mrf:\n  lambda: 0.25\n")
    out = build_report(
        tmp_path / "index.html",
        "demo",
        ReportInputs(
            metrics_csv,
            images["calib"][0].parent,
            {"plane": images["plane"][0].parent},
            find_benchmarks(root, "demo"),
            config,
        ),
        PageOptions(embed_images=True),
    )
    text = out.read_text(encoding="utf-8")
    assert text.count("data:image/png;base64,") == 6 and text.count("data:image/gif;") == 2
    assert "lambda: 0.25" in text
    assert as_dicts(page_tables(text)["timing"][0])["sum of jobs"]["total_s"] == "16.1"


# --------------------------------------------------------------------------- layout and provenance


def _fake_dataset(root: Path):
    """A stand-in for colourhs.capture.Dataset with what the report reads."""
    from types import SimpleNamespace as NS

    cams = tuple(
        NS(name=f"cam{i}", light_colour=c, light_offset=np.zeros(3))
        for i, c in enumerate(("red", "green", "blue"))
    )
    scenes = {
        "plane": NS(
            frames=("000000",),
            dynamic=False,
            chromatic=None,
            has_gt=True,
            description="held-out <board> pose",
        ),
        "sheet": NS(
            frames=tuple(f"{i:06d}" for i in range(4)),
            dynamic=True,
            chromatic="slinky",
            has_gt=False,
            description="",
        ),
    }
    rig = NS(cameras=cams, image=NS(width=640, height=480, bit_depth=16))
    return NS(root=root, rig=rig, poses=("p0", "p1"), chromatic_objects=("slinky",), scenes=scenes)


def test_report_layout_provenance_and_links(tmp_path, metrics_csv, images):
    """Summary table with legend first, Figure 7 full width, other figures as linked
    thumbnails, rig and scene.json facts, result-file links, git provenance."""
    results = tmp_path / "results" / "demo"
    for v, kind, name in [
        ("bayes_ph", "mesh", "000000.ply"),
        ("bayes_ph", "eval", "000000.ply"),
        ("bayes_ph", "depth", "000000.h5"),
        ("vh", "mesh", "000000.ply"),
    ]:
        (results / "plane" / v / kind).mkdir(parents=True, exist_ok=True)
        (results / "plane" / v / kind / name).write_text("x")
    figs = images["plane"][0].parent
    for stem in ("figure7", "vh_depth_error", "vh_depth", "bayes_ph_depth"):
        assert cv2.imwrite(str(figs / f"{stem}.png"), np.zeros((4, 4, 3), np.uint8))
    out = build_report(
        tmp_path / "reports" / "demo" / "index.html",
        "demo",
        ReportInputs(
            metrics_csv,
            [],
            {
                "plane": [
                    figs / f
                    for f in (
                        "vh_depth.png",
                        "figure7.png",
                        "bayes_ph_depth.png",
                        "vh_depth_error.png",
                    )
                ]
            },
            [],
            {},
        ),
        dataset=_fake_dataset(tmp_path / "data"),
        results_dir=results,
    )
    text = out.read_text(encoding="utf-8")
    tables = page_tables(text)
    # the summary (first section) with the key columns and the paper's number
    (summary,) = tables["summary"]
    assert summary[0] == [
        "scene",
        "variant",
        "frames",
        "hausdorff_rms_mm",
        "paper hausdorff_rms_mm",
        "depth_median_mm",
        "depth_rms_mm",
        "normal_median_deg",
        "coverage",
    ]
    assert len(summary) == 1 + 6 and summary[3][:5] == ["plane", "bayes_ph", "2", "2.50", "2.00"]
    assert text.index('id="summary"') < text.index('id="scene-plane"')
    assert "<dt>hausdorff_rms_mm</dt><dd>accuracy: RMS distance" in text
    # figures: Figure 7 first and wide, error maps next, then thumbnails linked to full size
    # (copied into the report's assets/: they lie outside its folder)
    wide = text.index('<figure class="wide"><a href="assets/figure7.png">')
    assert wide < text.index("vh_depth_error.png") < text.index("vh_depth.png")
    assert text.index("vh_depth.png") < text.index("bayes_ph_depth.png")  # paper's order
    assert '<a href="assets/vh_depth.png"><img' in text
    # rig summary and scene.json
    rig = {r[0]: r[1] for r in tables["provenance"][1]}
    assert rig["cameras"] == "3: cam0 (red light), cam1 (green light), cam2 (blue light)"
    assert (
        rig["image"] == "640 x 480 px, 16 bit" and rig["frames per scene"] == "plane: 1, sheet: 4"
    )
    assert rig["lights"].startswith("at the lens centres (collocated")
    assert "held-out &lt;board&gt; pose (static; white surface; ground truth)" in text
    assert "dynamic, 4 frames; chromatic object slinky; no ground truth" in text
    # result files, named in the run's folder (not the report's), not linked
    for rel in (
        "bayes_ph/mesh/000000.ply",
        "bayes_ph/eval/000000.ply",
        "bayes_ph/depth/000000.h5",
        "vh/mesh/000000.ply",
    ):
        assert f"<code>{rel}</code>" in text
    assert f"In <code>{results.as_posix()}/plane/</code> of the run" in text
    assert "Result files (4)" in text and 'href="../' not in text
    # provenance: this checkout's commit
    prov = {r[0]: r[1] for r in tables["provenance"][0]}
    assert re.fullmatch(r"[0-9a-f]{40}", prov["git commit"]), prov
    assert prov["git work tree"] in ("clean",) or prov["git work tree"].startswith("modified (")
    assert prov["report command"]


def test_sequence_plot_and_frame_note(tmp_path, metrics_csv, images):
    out = build_report(
        tmp_path / "index.html", "demo", ReportInputs(metrics_csv, [], {"plane": []}, [], {})
    )
    text = out.read_text(encoding="utf-8")
    # two frames: the maps' frame is named and the depth error is plotted over frames
    assert "Sequence of 2 frames (000000 to 000001)" in text
    assert "the maps and renders show frame 000000." in text
    plane = text[text.index('id="scene-plane"') : text.index('id="scene-sheet"')]
    assert plane.count("<svg") == 1 and "Median depth error per frame" in plane
    sheet = text[text.index('id="scene-sheet"') : text.index('id="timing"')]
    assert "<svg" not in sheet  # no finite depth errors: no plot


def test_git_provenance_and_resolve_config(tmp_path):
    assert git_provenance(tmp_path) == {"git commit": "not a git checkout"}
    config = {
        "reconstruction": {"params": {"alpha": 2.0}, "variants": None},
        "calibration": {"photometric": {"step_px": None, "coupling": 0.5}},
        "datasets": {
            "a": {"path": "x", "calibration": {"photometric": {"step_px": 9}}},
            "b": {"path": "y"},
        },
    }
    r = resolve_config(config, {"alpha": 1.0, "tau": 3}, {"step_px": 4, "coupling": 0.1})
    assert r["reconstruction"] == {"params": {"alpha": 2.0, "tau": 3}, "variants": None}
    assert r["calibration"]["photometric"] == {"step_px": 4, "coupling": 0.5}
    own = r["datasets"]["a"]["calibration"]["photometric"]
    assert own == {"step_px": 9, "coupling": 0.5} and r["datasets"]["b"] == {"path": "y"}
    assert config["datasets"]["a"]["calibration"]["photometric"] == {"step_px": 9}
    assert config["reconstruction"]["params"] == {"alpha": 2.0}  # not changed in place


def test_arrange_figures_and_template_is_package_data():
    from importlib.resources import files

    names = [
        "bayes_ph_normal.png",
        "hausdorff.png",
        "vh_normal_error.png",
        "animation.gif",
        "vh_depth.png",
        "figure7.png",
        "bayes_ph_depth.png",
        "vh_depth_error.png",
    ]
    a = arrange_figures([Path(n) for n in names])
    assert [p.name for p in a["wide"]] == ["figure7.png", "hausdorff.png"]
    # the sigma map right after the depth-error map it reads beside
    b = arrange_figures([Path(n) for n in ("depth_sigma.png", "hausdorff.png", "depth_error.png")])
    assert [p.name for p in b["wide"]] == ["depth_error.png", "depth_sigma.png", "hausdorff.png"]
    assert [p.name for p in a["errors"]] == ["vh_depth_error.png", "vh_normal_error.png"]
    thumbs = ["animation.gif", "vh_depth.png", "bayes_ph_depth.png", "bayes_ph_normal.png"]
    assert [p.name for p in a["thumbs"]] == thumbs  # by kind, then the paper's variant order
    assert (files("colourhs.report") / "templates" / "report.html").is_file()
    assert '"colourhs.report" = ["templates/*.html"]' in Path("pyproject.toml").read_text()


def test_report_expected_error_and_sigma_calibration(tmp_path, images):
    """Each scene's expected depth error (median sigma) shows also where there is no
    ground truth (``sheet``); the sigma calibration (shares within 1, 2, 3 sigma beside
    0.683, 0.954, 0.997) only where there is (``plane``); the signed median depth error
    right after the absolute one in the scene's metrics table."""
    rows = []
    for frame, f in (("000000", 0), ("000001", 1)):
        rows.append(
            {
                "scene": "sheet",
                "frame": frame,
                "variant": "bayes_full",
                "expected_depth_error_mm": (1.5, 2.5)[f],  # median over frames 2.00
                "uncertain_share": (0.1, 0.3)[f],  # mean 0.200
                "reciprocity_defect_deg": (0.2, 0.6)[f],  # median over frames 0.400
            }
        )
        rows.append({"scene": "sheet", "frame": frame, "variant": "vh"})  # no sigma
        rows.append(
            {
                "scene": "plane",
                "frame": frame,
                "variant": "bayes_full",
                "hausdorff_rms_mm": 2.0,
                "depth_median_mm": 1.0,
                "depth_signed_median_mm": (-0.25, -0.75)[f],  # median -0.500
                "depth_sigma_median_mm": 1.25,
                "sigma_within_1": (0.5, 0.6)[f],  # mean 0.550
                "sigma_within_2": 0.9,
                "sigma_within_3": (0.97, 0.99)[f],  # mean 0.980
                "expected_depth_error_mm": 1.3,
                "uncertain_share": 0.05,
            }
        )
    csv = tmp_path / "metrics.csv"
    cols = [*REQUIRED_COLUMNS, *EXTRA_COLUMNS, "method", "same_as"]
    pd.DataFrame(rows, columns=cols).to_csv(csv, index=False)
    out = build_report(
        tmp_path / "index.html", "demo", ReportInputs(csv, [], {"plane": [], "sheet": []}, [], {})
    )
    text = out.read_text(encoding="utf-8")
    tables = page_tables(text)
    sheet = text[text.index('id="scene-sheet"') : text.index('id="timing"')]
    assert "Expected depth error" in sheet and "Sigma calibration" not in sheet
    _, expected = tables["scene-sheet"]  # after the scene's metrics
    assert expected[0] == ["variant", *EXPECTED_ERROR_COLUMNS]
    assert as_dicts(expected) == {
        "bayes_full": {
            "variant": "bayes_full",
            "expected_depth_error_mm": "2.00",
            "uncertain_share": "0.200",
            "reciprocity_defect_deg": "0.400",
            "depth_sigma_median_mm": "",
            "depth_median_mm": "",
            "depth_signed_median_mm": "",
        }
    }  # vh has no sigma: no row
    metrics, expected, calibration = tables["scene-plane"]
    names = [r[0] for r in metrics[1:]]
    assert names[names.index("depth_median_mm") + 1] == "depth_signed_median_mm"
    assert per_variant(metrics)["bayes_full"]["depth_signed_median_mm"] == "-0.500"
    assert as_dicts(expected)["bayes_full"]["expected_depth_error_mm"] == "1.30"
    assert as_dicts(expected)["bayes_full"]["depth_signed_median_mm"] == "-0.500"
    assert calibration == [
        ["variant", "within 1 sigma", "within 2 sigma", "within 3 sigma"],
        ["bayes_full", "0.550", "0.900", "0.980"],
        ["calibrated (Gaussian)", "0.683", "0.954", "0.997"],
    ]
    assert sigma_calibration_table(summarise_metrics(read_metrics(csv))[:0]).empty
