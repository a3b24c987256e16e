"""The report's offline 3D view (colourhs.report.view3d): packing and simplifying meshes."""

from __future__ import annotations

import base64
import logging

import numpy as np
import open3d as o3d
import pytest

from colourhs.common.ply import write_ply
from colourhs.report.view3d import mesh_payload, pack_mesh, scene_views


def _unpack(p: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the page's decode() reads: int16 vertices, uint8 colours, uint32 triangles."""
    v = np.frombuffer(base64.b64decode(p["v"]), "<i2").reshape(-1, 3)
    c = np.frombuffer(base64.b64decode(p["c"]), np.uint8).reshape(-1, 3)
    t = np.frombuffer(base64.b64decode(p["t"]), "<u4").reshape(-1, 3)
    return v, c, t


def test_pack_mesh_round_trip():
    rng = np.random.default_rng(0)
    verts = rng.uniform([0.1, -0.2, 0.7], [0.3, 0.0, 0.8], (50, 3))  # metres
    tris = rng.integers(0, 50, (80, 3))
    cols = rng.uniform(0, 1, (50, 3))
    p = pack_mesh(verts, tris, cols)
    v, c, t = _unpack(p)
    assert (p["nv"], p["nt"]) == (50, 80) and np.array_equal(t, tris)
    size = np.ptp(verts, axis=0).max()
    assert p["size_m"] == pytest.approx(size)
    centre = (verts.min(axis=0) + verts.max(axis=0)) / 2
    # quantised to size / 65534: 3 um on a 0.2 m box, at most half a step off
    assert np.abs(v / 65534 * size + centre - verts).max() <= 0.5 * size / 65534 + 1e-12
    assert np.abs(v).max() <= 32767 and np.abs(c / 255 - cols).max() <= 0.5 / 255 + 1e-9
    # a rotation turns the mesh into that camera's axes: x <- world y, y <- world -x
    R = np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]])
    vr, _, _ = _unpack(pack_mesh(verts, tris, cols, rotation=R))
    assert np.array_equal(vr[:, 0], v[:, 1]) and np.array_equal(vr[:, 1], -v[:, 0])


def test_mesh_payload_simplifies_and_keeps_colours(tmp_path):
    sphere = o3d.geometry.TriangleMesh.create_sphere(0.05, resolution=30)  # 3480 triangles
    verts, tris = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    colours = np.tile([0.2, 0.6, 0.4], (len(verts), 1))
    for v in ("vh", "bayes_ph"):
        (tmp_path / "plane" / v / "eval").mkdir(parents=True)
        write_ply(tmp_path / "plane" / v / "eval" / "000000.ply", verts, tris, colours=colours)
    full = mesh_payload(tmp_path / "plane" / "vh" / "eval" / "000000.ply", max_triangles=10**6)
    assert full["nt"] == len(tris) == 3480
    small = mesh_payload(tmp_path / "plane" / "vh" / "eval" / "000000.ply", max_triangles=1000)
    assert 900 <= small["nt"] <= 1000  # measured 1000
    _, c, _ = _unpack(small)
    assert np.abs(c.astype(int) - [51, 153, 102]).max() <= 1  # colours kept
    assert small["size_m"] == pytest.approx(0.1, rel=0.005)  # measured 2.7e-3 off
    views = scene_views(tmp_path, "plane", max_triangles=1000)
    assert list(views) == ["vh", "bayes_ph"]  # the paper's order
    assert views["bayes_ph"]["nt"] == small["nt"] and scene_views(tmp_path, "none") == {}


def test_simplify_large_noisy_mesh_fits_the_budget_and_keeps_the_shape():
    """Over PRE_FACTOR x the budget: clustering first, then quadric decimation;
    the result fits the budget, keeps the colours and stays on the surface."""
    from colourhs.report.view3d import PRE_FACTOR, simplify

    sphere = o3d.geometry.TriangleMesh.create_sphere(0.05, resolution=80)  # 25280 triangles
    rng = np.random.default_rng(1)
    verts = np.asarray(sphere.vertices) + rng.normal(0, 2e-4, (len(sphere.vertices), 3))
    sphere.vertices = o3d.utility.Vector3dVector(verts)
    sphere.vertex_colors = o3d.utility.Vector3dVector(np.tile([0.2, 0.6, 0.4], (len(verts), 1)))
    assert len(sphere.triangles) > PRE_FACTOR * 1000
    small = simplify(sphere, 1000)
    assert 900 <= len(small.triangles) <= 1000  # measured 999
    r = np.linalg.norm(np.asarray(small.vertices), axis=1)
    assert np.abs(r - 0.05).max() < 1.5e-3  # measured 0.6 mm (the chords of 1000 triangles)
    assert np.abs(np.asarray(small.vertex_colors) - [0.2, 0.6, 0.4]).max() < 1e-6
    assert simplify(sphere, 10**6) is sphere


def test_scene_views_leave_out_the_empty_mesh(tmp_path, caplog):
    """A variant whose first frame has nothing reconstructed (the empty mesh) has no 3D
    view, with a warning naming the file; a file that is no mesh at all still raises."""
    sphere = o3d.geometry.TriangleMesh.create_sphere(0.05, resolution=10)
    verts, tris = np.asarray(sphere.vertices), np.asarray(sphere.triangles)
    empty = np.zeros((0, 3))
    for v in ("vh", "bayes_full"):
        (tmp_path / "seq" / v / "eval").mkdir(parents=True)
    write_ply(tmp_path / "seq" / "vh" / "eval" / "000000.ply", verts, tris, colours=verts * 0)
    blank = tmp_path / "seq" / "bayes_full" / "eval" / "000000.ply"
    write_ply(blank, empty, np.zeros((0, 3), int), empty, colours=empty)
    assert mesh_payload(blank) is None
    with caplog.at_level(logging.WARNING, logger="colourhs"):
        views = scene_views(tmp_path, "seq")
    assert list(views) == ["vh"] and views["vh"]["nt"] == len(tris)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and str(blank) in warnings[0] and "bayes_full" in warnings[0]
    (tmp_path / "junk.ply").write_bytes(b"\x00" * 64)
    with pytest.raises(ValueError, match="not a PLY file"):
        mesh_payload(tmp_path / "junk.ply")
    with pytest.raises(ValueError, match="no faces"):
        mesh_payload(write_ply(tmp_path / "cloud.ply", verts))
