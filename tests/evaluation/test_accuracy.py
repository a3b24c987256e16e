"""Hausdorff distances, seen regions, depth errors and the metrics table
(colourhs.evaluation.accuracy)."""

from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np
import open3d as o3d
import pandas as pd
import pytest
from scipy.spatial import cKDTree

from colourhs.capture import Camera
from colourhs.common.depthfile import DepthResult, read_depth, write_depth
from colourhs.common.geometry import look_at, project
from colourhs.common.metrics_csv import DROP_COLUMNS, EXTRA_COLUMNS, GAUSSIAN_WITHIN
from colourhs.common.ply import is_empty_mesh, load_mesh, write_ply
from colourhs.common.raycast import (
    cast_pixels,
    closest_on_triangles,
    closest_points,
    depth_normal_maps,
    pixel_rays,
    render_depth_normals,
)
from colourhs.evaluation.accuracy import (
    CONTRACT_COLUMNS,
    FrameKey,
    depth_errors,
    evaluate_frame,
    hausdorff,
    metrics_table,
    seen_surface,
    visible_vertices,
)
from colourhs.evaluation.depth_errors import sigma_summary, uncertainty_summary
from colourhs.surfaces.poisson import frame_mesh

W, H = 128, 96


def sphere(r: float, resolution: int, scale=(1.0, 1.0, 1.0), centre=(0.0, 0.0, 0.0)):
    """Vertices (metres), triangles and unit normals of a UV sphere (or ellipsoid)."""
    m = o3d.geometry.TriangleMesh.create_sphere(r, resolution)
    m.vertices = o3d.utility.Vector3dVector(np.asarray(m.vertices) * scale + centre)
    m.compute_vertex_normals()
    return np.asarray(m.vertices), np.asarray(m.triangles), np.asarray(m.vertex_normals)


def surface_samples(vertices, triangles, n, seed=0):
    """n area-uniform random points on a triangle mesh."""
    rng = np.random.default_rng(seed)
    tri = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    k = rng.choice(len(tri), n, p=area / area.sum())
    a, b = rng.random((2, n))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    t = tri[k]
    return t[:, 0] + a[:, None] * (t[:, 1] - t[:, 0]) + b[:, None] * (t[:, 2] - t[:, 0])


def make_camera() -> Camera:
    K = np.array([[300.0, 0.0, W / 2 - 0.3], [0.0, 300.0, H / 2 + 0.2], [0.0, 0.0, 1.0]])
    R, t = look_at(np.array([0.03, -0.02, -0.8]), np.zeros(3))
    return Camera("cam1", K, np.array([-0.05, 0.02, 0.0, 0.0, 0.0]), R, t, "red", np.zeros(3))


def test_hausdorff_agrees_with_nearest_neighbours():
    # Sphere (r = 0.1 m) to an ellipsoid (semi-axes 0.115, 0.1, 0.09 m): distances
    # 0 to 15 mm. Reference: nearest of 600 000 random samples of the ellipsoid
    # mesh (about 0.25 mm apart, which overestimates a 5 mm distance by
    # ~0.25**2 / 10 = 0.006 mm).
    va, ta, _ = sphere(0.1, 20)
    vb, tb, _ = sphere(0.1, 40, scale=(1.15, 1.0, 0.9))
    res = hausdorff(va, ta, vb, tb)
    assert res["n_samples"] == len(va)
    assert np.array_equal(res["samples"], va)  # all vertices, in order
    ref = cKDTree(surface_samples(vb, tb, 600_000)).query(va)[0]
    rms_ref = np.sqrt(np.mean(ref**2))
    assert rms_ref > 5e-3  # a non-trivial pair
    # Measured relative gaps to the sampled reference: rms 6.9e-4, mean 3.3e-3,
    # max 7.4e-5 (the reference's seeded samples fix them).
    assert res["rms_m"] == pytest.approx(rms_ref, rel=1.5e-3)
    assert res["mean_m"] == pytest.approx(ref.mean(), rel=5e-3)
    assert res["max_m"] == pytest.approx(ref.max(), rel=2e-4)
    assert np.abs(res["distances"] - ref).max() < 0.5e-3
    assert np.sqrt(np.mean(res["distances"] ** 2)) == pytest.approx(res["rms_m"], rel=1e-6)
    # Monte-Carlo face samples: same agreement on the samples it drew.
    faces = hausdorff(va, ta, vb, tb, sample_vertices=False, n_samples=5000)
    assert faces["n_samples"] == len(faces["samples"]) == 5000
    ref_f = cKDTree(surface_samples(vb, tb, 600_000, seed=1)).query(faces["samples"])[0]
    # Measured relative gap 8.6e-4; bound 1.5e-3.
    assert faces["rms_m"] == pytest.approx(np.sqrt(np.mean(ref_f**2)), rel=1.5e-3)


def test_hausdorff_both_directions():
    # A unit-ish sphere and one 2 mm larger: 2 mm either way, up to the
    # tessellation's sagitta (r (1 - cos(pi / 60)) = 0.14 mm at resolution 60).
    # The sampled vertices face matching vertices, so the gap is far smaller:
    # measured 1.05e-6 m on the means and 3e-18 m on the max.
    va, ta, _ = sphere(0.1, 60)
    vb, tb, _ = sphere(0.102, 60)
    ab, ba = hausdorff(va, ta, vb, tb), hausdorff(vb, tb, va, ta)
    res = {"a_to_b": ab, "b_to_a": ba, "max_m": max(ab["max_m"], ba["max_m"])}
    for side in ("a_to_b", "b_to_a"):
        assert res[side]["mean_m"] == pytest.approx(2e-3, abs=2e-6)
    assert res["max_m"] == pytest.approx(2e-3, abs=1e-9)
    # A point set as the sampled side: its points' distances.
    pts = np.array([[0.0, 0.0, 0.2], [0.0, 0.13, 0.0]])
    res = hausdorff(pts, None, va, ta)
    assert res["distances"] == pytest.approx([0.1, 0.03], abs=1e-6)


def test_closest_points_are_the_nearest_of_all_triangles():
    # Points 0-30 mm off an ellipsoid of 3200 triangles: the closest point of
    # each, against every triangle in float64 (brute force), to 1e-12 m
    # (measured 0); single precision alone was off by up to 2e-8 m on the demo.
    vb, tb, _ = sphere(0.1, 40, scale=(1.15, 1.0, 0.9))
    rng = np.random.default_rng(3)
    p = surface_samples(vb, tb, 300) * rng.uniform(0.7, 1.3, (300, 1))
    x, d = closest_points(vb, tb, p)
    every = closest_on_triangles(
        np.repeat(p, len(tb), 0), *(np.tile(vb[tb[:, k]], (300, 1)) for k in range(3))
    )
    brute = (
        np.linalg.norm(np.repeat(p, len(tb), 0) - every, axis=1).reshape(300, len(tb)).min(axis=1)
    )
    assert np.abs(d - brute).max() < 1e-12
    assert np.abs(np.linalg.norm(p - x, axis=1) - d).max() < 1e-15
    assert 0.003 < np.median(d) < 0.03
    # A degenerate (zero-area) triangle is its longest edge; a point right above a face.
    a, b, c = np.zeros((1, 3)), np.array([[1.0, 0, 0]]), np.array([[2.0, 0, 0]])
    assert closest_on_triangles(np.array([[1.5, 1.0, 0]]), a, b, c)[0] == pytest.approx([1.5, 0, 0])
    y = np.array([[0, 1.0, 0]])
    assert closest_on_triangles(np.array([[0.2, 0.2, 1.0]]), a, b, y)[0] == pytest.approx(
        [0.2, 0.2, 0]
    )
    # A point that is not finite has no closest point (NaN, not stale memory).
    assert np.isnan(closest_on_triangles(np.array([[np.nan, 0.2, 1.0]]), a, b, y)).all()
    x, d = closest_points(vb, tb, np.array([[np.nan, 0.0, 0.0], [0.0, 0.0, 0.2]]))
    assert np.isnan(x[0]).all() and np.isnan(d[0]) and np.isfinite(d[1])


def test_hausdorff_matches_meshlab():
    """The distances of MeshLab's Hausdorff filter (pymeshlab, which the evaluation used
    before): here all 762 equal to 3e-17 m. MeshLab reports its statistics in
    single precision (measured: at most 4.4e-10 m off here). On the demo its grid search
    missed the closest triangle for a few samples (27 of 18 596, by up to 0.06 mm)."""
    pymeshlab = pytest.importorskip("pymeshlab")
    va, _, _ = sphere(0.1, 20)
    vb, tb, _ = sphere(0.1, 40, scale=(1.15, 1.0, 0.9))
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=va), "a")
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vb, face_matrix=tb.astype(np.int32)), "b")
    ref = ms.get_hausdorff_distance(
        sampledmesh=0,
        targetmesh=1,
        savesample=True,
        samplevert=True,
        sampleface=False,
        samplenum=len(va),
        maxdist=pymeshlab.PureValue(1.0),
    )
    closest = {ms.mesh(i).label(): ms.mesh(i) for i in range(ms.mesh_number())}
    d_ref = np.linalg.norm(va - closest["Hausdorff Closest Points"].vertex_matrix(), axis=1)
    res = hausdorff(va, None, vb, tb)
    assert res["n_samples"] == ref["n_samples"] == len(va)
    assert np.abs(res["distances"] - d_ref).max() < 1e-12
    for key in ("RMS", "mean", "max", "min"):
        assert res[f"{key.lower()}_m"] == pytest.approx(ref[key], abs=1e-9)


def _depth_map(tmp_path, name, depth, normal, camera):
    finite = np.isfinite(depth)
    result = DepthResult(
        depth.astype(np.float32), normal.astype(np.float32), finite.astype(np.float32), finite, {}
    )
    path = tmp_path / f"{name}.h5"
    write_depth(path, result, camera, {"method": "test"})
    return path


def test_depth_errors_zero_for_truth_and_the_offset_for_a_shift(tmp_path):
    cam = make_camera()
    gv, gt, gn = sphere(0.1, 60)
    gd, gnorm = render_depth_normals(gv, gt, gn, cam, W, H)
    assert 3000 < np.isfinite(gd).sum() < W * H
    dm = read_depth(_depth_map(tmp_path, "truth", gd, gnorm, cam))
    err, ang, m = depth_errors(dm, gv, gt, gn, W, H)
    assert np.array_equal(np.isfinite(err), np.isfinite(gd))
    # float32 storage of 0.8 m: at most half an ulp (2.98e-8 m, measured 2.98e-8 m);
    # bound one ulp, 6e-8 m. rms measured 1.7e-5 mm, normals 8.5e-7 deg.
    assert np.nanmax(np.abs(err)) < 6e-8
    assert m["depth_rms_mm"] < 6e-5 and m["normal_median_deg"] < 2e-6
    assert m["coverage"] == 1.0
    shifted = gd + 2e-3
    shifted[:, : W // 2] = np.nan  # half the image reconstructed
    dm = read_depth(_depth_map(tmp_path, "shifted", shifted, gnorm, cam))
    err, _, m = depth_errors(dm, gv, gt, gn)
    # Measured 2.98e-8 m; median, rms, p95 off by 5.2e-7, 1.4e-7, 2.7e-5 mm: all
    # within the float32 storage's half ulp (3e-5 mm); bound one ulp, 6e-5 mm.
    assert np.nanmax(np.abs(err - 2e-3)) < 6e-8
    assert m["depth_median_mm"] == pytest.approx(2.0, abs=6e-5)
    assert m["depth_rms_mm"] == pytest.approx(2.0, abs=6e-5)
    assert m["depth_p95_mm"] == pytest.approx(2.0, abs=6e-5)
    assert m["coverage"] == pytest.approx(np.isfinite(shifted).sum() / np.isfinite(gd).sum())
    with pytest.raises(ValueError, match="image is"):
        depth_errors(dm, gv, gt, gn, W + 1, H)


def test_seen_surface_is_the_front():
    cam = make_camera()
    gv, gt, _ = sphere(0.1, 40)
    seen, mask, pts = seen_surface(gv, gt, cam, W, H)
    assert len(pts) == mask.sum() > 3000
    # Measured 1.5e-4 m; bound 3e-4 m (the sagitta r (1 - cos(pi / 40)) is 3.1e-4 m).
    assert np.abs(np.linalg.norm(pts, axis=1) - 0.1).max() < 3e-4
    # The camera at distance D sees the smooth sphere up to the rim angle
    # arccos(r / D) from its direction; the polyhedron (4.5 degree steps) one
    # step more (a vertex is visible when one of its faces faces the camera),
    # its seen triangles one step further still.
    c = cam.centre
    angle = np.degrees(np.arccos((gv @ c) / (0.1 * np.linalg.norm(c))))
    rim = np.degrees(np.arccos(0.1 / np.linalg.norm(c)))
    seen_v = np.zeros(len(gv), bool)
    seen_v[gt[seen].ravel()] = True
    visible, pixel = visible_vertices(gv, gt, cam, W, H)
    assert np.all(visible[angle < rim - 0.5]) and not np.any(visible[angle > rim + 5])
    assert np.all(seen_v[angle < rim]) and not np.any(seen_v[angle > rim + 9.5])
    assert 0.4 < seen.mean() < 0.6
    assert np.all(pixel[~visible] == -1) and np.all(pixel[visible] >= 0)


def test_pixel_rays():
    cam = make_camera()
    origin, dirs = pixel_rays(cam, W, H)
    assert dirs.shape == (W * H, 3)
    # Round-off bounds (measured 2.2e-16), left far above it on purpose.
    assert np.abs(np.linalg.norm(dirs, axis=1) - 1).max() < 1e-12
    assert np.allclose(origin, cam.centre, atol=1e-12)
    # Each ray projects back onto its own pixel centre, within the undistortion's
    # tolerance of 1e-9 px (measured 3.6e-14 px).
    uv = project(origin + 0.7 * dirs, cam.K, cam.dist, cam.R, cam.t)
    grid = np.stack(np.meshgrid(np.arange(W), np.arange(H)), -1).reshape(-1, 2)
    assert np.abs(uv - grid).max() < 1e-9


def test_one_cast_serves_depth_errors_and_the_seen_region(tmp_path):
    # The evaluation's shared cast gives what the two separate casts give.
    cam = make_camera()
    gv, gt, gn = sphere(0.1, 40)
    gd, gnorm = render_depth_normals(gv, gt, gn, cam, W, H)
    dm = read_depth(_depth_map(tmp_path, "d", gd + 1e-3, gnorm, cam))
    hits = cast_pixels(gv, gt, gn, cam, W, H)
    truth = depth_normal_maps(hits, cam)
    assert np.array_equal(truth[0], gd, equal_nan=True)
    assert np.array_equal(truth[1], gnorm, equal_nan=True)
    a = depth_errors(dm, gv, gt, gn, truth=truth)
    b = depth_errors(dm, gv, gt, gn)
    assert a[2] == b[2] and abs(a[2]["depth_median_mm"] - 1.0) < 1e-3
    s1 = seen_surface(gv, gt, cam, W, H, hits=hits)
    s2 = seen_surface(gv, gt, cam, W, H)
    assert all(np.array_equal(x, y) for x, y in zip(s1, s2, strict=True))


def test_evaluate_frame_and_metrics_table(tmp_path):
    # GT: a 0.1 m sphere. Reconstruction: a whole sphere 1 mm larger (its back
    # included) and the exact depth map. The two tessellations share their
    # directions, so each seen vertex is 1 mm above a GT vertex (measured
    # 1.0000 mm; completeness 0.9995 mm from points on the facets). Were the
    # unseen back counted, the max would be ~0.2 m.
    cam = make_camera()
    gv, gt, gn = sphere(0.1, 60)
    gt_ply = write_ply(tmp_path / "gt.ply", gv, gt, gn)
    mv, mt, mn = sphere(0.101, 60)
    mesh_ply = write_ply(tmp_path / "mesh.ply", mv, mt, mn)
    gd, gnorm = render_depth_normals(gv, gt, gn, cam, W, H)
    h5 = _depth_map(tmp_path, "depth", gd, gnorm, cam)
    out_json, out_ply = tmp_path / "m" / "sphere_a.json", tmp_path / "m" / "sphere_a.ply"
    info = evaluate_frame(
        h5,
        mesh_ply,
        gt_ply,
        out_json,
        out_ply,
        key=FrameKey("sphere", "000001", "bayes_full"),
    )
    assert json.loads(out_json.read_text()) == pytest.approx(info)
    # Measured: mean and rms 1 mm - 4.6e-7 mm, max 1.0000059 mm (float32 PLY
    # vertices), completeness mean 0.99951 and max 0.99966 mm, depth median
    # 1.5e-5 mm (float32 depth: 6e-5 mm is one ulp at 0.8 m).
    assert info["hausdorff_mean_mm"] == pytest.approx(1.0, abs=1e-6)
    assert info["hausdorff_rms_mm"] == pytest.approx(1.0, abs=1e-6)
    assert info["hausdorff_max_mm"] < 1.00002
    assert 0.3 * len(mv) < info["hausdorff_samples"] < 0.55 * len(mv)
    assert info["completeness_mean_mm"] == pytest.approx(1.0, abs=1e-3)
    assert info["completeness_max_mm"] < 1.00002
    assert info["depth_median_mm"] < 6e-5 and info["coverage"] == 1.0
    cv, ct, _ = load_mesh(out_ply)
    assert len(cv) == len(mv)
    coloured = o3d.io.read_triangle_mesh(str(out_ply))
    assert coloured.has_vertex_colors()
    # The same frame without ground truth: the metrics are empty.
    empty = evaluate_frame(
        h5,
        mesh_ply,
        None,
        tmp_path / "m" / "sphere_b.json",
        key=FrameKey("sphere", "000001", "bayes_nocalib"),
    )
    assert empty["hausdorff_rms_mm"] is None and empty["depth_median_mm"] is None
    # Invented surface: the same sphere plus a small one beside it (radius 2 cm, 7
    # pixels off the true silhouette), in view but off the ground truth: outside_share
    # counts it, the accuracy does not change.
    assert info["outside_share"] < 0.01
    bv, bt, bn = sphere(0.02, 60)
    both = write_ply(
        tmp_path / "both.ply",
        np.vstack([mv, bv + [0.14, 0.0, 0.0]]),
        np.vstack([mt, bt + len(mv)]),
        np.vstack([mn, bn]),
    )
    extra = evaluate_frame(
        h5, both, gt_ply, tmp_path / "extra.json", key=FrameKey("sphere", "000001", "ml_full")
    )
    assert 0.45 < extra["outside_share"] < 0.6  # measured 0.518
    # Measured identical; bound 1e-9 mm.
    assert extra["hausdorff_rms_mm"] == pytest.approx(info["hausdorff_rms_mm"], abs=1e-9)
    evaluate_frame(
        h5,
        mesh_ply,
        gt_ply,
        tmp_path / "m" / "aaa.json",
        key=FrameKey("another", "000000", "ml_full"),
    )
    csv = tmp_path / "reports" / "metrics.csv"
    table = metrics_table(sorted((tmp_path / "m").glob("*.json")), csv)
    read = pd.read_csv(csv, dtype={"frame": str})
    assert list(read.columns[: len(CONTRACT_COLUMNS)]) == list(CONTRACT_COLUMNS)
    assert list(zip(read.scene, read.frame, read.variant, strict=True)) == [
        ("another", "000000", "ml_full"),
        ("sphere", "000001", "bayes_full"),
        ("sphere", "000001", "bayes_nocalib"),
    ]
    assert read.loc[2, "hausdorff_rms_mm":"normal_median_deg"].isna().all()
    assert read.loc[1, "hausdorff_rms_mm"] == pytest.approx(info["hausdorff_rms_mm"])
    assert len(table) == 3
    with pytest.raises(ValueError, match="repeated"):
        metrics_table([out_json, out_json], tmp_path / "dup.csv")
    assert not (tmp_path / "dup.csv").exists()


# --------------------------------------------------------------------------- depth sigma

SIGMA_COLUMNS = (
    "depth_signed_median_mm",
    "depth_sigma_median_mm",
    "sigma_within_1",
    "sigma_within_2",
    "sigma_within_3",
    "expected_depth_error_mm",
    "uncertain_share",
    "reciprocity_defect_deg",
)


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_sigma_shares_of_gaussian_errors(scale):
    """Errors drawn from N(0, sigma), sigma from 0.5 to 3 mm, over 100 000 pixels: a
    calibrated sigma has 0.683, 0.954, 0.997 of them within 1, 2, 3 sigma; a sigma half
    the true one the shares of |N(0, 1)| within 0.5, 1, 1.5: 0.383, 0.683, 0.866.
    Bound: 4 binomial standard deviations, sqrt(p (1 - p) / n) (0.0059, 0.0026,
    0.0007 for the calibrated shares). Measured gaps at most 1.2e-4 (seed 7)."""
    import math

    n = 100_000
    rng = np.random.default_rng(7)
    sigma = rng.uniform(0.5e-3, 3e-3, n)
    err = sigma * rng.standard_normal(n)
    m = sigma_summary(err, scale * sigma)
    for k in (1, 2, 3):
        p = math.erf(scale * k / math.sqrt(2.0))
        assert m[f"sigma_within_{k}"] == pytest.approx(p, abs=4 * math.sqrt(p * (1 - p) / n))
    if scale == 1.0:
        assert [round(GAUSSIAN_WITHIN[k], 3) for k in (1, 2, 3)] == [0.683, 0.954, 0.997]
    assert m["depth_sigma_median_mm"] == pytest.approx(scale * np.median(sigma) * 1e3, rel=1e-12)
    assert m["sigma_pixels"] == n


def test_sigma_summary_skips_pixels_without_error_or_sigma():
    err = np.array([0.5, -1.5, 2.5, np.nan, 0.1, 0.2]) * 1e-3
    sigma = np.array([1.0, 1.0, 1.0, 1.0, np.nan, 1.0]) * 1e-3
    m = sigma_summary(err, sigma)  # pixels 0, 1, 2 and 5: errors 0.5, 1.5, 2.5, 0.2 sigma
    assert m["sigma_pixels"] == 4
    assert (m["sigma_within_1"], m["sigma_within_2"], m["sigma_within_3"]) == (0.5, 0.75, 1.0)
    assert m["depth_sigma_median_mm"] == pytest.approx(1.0, rel=1e-12)
    none = sigma_summary(err, None)
    assert none["sigma_within_1"] is None and none["depth_sigma_median_mm"] is None
    assert sigma_summary(err, np.full(6, np.nan))["sigma_within_2"] is None


def _sigma_depth_map(tmp_path, gd, gnorm, camera):
    """The GT depth off by +0.5 sigma on the left 3/5 of the columns and -1.5 sigma on
    the rest (sigma 1 mm; 2 mm on the bottom rows); the top rows have no sigma and the
    columns right of 0.7 W are flagged uncertain (no depth, not in the mask). Returns
    the file, the signed errors (m) and the sigma (m) written."""
    rows, cols = np.indices(gd.shape)
    sigma = np.where(rows >= 3 * H // 4, 2e-3, 1e-3)
    offset = np.where(cols < 3 * W // 5, 0.5, -1.5) * sigma
    depth = gd + offset
    uncertain = np.isfinite(gd) & (cols > 0.7 * W)
    depth[uncertain] = np.nan
    sigma[rows < H // 5] = np.nan
    mask = np.isfinite(depth)
    result = DepthResult(
        depth.astype(np.float32),
        gnorm.astype(np.float32),
        mask.astype(np.float32),
        mask,
        {},
        depth_sigma=sigma.astype(np.float32),
        uncertain=uncertain,
    )
    path = tmp_path / "sigma.h5"
    write_depth(
        path, result, camera, {"method": "bayes", "params": {"reciprocity_defect_deg": 0.25}}
    )
    return path, np.where(mask, offset, np.nan), sigma


def test_evaluate_frame_sigma_columns(tmp_path):
    """On the pixels the depth errors compare (reconstructed and true), the shares are
    those of the constructed errors: +0.5 sigma within 1, 2 and 3 sigma, -1.5 sigma
    within 2 and 3. Without ground truth the expected error and the flagged share stay;
    a file without sigma (the visual hull, older files) leaves every sigma column empty."""
    cam = make_camera()
    gv, gt, gn = sphere(0.1, 40)
    gt_ply = write_ply(tmp_path / "gt.ply", gv, gt, gn)
    gd, gnorm = render_depth_normals(gv, gt, gn, cam, W, H)
    h5, offset, sigma = _sigma_depth_map(tmp_path, gd, gnorm, cam)
    compared = np.isfinite(offset) & np.isfinite(sigma)
    left = compared & (offset > 0)
    flagged = np.isfinite(gd) & (np.indices(gd.shape)[1] > 0.7 * W)
    assert compared.sum() > 1500 and 0.4 < left.sum() / compared.sum() < 0.9
    out = tmp_path / "m"
    info = evaluate_frame(h5, None, gt_ply, out / "a.json", key=FrameKey("s", "000000", "b"))
    # float32 depths at 0.8 m: 6e-8 m = 0.06 sigma at worst, far from any share's edge
    assert info["sigma_within_1"] == pytest.approx(left.sum() / compared.sum(), abs=1e-12)
    assert info["sigma_within_2"] == info["sigma_within_3"] == 1.0
    assert info["sigma_pixels"] == compared.sum()
    assert np.median(sigma[compared]) == 1e-3  # the 2 mm rows are the fewer
    assert info["depth_sigma_median_mm"] == pytest.approx(1.0, abs=1e-6)  # float32 sigma
    # the bias beside the absolute error (one float32 ulp at 0.8 m: 6e-5 mm)
    reconstructed = np.isfinite(offset)
    signed = np.median(offset[reconstructed]) * 1e3
    assert info["depth_signed_median_mm"] == pytest.approx(signed, abs=6e-5)
    absolute = np.median(np.abs(offset[reconstructed])) * 1e3
    assert info["depth_median_mm"] == pytest.approx(absolute, abs=6e-5)
    expected = np.median(sigma[reconstructed & np.isfinite(sigma)]) * 1e3
    assert info["expected_depth_error_mm"] == pytest.approx(expected, abs=1e-6)
    share = flagged.sum() / (reconstructed.sum() + flagged.sum())
    assert info["uncertain_share"] == pytest.approx(share, abs=1e-12)
    assert 0.05 < share < 0.4
    # no ground truth: no comparison, but the reconstruction's own expected error
    blind = evaluate_frame(h5, None, None, out / "b.json", key=FrameKey("s", "000000", "c"))
    assert blind["sigma_within_1"] is None and blind["depth_sigma_median_mm"] is None
    assert blind["depth_signed_median_mm"] is None
    assert blind["expected_depth_error_mm"] == info["expected_depth_error_mm"]
    assert blind["uncertain_share"] == info["uncertain_share"]
    # the lights' reciprocity defect the reconstruction recorded, with or without truth
    assert blind["reciprocity_defect_deg"] == info["reciprocity_defect_deg"] == 0.25
    # a depth file without sigma: every sigma column empty
    plain = _depth_map(tmp_path, "plain", gd + 1e-3, gnorm, cam)
    vh = evaluate_frame(plain, None, gt_ply, out / "c.json", key=FrameKey("s", "000000", "vh"))
    assert all(vh[c] is None for c in SIGMA_COLUMNS if c != "depth_signed_median_mm")
    assert vh["depth_signed_median_mm"] == pytest.approx(1.0, abs=6e-5)
    assert uncertainty_summary(read_depth(plain)) == {
        "expected_depth_error_mm": None,
        "uncertain_share": None,
        "reciprocity_defect_deg": None,
    }
    # metrics.csv: the new columns after the earlier extras, before the dropped shares
    # (test_dropped.py), method and same_as
    csv = tmp_path / "metrics.csv"
    metrics_table(sorted(out.glob("*.json")), csv)
    read = pd.read_csv(csv, dtype={"frame": str}).set_index("variant")
    tail = [*SIGMA_COLUMNS, *DROP_COLUMNS, "method", "same_as"]
    assert list(read.columns[-len(tail) :]) == tail
    assert tuple(EXTRA_COLUMNS[-len(tail) + 2 :]) == (*SIGMA_COLUMNS, *DROP_COLUMNS)
    assert read.loc["b", "sigma_within_1"] == pytest.approx(info["sigma_within_1"], rel=1e-12)
    assert read.loc["c", "expected_depth_error_mm"] == pytest.approx(expected, abs=1e-6)
    assert read.loc["c", ["sigma_within_1", "depth_sigma_median_mm"]].isna().all()
    assert read.loc["vh", list(SIGMA_COLUMNS[1:])].isna().all()


def test_evaluate_frame_of_the_empty_mesh(tmp_path, caplog):
    """A frame with nothing reconstructed (its depth: 3 pixels beside the sphere, too
    few to mesh) scores as such, without an error: coverage 0, no accuracy or
    completeness (undefined, not 0), 0 vertices scored and an empty coloured mesh,
    with a warning naming the depth file. So does a depth map without any depth."""
    cam = make_camera()
    gv, gt, gn = sphere(0.1, 40)
    gt_ply = write_ply(tmp_path / "gt.ply", gv, gt, gn)
    gd, _ = render_depth_normals(gv, gt, gn, cam, W, H)
    depth = np.full((H, W), np.nan)
    depth[0, :3] = 0.8  # in a corner, off the sphere
    assert not np.isfinite(gd[0, :3]).any()
    h5 = _depth_map(tmp_path, "corner", depth, np.broadcast_to([0.0, 0.0, -1.0], (H, W, 3)), cam)
    mesh_ply = tmp_path / "mesh.ply"
    assert frame_mesh(h5, mesh_ply)["empty"] and is_empty_mesh(mesh_ply)
    out = tmp_path / "m"
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="colourhs"):
        info = evaluate_frame(
            h5, mesh_ply, gt_ply, out / "a.json", out / "a.ply", key=FrameKey("s", "000001", "b")
        )
    assert json.loads((out / "a.json").read_text()) == pytest.approx(info)
    assert info["coverage"] == 0.0 and info["truth_pixels"] == np.isfinite(gd).sum() > 3000
    assert info["hausdorff_samples"] == 0 and info["mesh_vertices"] == 0
    accuracy = [f"hausdorff_{k}_mm" for k in ("rms", "mean", "max", "median")]
    completeness = [f"completeness_{k}" for k in ("rms_mm", "mean_mm", "max_mm", "samples")]
    depth = ["depth_median_mm", "depth_rms_mm", "depth_p95_mm", "depth_signed_median_mm"]
    undefined = [*accuracy, *completeness, "outside_share", *depth, "normal_median_deg"]
    assert {c: info[c] for c in undefined} == dict.fromkeys(undefined)
    assert is_empty_mesh(out / "a.ply")  # the coloured mesh: empty too
    assert load_mesh(out / "a.ply", allow_empty=True)[0].shape == (0, 3)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert [r.name for r in warnings] == ["colourhs.evaluation.accuracy"]
    assert str(h5) in warnings[0].getMessage() and "empty" in warnings[0].getMessage()
    # A depth map without a single depth (read_depth refuses such a file: given as the
    # DepthMap), with and without ground truth.
    none = dataclasses.replace(read_depth(h5), depth=np.full((H, W), np.nan, np.float32))
    key = FrameKey("s", "000002", "b")
    nan = evaluate_frame(none, mesh_ply, gt_ply, out / "b.json", out / "b.ply", key=key)
    assert nan["coverage"] == 0.0 and nan["depth_median_mm"] is None
    assert nan["hausdorff_samples"] == 0 and nan["hausdorff_rms_mm"] is None
    blind = evaluate_frame(none, mesh_ply, None, tmp_path / "c.json", tmp_path / "c.ply")
    assert blind["coverage"] is None and blind["hausdorff_samples"] is None
    assert blind["mesh_vertices"] == 0 and is_empty_mesh(tmp_path / "c.ply")
    # metrics.csv: the frames' rows say it (coverage 0, no vertex scored, accuracy empty)
    metrics_table(sorted(out.glob("*.json")), tmp_path / "metrics.csv")
    read = pd.read_csv(tmp_path / "metrics.csv")
    assert list(read["coverage"]) == [0.0, 0.0] and list(read["hausdorff_samples"]) == [0, 0]
    assert (
        read[["hausdorff_rms_mm", "completeness_rms_mm", "depth_median_mm"]].isna().all(axis=None)
    )
