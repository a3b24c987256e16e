"""The one PLY writer and reader (colourhs.common.ply)."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from colourhs.capture import CaptureFormatError
from colourhs.common.ply import is_empty_mesh, load_mesh, write_ply


def _sphere():
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=0.1, resolution=12)
    mesh.translate([0.02, -0.01, 0.8])
    mesh.compute_vertex_normals()
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles), np.asarray(mesh.vertex_normals)


def test_mesh_with_normals_and_colours_round_trips(tmp_path):
    """float32 coordinates, normals, 8-bit colours: measured errors 3.0e-8 (half a
    float32 ulp below 1); bound one ulp, 6e-8."""
    v, t, n = _sphere()
    rgb = np.random.default_rng(0).uniform(0, 1, (len(v), 3))
    path = write_ply(tmp_path / "m.ply", v, t, n, rgb)
    mesh = o3d.io.read_triangle_mesh(str(path))
    assert np.abs(np.asarray(mesh.vertices) - v).max() < 6e-8
    assert np.abs(np.asarray(mesh.vertex_normals) - n).max() < 6e-8
    assert np.abs(np.asarray(mesh.vertex_colors) - rgb).max() <= 0.5 / 255 + 1e-9
    assert np.array_equal(np.asarray(mesh.triangles), t)
    lv, lt, ln = load_mesh(path)
    assert np.array_equal(lt, t) and np.abs(ln - n).max() < 6e-8
    # 4 bytes a coordinate: 3 + 3 floats and 3 bytes per vertex, 13 bytes per face.
    header = path.read_bytes().index(b"end_header\n") + len(b"end_header\n")
    assert path.stat().st_size - header == len(v) * 27 + len(t) * 13
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.ply"]


def test_points_without_faces_and_uint8_colours(tmp_path):
    v = np.random.default_rng(1).uniform(-1, 1, (50, 3))
    rgb = np.full((50, 3), 200, np.uint8)
    cloud = o3d.io.read_point_cloud(str(write_ply(tmp_path / "p.ply", v, colours=rgb)))
    assert np.abs(np.asarray(cloud.points) - v).max() < 6e-8  # measured 2.9e-8
    assert np.allclose(np.asarray(cloud.colors), 200 / 255)
    with pytest.raises(CaptureFormatError, match="no faces"):
        load_mesh(tmp_path / "p.ply")


def test_mismatched_columns_are_an_error_and_write_nothing(tmp_path):
    v, t, n = _sphere()
    with pytest.raises(ValueError, match="vertices but"):
        write_ply(tmp_path / "bad.ply", v, t, n[:-1])
    assert list(tmp_path.iterdir()) == []


def test_empty_mesh_round_trips(tmp_path):
    """The empty mesh (a frame with nothing reconstructed): a header and no data.
    open3d reads it back as 0 vertices and 0 faces (while reporting a failed read, as
    it does for a file that is not a PLY), so load_mesh reads its header."""
    empty = np.zeros((0, 3))
    path = write_ply(tmp_path / "e.ply", empty, np.zeros((0, 3), np.int32), empty, empty)
    data = path.read_bytes()
    assert data.endswith(b"end_header\n")  # nothing after the header
    assert b"element vertex 0\n" in data and b"element face 0\n" in data
    mesh = o3d.io.read_triangle_mesh(str(path))
    assert len(mesh.vertices) == 0 and len(mesh.triangles) == 0
    assert is_empty_mesh(path)
    v, t, n = load_mesh(path, allow_empty=True)
    assert v.shape == t.shape == n.shape == (0, 3)
    assert v.dtype == n.dtype == np.float64 and np.issubdtype(t.dtype, np.integer)
    with pytest.raises(CaptureFormatError, match="no faces"):
        load_mesh(path)  # the default: a mesh must have a surface (ground truth, hull)
    # allow_empty changes nothing else: a mesh loads, a point cloud and a file that is
    # not a PLY are still errors
    sv, st, sn = _sphere()
    sphere = write_ply(tmp_path / "s.ply", sv, st, sn)
    assert not is_empty_mesh(sphere)
    assert np.array_equal(load_mesh(sphere, allow_empty=True)[1], st)
    cloud = write_ply(tmp_path / "p.ply", sv)
    assert not is_empty_mesh(cloud)
    with pytest.raises(CaptureFormatError, match="no faces"):
        load_mesh(cloud, allow_empty=True)
    (tmp_path / "x.ply").write_bytes(b"not a mesh\n")
    with pytest.raises(CaptureFormatError, match="not a PLY file"):
        load_mesh(tmp_path / "x.ply", allow_empty=True)
    with pytest.raises(CaptureFormatError, match="no faces"):
        load_mesh(tmp_path / "x.ply")
