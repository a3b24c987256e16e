"""Oriented points, hull completion and Poisson meshes (colourhs.surfaces.poisson) against
known geometry."""

from __future__ import annotations

import logging

import h5py
import numpy as np
import open3d as o3d
import pytest
from scipy.spatial import cKDTree

from colourhs.capture import Camera
from colourhs.common.depthfile import DepthResult, read_depth, write_depth
from colourhs.common.geometry import backproject, look_at, pixel_grid, ray_plane_intersection
from colourhs.common.ply import is_empty_mesh, load_mesh, write_ply
from colourhs.surfaces.poisson import (
    add_hull_points,
    crop_to_data,
    frame_mesh,
    oriented_points,
    poisson_mesh,
    poisson_voxel,
)

W, H = 128, 96


def fibonacci_sphere(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


def make_camera(dist=(0.0, 0.0, 0.0, 0.0, 0.0), centre=(0.02, -0.01, -0.8)) -> Camera:
    K = np.array([[300.0, 0.0, W / 2 - 0.3], [0.0, 300.0, H / 2 + 0.2], [0.0, 0.0, 1.0]])
    R, t = look_at(np.array(centre), np.zeros(3))
    return Camera("cam1", K, np.asarray(dist, float), R, t, "red", np.zeros(3))


def write_depth_file(path, camera, depth, normal, attrs=None):
    """A results-contract depth file through the pipeline's own writer."""
    finite = np.isfinite(depth)
    result = DepthResult(
        depth.astype(np.float32), normal.astype(np.float32), finite.astype(np.float32), finite, {}
    )
    write_depth(path, result, camera, attrs or {"method": "test"})
    return path


def plane_depth(camera, point, normal):
    """z-depth (H, W) and the true world points of every pixel's ray on a plane."""
    uv = pixel_grid(W, H).reshape(-1, 2)
    o, d = backproject(uv, camera.K, camera.dist, camera.R, camera.t)
    X, _ = ray_plane_intersection(o, d, point, normal)
    z = (X @ camera.R.T + camera.t)[:, 2]
    return z.reshape(H, W), X


def test_oriented_points_reproduce_a_plane(tmp_path):
    cam = make_camera(dist=(-0.08, 0.03, 1e-3, -5e-4, 0.0))
    p0 = np.array([0.0, 0.0, 0.05])
    n = np.array([0.2, -0.1, 1.0])
    n /= np.linalg.norm(n)  # faces away from the camera (at z = -0.8): must be flipped
    z, X = plane_depth(cam, p0, n)
    path = write_depth_file(tmp_path / "plane.h5", cam, z, np.broadcast_to(n, (H, W, 3)))
    dm = read_depth(path)
    assert dm.camera == "cam1" and np.allclose(dm.dist, cam.dist)
    points, normals = oriented_points(dm)
    assert points.shape == (H * W, 3)
    # float32 depth at 0.85 m holds ~5e-8 m; the undistortion converges to ~1e-12.
    # Measured 3.04e-8 and 2.99e-8 m (half an ulp); bound one ulp, 6e-8 m.
    assert np.abs((points - p0) @ n).max() < 6e-8
    assert np.abs(points - X).max() < 6e-8
    # float32 storage: measured 2.8e-9; bound one ulp, as this rounding can reach it
    assert np.allclose(normals, -n, rtol=0, atol=6e-8)
    assert np.all(np.sum(normals * (cam.centre - points), axis=1) > 0)


def test_oriented_points_skip_pixels_without_depth_or_normal(tmp_path):
    cam = make_camera()
    z, _ = plane_depth(cam, np.zeros(3), np.array([0.0, 0.0, 1.0]))
    normal = np.broadcast_to([0.0, 0.0, -1.0], (H, W, 3)).copy()
    z[:10] = np.nan
    normal[-5:] = np.nan
    dm = read_depth(write_depth_file(tmp_path / "holes.h5", cam, z, normal))
    points, _ = oriented_points(dm)
    assert len(points) == (H - 15) * W


def corrupt_chunk(path, name: str) -> None:
    """Zero 64 bytes in the middle of the first (gzip) chunk of dataset ``name``: the
    file keeps its length and structure, the chunk no longer inflates."""
    with h5py.File(path, "r") as f:
        chunk = f[name].id.get_chunk_info(0)
    data = bytearray(path.read_bytes())
    middle = chunk.byte_offset + chunk.size // 2
    data[middle : middle + 64] = bytes(64)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("case", ["empty", "no_normal", "bad_normal_shape", "corrupt_chunk"])
def test_bad_depth_files_are_refused_by_name(tmp_path, case):
    """A ValueError naming the file and what is wrong. ``corrupt_chunk``:
    a dataset whose bytes are damaged mid-file raised h5py's OSError ("Can't
    synchronously read data (filter returned failure during read)"), without the file."""
    path = tmp_path / f"{case}.h5"
    cam = make_camera()
    depth = np.full((H, W), np.nan, np.float32)
    normal = np.zeros((H, W, 3), np.float32)
    if case == "empty":
        depth, normal = np.zeros((0, 0), np.float32), np.zeros((0, 0, 3), np.float32)
    if case in ("no_normal", "bad_normal_shape", "corrupt_chunk"):
        depth[:] = 0.8
    if case == "corrupt_chunk":
        write_depth_file(path, cam, depth, np.broadcast_to([0.0, 0.0, -1.0], (H, W, 3)))
        corrupt_chunk(path, "depth")
    else:
        with h5py.File(path, "w") as f:
            f["depth"] = depth
            if case != "no_normal":
                f["normal"] = normal[:, :2] if case == "bad_normal_shape" else normal
            f.attrs.update(camera="cam1", K=cam.K, R=cam.R, t=cam.t)
    out = tmp_path / "mesh.ply"
    expected = {
        "empty": "no reconstructed pixels",
        "no_normal": "missing dataset 'normal'",
        "bad_normal_shape": "'normal' has shape",
        "corrupt_chunk": r"dataset 'depth' does not read \(Can't synchronously read data",
    }
    with pytest.raises(ValueError, match=expected[case]) as err:
        frame_mesh(path, out)
    assert str(path) in str(err.value)
    assert not out.exists() and not list(tmp_path.glob(".*"))


def test_add_hull_points_only_away_from_the_data():
    rng = np.random.default_rng(1)
    u = fibonacci_sphere(4000)
    front = u[u[:, 2] < -0.3]  # a cap facing a camera on -z
    points, normals = 0.1 * front, front
    hull_v = 0.104 * fibonacci_sphere(3000) + rng.normal(0, 1e-4, (3000, 3))  # a looser shell
    hull_n = hull_v / np.linalg.norm(hull_v, axis=1, keepdims=True)
    radius = 0.01
    p, n, is_hull = add_hull_points(points, normals, hull_v, hull_n, radius)
    assert np.array_equal(p[~is_hull], points) and np.array_equal(n[~is_hull], normals)
    d_all, _ = cKDTree(points).query(hull_v)
    expected = hull_v[d_all > radius]
    assert is_hull.sum() == len(expected) > 1000
    assert np.array_equal(p[is_hull], expected)
    assert np.allclose(n[is_hull], hull_n[d_all > radius])
    assert cKDTree(points).query(p[is_hull])[0].min() > radius
    # A box keeps only the hull inside it.
    _, _, in_box = add_hull_points(
        points, normals, hull_v, hull_n, radius, box=(np.full(3, -1.0), np.array([1.0, 1.0, 0.0]))
    )
    assert 0 < in_box.sum() < is_hull.sum()


def test_poisson_sphere_is_accurate():
    # 20 000 exact oriented samples of a 0.1 m sphere, octree depth 7: cell edge
    # h = 0.2 m * 1.1 / 2**7 = 1.7 mm. Iso-surface extraction of the smooth
    # indicator errs by about the sagitta h**2 / (8 r) = 0.004 mm, plus Poisson's
    # (screened, hence small) shrinkage. Measured: 0.0123 mm RMS, 0.082 mm max
    # (h / 21); bounds 0.025 mm and h / 10 = 0.17 mm.
    centre, r = np.array([0.1, -0.05, 0.8]), 0.1
    u = fibonacci_sphere(20000)
    mesh = poisson_mesh(centre + r * u, u, depth=7, density_quantile=0.0)
    h = poisson_voxel(centre + r * u, 7)
    assert h == pytest.approx(1.72e-3, rel=1.5e-3)  # measured 1.71866e-3
    err = np.linalg.norm(mesh.vertices - centre, axis=1) - r
    assert np.sqrt(np.mean(err**2)) < 2.5e-5
    assert np.abs(err).max() < h / 10
    outward = np.sum(mesh.normals * (mesh.vertices - centre), axis=1)
    assert np.all(outward > 0)


def test_crop_removes_the_invented_side():
    # A one-sided cap: Poisson closes it into a blob; the crop keeps only the cap.
    centre, r = np.zeros(3), 0.1
    u = fibonacci_sphere(12000)
    cap = u[:, 2] < -0.5
    mesh = poisson_mesh(r * u[cap], u[cap], depth=7)
    max_d = 3e-3
    far = cKDTree(r * u[cap]).query(mesh.vertices)[0] > max_d
    assert far.sum() > 0.1 * len(far)  # the invented closing surface
    cropped = crop_to_data(mesh, r * u[cap], max_d)
    assert 0 < len(cropped.vertices) < len(mesh.vertices)
    assert cKDTree(r * u[cap]).query(cropped.vertices)[0].max() <= max_d
    assert cropped.triangles.max() < len(cropped.vertices)
    err = np.abs(np.linalg.norm(cropped.vertices - centre, axis=1) - r)
    assert np.median(err) < 2e-5  # measured 8.6e-6 m


def test_frame_mesh_writes_a_sphere_ply_and_the_hull_helps(tmp_path):
    # A 0.1 m sphere's depth map (4477 pixels, 2.5 mm apart), meshed with and
    # without a hull 3 mm outside it. Measured: with the hull 0.15 mm RMS, 1.7 mm
    # max (at the limb, pulled towards the hull); without, 0.44 mm and 8.5 mm
    # (Poisson balloons past the limb, up to the 10 mm crop distance).
    cam = make_camera(dist=(-0.05, 0.02, 0.0, 0.0, 0.0))
    centre, r = np.zeros(3), 0.1
    uv = pixel_grid(W, H).reshape(-1, 2)
    o, d = backproject(uv, cam.K, cam.dist, cam.R, cam.t)
    b = d @ (o - centre)
    disc = b**2 - (np.sum((o - centre) ** 2) - r**2)
    X = o + (-b - np.sqrt(np.where(disc > 0, disc, np.nan)))[:, None] * d
    z = (X @ cam.R.T + cam.t)[:, 2].reshape(H, W)
    h5 = write_depth_file(tmp_path / "sphere.h5", cam, z, ((X - centre) / r).reshape(H, W, 3))
    ball = o3d.geometry.TriangleMesh.create_sphere(1.03 * r, 30)
    ball.compute_vertex_normals()
    hull = write_ply(
        tmp_path / "hull.ply",
        np.asarray(ball.vertices),
        np.asarray(ball.triangles),
        np.asarray(ball.vertex_normals),
    )
    points, _ = oriented_points(read_depth(h5))
    errors = {}
    for hull_ply in (None, hull):
        out = tmp_path / "mesh" / f"{hull_ply is None}.ply"
        info = frame_mesh(h5, out, hull_ply=hull_ply, poisson_depth=7)
        assert info["points"] == np.isfinite(z).sum() == len(points)
        assert info["empty"] is False and info["reason"] is None
        assert (info["hull_points"] > 0) == (hull_ply is not None)
        v, t, n = load_mesh(out)
        assert len(t) == info["triangles"] and len(v) == info["vertices"]
        assert np.mean(np.sum(n * (cam.centre - v), axis=1) > 0) > 0.98  # facing the camera
        # Only the side the camera saw: every vertex within the crop distance of the data.
        assert cKDTree(points).query(v)[0].max() <= info["crop_dist_m"]
        errors[hull_ply is not None] = np.linalg.norm(v - centre, axis=1) - r
    rms = {k: np.sqrt(np.mean(e**2)) for k, e in errors.items()}
    assert rms[True] < 0.3e-3 and np.abs(errors[True]).max() < 3e-3
    assert rms[True] < rms[False] and np.abs(errors[True]).max() < np.abs(errors[False]).max()


@pytest.mark.parametrize("case", ["all_nan", "three_pixels", "no_normal", "cropped_away"])
def test_frame_without_a_surface_gets_the_empty_mesh(tmp_path, caplog, case):
    """A frame with no surface to mesh is a result, not an error: the empty mesh (a
    valid PLY with no vertices and no faces), ``empty`` and why in the returned
    dict, and a warning naming the depth file. ``all_nan``: a depth file without a
    single depth (the reconstruction's output for a frame it lost entirely);
    ``cropped_away``: a whole plane whose Poisson surface a 1 nm crop removes."""
    cam = make_camera()
    z, _ = plane_depth(cam, np.zeros(3), np.array([0.0, 0.0, 1.0]))
    normal = np.broadcast_to([0.0, 0.0, -1.0], (H, W, 3)).copy()
    if case in ("three_pixels", "all_nan"):
        z[:] = np.nan
    if case == "three_pixels":
        z[0, :3] = 0.8
    if case == "no_normal":
        normal[:] = np.nan
    h5 = write_depth_file(tmp_path / f"{case}.h5", cam, z, normal)
    out = tmp_path / "mesh" / f"{case}.ply"
    crop = 1e-9 if case == "cropped_away" else None
    with caplog.at_level(logging.WARNING, logger="colourhs"):
        info = frame_mesh(h5, out, poisson_depth=6, crop_dist_m=crop)
    points = {"all_nan": 0, "three_pixels": 3, "no_normal": 0, "cropped_away": H * W}[case]
    assert info["empty"] is True and info["points"] == points
    assert info["vertices"] == info["triangles"] == info["hull_points"] == 0
    if case == "cropped_away":
        assert info["reason"].startswith("the Poisson mesh is empty after cropping")
        assert info["crop_dist_m"] == 1e-9 and info["spacing_m"] > 0
    else:
        assert info["reason"] == f"only {points} pixels with depth and normal (Poisson needs 4)"
        assert info["spacing_m"] is None and info["crop_dist_m"] is None
    assert is_empty_mesh(out) and o3d.io.read_triangle_mesh(str(out)).is_empty()
    v, t, n = load_mesh(out, allow_empty=True)
    assert v.shape == t.shape == n.shape == (0, 3)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and warnings[0].name == "colourhs.surfaces.poisson"
    assert str(h5) in warnings[0].getMessage() and info["reason"] in warnings[0].getMessage()
