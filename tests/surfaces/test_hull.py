"""Visual hull: carving a sphere seen by a ring of cameras, and the tiny preset's scenes."""

from __future__ import annotations

import shutil

import cv2
import h5py
import numpy as np
import open3d as o3d
import pytest
from scipy.ndimage import binary_erosion

from colourhs.capture import Camera, CaptureFormatError, open_dataset, read_mask
from colourhs.common.geometry import backproject, look_at, pixel_grid
from colourhs.common.ply import load_mesh
from colourhs.common.progress import show_progress
from colourhs.common.raycast import render_depth_normals
from colourhs.surfaces.hull import (
    HullOptions,
    axes_centre,
    carve,
    carve_field,
    depth_bounds,
    hull_depth_range,
    hull_surface,
    mesh_volume,
    visual_hull,
    working_volume,
)
from colourhs.surfaces.silhouettes import silhouettes, threshold_silhouette

# ---------------------------------------------------------------------------------------------
# A sphere of radius R at the origin, 12 cameras at distance D on two rings (+-25 deg
# elevation, interleaved), 160 x 160 pixels, f = 300 px (1.5 mm pixel footprint at the
# sphere), mild barrel distortion.

R_SPHERE, D_CAM, SIZE, F_PX, VOXEL = 0.05, 0.5, 160, 300.0, 0.002
LO, HI = np.full(3, -0.08), np.full(3, 0.08)


def _ring_cameras(n=12):
    cams = []
    for k in range(n):
        az, el = 2 * np.pi * k / n, np.radians(25.0 if k % 2 else -25.0)
        c = D_CAM * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        Rm, t = look_at(c, np.zeros(3), down=(0.0, 0.0, -1.0))
        K = np.array([[F_PX, 0, (SIZE - 1) / 2], [0, F_PX, (SIZE - 1) / 2], [0, 0, 1.0]])
        dist = np.array([-0.05, 0.01, 0.0, 0.0, 0.0])
        cams.append(Camera(f"c{k}", K, dist, Rm, t, "red", np.zeros(3)))
    return cams


def _sphere_silhouette(cam):
    """Pixels whose centre's ray meets the sphere (exact, through the distortion model)."""
    origin, d = backproject(pixel_grid(SIZE, SIZE).reshape(-1, 2), cam.K, cam.dist, cam.R, cam.t)
    axis = -origin / np.linalg.norm(origin)
    cos_beta = np.sqrt(1 - (R_SPHERE / np.linalg.norm(origin)) ** 2)
    return (d @ axis >= cos_beta).reshape(SIZE, SIZE)


def _exact_hull_radius(u, cams):
    """Radius of the exact visual hull of the sphere along unit directions u (N, 3).

    The exact hull is the intersection of the cameras' tangent cones: X is in
    it iff, for every camera centre C, the angle between X - C and -C is at
    most asin(R / |C|). Bisection along each direction (the hull is star-shaped
    about the centre, being convex).
    """

    def inside(X):
        ok = np.ones(len(X), bool)
        for cam in cams:
            C = cam.centre
            v = X - C
            cos = (v @ -C) / (np.linalg.norm(v, axis=1) * np.linalg.norm(C))
            ok &= cos >= np.sqrt(1 - (R_SPHERE / np.linalg.norm(C)) ** 2)
        return ok

    lo, hi = np.full(len(u), R_SPHERE * 0.999), np.full(len(u), 2 * R_SPHERE)
    for _ in range(40):
        mid = (lo + hi) / 2
        ins = inside(mid[:, None] * u)
        lo, hi = np.where(ins, mid, lo), np.where(ins, hi, mid)
    return (lo + hi) / 2


def _fibonacci_sphere(n):
    k = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * k / n)
    theta = np.pi * (1 + 5**0.5) * k
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


@pytest.fixture(scope="module")
def ring():
    cams = _ring_cameras()
    return cams, [_sphere_silhouette(c) for c in cams]


def test_axes_centre_is_the_fixation_point(ring):
    cams, _ = ring
    assert np.linalg.norm(axes_centre(cams)) < 1e-12  # round-off: measured 1.6e-17


def test_sphere_hull_contains_the_sphere_and_is_close_to_the_exact_hull(ring):
    cams, sils = ring
    occ = carve(sils, cams, LO, HI, VOXEL)
    assert occ.shape == (80, 80, 80)
    # Every point of the solid sphere lies in an occupied voxel (conservative carving).
    pts = _fibonacci_sphere(4000)[:, None, :] * np.array([1.0, 0.7, 0.3])[None, :, None] * R_SPHERE
    idx = np.floor((pts.reshape(-1, 3) - LO) / VOXEL).astype(int)
    assert occ[idx[:, 0], idx[:, 1], idx[:, 2]].all()
    # The exact hull of the 12 views touches the sphere on the tangent circles and
    # overshoots it between them and towards the poles, which no camera looks
    # along: measured 2.54 mm (5 % of R) at most, 0.23 mm on average, and
    # 0.9 % more volume than the sphere (Monte Carlo).
    u = _fibonacci_sphere(3000)
    rho = _exact_hull_radius(u, cams)
    # (rho.min() - R measured 2.9e-11 m: the tangent circles, to round-off.)
    assert 0.0 <= rho.min() - R_SPHERE < 1e-9 and 2e-3 < rho.max() - R_SPHERE < 3e-3
    # Occupied voxel centres lie outside the exact hull by at most the voxel's
    # circumradius (a voxel is kept when its bounding sphere meets every cone:
    # 1.73 mm) plus one pixel footprint at the farthest voxel (half a pixel of
    # margin for the masks' sampling at pixel centres, and half a pixel of that
    # sampling itself: 0.58 m / 300 px = 1.93 mm). Measured: 3.14 mm, on the rind.
    rind = occ & ~binary_erosion(occ)
    c = LO + (np.argwhere(rind) + 0.5) * VOXEL
    r = np.linalg.norm(c, axis=1)
    excess = r - _exact_hull_radius(c / r[:, None], cams)
    bound = np.sqrt(3) / 2 * VOXEL + (D_CAM + 0.08) / F_PX
    assert excess.max() < bound
    # Its volume: the exact hull's plus a rind up to `bound` thick. Measured: +18 %.
    sphere = 4 / 3 * np.pi * R_SPHERE**3
    assert 1.0 < occ.sum() * VOXEL**3 / sphere < 1.0 + 3 * bound / R_SPHERE


def test_sphere_hull_mesh_is_closed_outward_and_tight(ring):
    cams, sils = ring
    field = carve_field(sils, cams, LO, HI, VOXEL)
    # Coarse-to-fine evaluation gives the same signs as evaluating every voxel.
    assert np.array_equal(field < 0, carve_field(sils, cams, LO, HI, VOXEL, block=1) < 0)
    v, t, n = hull_surface(field, LO, VOXEL)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(t))
    assert mesh.is_edge_manifold(allow_boundary_edges=False) and mesh.is_vertex_manifold()
    assert np.all(np.sum(n * v, axis=1) > 0)  # outward normals on a star-shaped hull
    # Vertices lie on the exact hull to within half a voxel: the field's zero level
    # is the masks' outline, which samples the true one at pixel centres (half a
    # pixel, 0.75 mm). Measured: -0.70 to +0.66 mm (voxel 2 mm).
    r = np.linalg.norm(v, axis=1)
    err = r - _exact_hull_radius(v / r[:, None], cams)
    assert -0.5 * VOXEL < err.min() and err.max() < 0.5 * VOXEL
    # The true sphere is inside the mesh, to within half a voxel (the same half
    # pixel). Measured: at most 0.59 mm outside.
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    pts = (_fibonacci_sphere(3000) * R_SPHERE).astype(np.float32)
    assert scene.compute_signed_distance(o3d.core.Tensor(pts)).numpy().max() < 0.5 * VOXEL
    # Volume: measured 1.007 sphere volumes, the exact hull's being 1.009.
    volume = mesh_volume(v, t) / (4 / 3 * np.pi * R_SPHERE**3)
    assert 0.995 < volume < 1.025
    # The binary occupancy meshes too, closed and outward (a voxel coarser).
    vb, tb, nb = hull_surface(field <= 0, LO, VOXEL)
    assert mesh_volume(vb, tb) > 0 and np.mean(np.sum(nb * vb, axis=1) > 0) > 0.99


def test_depth_bounds_bracket_the_sphere(ring):
    cams, sils = ring
    # Silhouettes widened by half a pixel (as visual_hull does): the hull then holds
    # every ray through a silhouette pixel's centre.
    field = carve_field(sils, cams, LO, HI, VOXEL, margin_px=0.5)
    v, t, _ = hull_surface(field, LO, VOXEL)
    cam = cams[0]
    near, far = depth_bounds(v, t, cam, SIZE, SIZE)
    # Sphere entry and exit depths per pixel, closed form.
    origin, d = backproject(pixel_grid(SIZE, SIZE).reshape(-1, 2), cam.K, cam.dist, cam.R, cam.t)
    b = d @ origin
    disc = b**2 - (origin @ origin - R_SPHERE**2)
    hit = disc > 0
    s_in, s_out = -b - np.sqrt(np.where(hit, disc, 0)), -b + np.sqrt(np.where(hit, disc, 0))
    cos = d @ cam.R[2]
    z_in, z_out = (s_in * cos).reshape(SIZE, SIZE), (s_out * cos).reshape(SIZE, SIZE)
    hit = hit.reshape(SIZE, SIZE)
    assert np.isfinite(near[hit]).all() and np.isfinite(far[hit]).all()
    assert np.all(near[hit] <= z_in[hit] + 0.5 * VOXEL)
    assert np.all(far[hit] >= z_out[hit] - 0.5 * VOXEL)
    # On the silhouette's inner part the bounds are tight (a few mm: the hull's overshoot).
    core = cv2.erode(hit.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert np.median(z_in[core] - near[core]) < 2e-3
    far_off = ~cv2.dilate(hit.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert np.isnan(near[far_off]).all()


def test_hull_depth_range_holds_the_sphere_and_little_more(ring):
    cams, sils = ring
    field = carve_field(sils, cams, LO, HI, VOXEL, margin_px=0.5)
    v, t, _ = hull_surface(field, LO, VOXEL)
    cam = cams[0]
    near, far = hull_depth_range(v, t, cam, SIZE, SIZE, margin_m=0.003)
    # The sphere spans z in [D - R, D + R] along the camera's axis (it looks at the centre).
    assert near <= D_CAM - R_SPHERE - 0.003 + 0.5 * VOXEL
    assert far >= D_CAM + R_SPHERE + 0.003 - 0.5 * VOXEL
    # No wider than the 12-camera hull's overshoot plus the margins: measured
    # 2.7 mm nearer and 0.95 mm farther; bounds 2 and 1 voxels (4 and 2 mm).
    assert near > D_CAM - R_SPHERE - 0.003 - 2 * VOXEL
    assert far < D_CAM + R_SPHERE + 0.003 + VOXEL
    away = Camera(
        "away", cam.K, cam.dist, cam.R, cam.t + np.array([0.0, 0.0, -2.0]), "red", np.zeros(3)
    )
    with pytest.raises(ValueError, match="not seen by camera away"):
        hull_depth_range(v, t, away, SIZE, SIZE)


def test_working_volume_finds_the_sphere(ring):
    cams, sils = ring
    lo, hi = working_volume(sils, cams, VOXEL)
    # The hull's bounding box widened by one coarse voxel (2 * 0.25 m / 64 = 7.8 mm)
    # and two voxels, inside the searched cube (+-0.25 m). Measured: +-66.5 mm
    # across the rings' axis, +-74.3 mm along it (the hull's overshoot at the poles).
    assert np.all(lo < -R_SPHERE) and np.all(hi > R_SPHERE)
    assert np.all(lo > -R_SPHERE - 0.03) and np.all(hi < R_SPHERE + 0.03)
    explicit = working_volume(sils, cams, VOXEL, bounds=(LO, HI))
    assert np.array_equal(explicit[0], LO) and np.array_equal(explicit[1], HI)


# ---------------------------------------------------------------------------------------------
# The tiny preset (160 x 120, three cameras, about 20 deg apart)


@pytest.mark.parametrize("scene", ["statue", "plane"])
def test_tiny_hull_contains_ground_truth(tiny_dataset, tmp_path, scene):
    ply, h5 = tmp_path / "hull.ply", tmp_path / "depth.h5"
    info = visual_hull(tiny_dataset, scene, "000000", ply, out_depth_h5=h5)
    vox = info["voxel_m"]
    # Two pixel footprints at the 0.77 m working distance with f = 312.5 px.
    assert 4.5e-3 < vox < 5.5e-3
    assert info["silhouettes"] == "masks" and info["volume_m3"] > 0
    v, t, _ = load_mesh(ply)
    assert len(v) == info["n_vertices"]
    ds = open_dataset(tiny_dataset, check_images=False)
    gv, gt, gn = load_mesh(ds.gt_mesh(scene, 0))
    scene_rc = o3d.t.geometry.RaycastingScene()
    scene_rc.add_triangles(
        o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(t.astype(np.uint32))
    )
    sd = scene_rc.compute_signed_distance(o3d.core.Tensor(gv.astype(np.float32))).numpy()
    # Every ground-truth vertex inside the hull, within a voxel (5 mm). Measured: at
    # most 0.05 mm out (statue), 1.9 mm (plane: its rim, where the hull is thinnest).
    assert sd.max() < vox
    cam = ds.rig.cameras[0]
    near, far = depth_bounds(v, t, cam, 160, 120)
    gd, _ = render_depth_normals(gv, gt, gn, cam, 160, 120)
    m = np.isfinite(gd)
    assert m.sum() > 3000  # measured 4647 pixels
    # The hull's entry and exit bracket the true depth (measured: within 0.6 mm), but
    # for rare rays through a corner of the silhouette: the hull is thinner than a
    # voxel there, and marching cubes cuts it off (measured: one pixel of 7121 on the
    # board's corner, none on the statue; on the demo, one of 113817 on the board).
    tol = 0.5 * vox
    bad = m & ~((near <= gd + tol) & (far >= gd - tol))
    rim = m & ~cv2.erode(m.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert bad.sum() <= 2 and not (bad & ~rim).any()
    with h5py.File(h5) as f:
        depth, mask, conf = f["depth"][:], f["mask"][:], f["confidence"][:]
        assert f.attrs["camera"] == cam.name and f.attrs["method"] == "visual_hull"
        normal = f["normal"][:]
    # The vh depth map is the hull's near side, on the reference silhouette.
    sil = read_mask(ds.mask_image(scene, 0, cam.name), ds.rig.image)
    assert np.array_equal(mask, sil & np.isfinite(near))
    # Measured 3.1e-6 m off (bound 6e-6 m) and unit normals to 6e-8 (float32: two
    # ulps, 2.5e-7).
    assert np.allclose(depth[mask], near[mask], rtol=0, atol=6e-6) and np.all(conf[mask] == 1)
    assert np.allclose(np.linalg.norm(normal[mask], axis=1), 1, rtol=0, atol=2.5e-7)


def test_empty_mask_is_refused_and_nothing_written(tiny_dataset, tmp_path):
    root = shutil.copytree(tiny_dataset, tmp_path / "ds")
    mask = root / "scenes" / "statue" / "masks" / "000000" / "cam2.png"
    cv2.imwrite(str(mask), np.zeros((120, 160), np.uint8))
    out = tmp_path / "out" / "hull.ply"
    with pytest.raises(CaptureFormatError, match="no object pixel") as err:
        visual_hull(root, "statue", "000000", out, out_depth_h5=tmp_path / "out" / "d.h5")
    assert err.value.path == mask
    assert not out.parent.exists() or not any(out.parent.iterdir())


def test_inconsistent_silhouettes_carve_to_nothing(tiny_dataset, tmp_path):
    root = shutil.copytree(tiny_dataset, tmp_path / "ds")
    mask = np.zeros((120, 160), np.uint8)
    mask[2:8, 2:8] = 255  # the object in a corner of cam2 only: no common volume
    cv2.imwrite(str(root / "scenes" / "statue" / "masks" / "000000" / "cam2.png"), mask)
    out = tmp_path / "hull.ply"
    with pytest.raises(CaptureFormatError, match="empty|carves to nothing") as err:
        visual_hull(root, "statue", 0, out)
    assert err.value.path == root / "scenes" / "statue" / "frames" / "000000"
    assert not out.exists()


def test_threshold_silhouettes_match_the_masks(tiny_dataset, tmp_path):
    root = shutil.copytree(tiny_dataset, tmp_path / "ds")
    masks = silhouettes(root, "statue", 0)
    plane_masks = silhouettes(root, "plane", 0)
    shutil.rmtree(root / "scenes" / "statue" / "masks")
    shutil.rmtree(root / "scenes" / "plane" / "masks")
    # Measured IoU 0.982-0.985 (statue), 0.981-0.987 (plane): the threshold keeps the
    # rim pixels that the object covers by less than half, and misses none.
    for scene, given in (("statue", masks), ("plane", plane_masks)):
        found = silhouettes(root, scene, 0)
        for name, m in given.items():
            s = found[name]
            assert (m & s).sum() / (m | s).sum() > 0.97
            assert (m & ~s).sum() <= 0.005 * m.sum()
    info = visual_hull(root, "statue", 0, tmp_path / "hull.ply")
    assert info["silhouettes"] == "threshold"
    # A dark frame has no object: the error names the image that was thresholded.
    frame = root / "scenes" / "statue" / "frames" / "000000" / "cam1.png"
    cv2.imwrite(str(frame), np.zeros((120, 160, 3), np.uint16))
    with pytest.raises(CaptureFormatError, match="threshold") as err:
        silhouettes(root, "statue", 0)
    assert err.value.path == frame


def test_visual_hull_carves_with_its_options(tiny_dataset, tmp_path):
    """HullOptions reach the carving: a given voxel edge and box are used as they
    are, and silhouettes not widened and seen by all three cameras give a smaller hull."""
    default = visual_hull(tiny_dataset, "statue", 0, tmp_path / "a.ply")
    assert (default["min_views"], default["margin_px"]) == (2, 0.5)
    options = HullOptions(
        voxel_m=default["voxel_m"], bounds=default["bounds"], min_views=3, margin_px=0.0
    )
    tight = visual_hull(tiny_dataset, "statue", 0, tmp_path / "b.ply", options)
    assert tight["voxel_m"] == default["voxel_m"] and tight["bounds"] == default["bounds"]
    assert (tight["min_views"], tight["margin_px"]) == (3, 0.0)
    assert tight["volume_m3"] < default["volume_m3"]


def test_threshold_silhouette_cleanup():
    img = np.zeros((40, 50, 3), np.float32)
    img[10:30, 10:40] = 0.5
    img[18:22, 20:24] = 0.0  # a dark spot on the object: filled
    img[12:28, 33] = 0.0  # a dark crack: filled
    img[33:38, 5:8] = 0.03  # a small, faint second object: kept
    img[2, 2] = img[35, 45] = 0.9  # hot pixels: dropped
    sil = threshold_silhouette(img, 0.02)
    expected = np.zeros((40, 50), bool)
    expected[10:30, 10:40] = True
    expected[33:38, 5:8] = True
    assert np.array_equal(sil, expected)


def test_padded_field_is_meshed_in_place_to_the_same_mesh(ring, monkeypatch):
    """The paper-scale hull peaked at 8 GB from copies of its 1.8 GB field
    (the block upsampling, then the float32 copy, finite mask, inf replacement and
    padding of marching cubes' input). The padded field is built without copies
    and meshed in place: same numbers, and far less memory than the old copies."""
    import tracemalloc

    import colourhs.surfaces.carving as carving
    from colourhs.surfaces.hull_mesh import march_surface

    cams, sils = ring
    monkeypatch.setattr(carving, "SLAB_VOXELS", 1 << 14)  # small batches: the field dominates
    tracemalloc.start()
    padded = carve_field(sils, cams, LO, HI, VOXEL / 2, pad=1)
    carving_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.reset_peak()
    plain = carve_field(sils, cams, LO, HI, VOXEL / 2)
    assert padded.shape == tuple(n + 2 for n in plain.shape) == (162, 162, 162)
    assert np.array_equal(padded[1:-1, 1:-1, 1:-1], plain)
    border = np.ones(padded.shape, bool)
    border[1:-1, 1:-1, 1:-1] = False
    assert np.all(padded[border] == np.inf)
    v, t, n = hull_surface(plain, LO, VOXEL / 2)
    before = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    vp, tp = march_surface(padded, LO, VOXEL / 2, padded=True)
    meshing_peak = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert np.array_equal(v, vp) and (np.array_equal(t, tp) or np.array_equal(t, tp[:, ::-1]))
    assert np.isfinite(padded).all()  # its +inf became the outside level, in place
    # Peak numpy memory in field sizes (17 MB). Measured: carving 1.32 (the field and
    # the coarse pass), meshing in place 0.54 (the mesh, and slabs of the field's
    # finite mask). Before: 1.77 (the upsampling's copies) and 4.46 (hull_surface's).
    assert carving_peak < 1.45 * plain.nbytes and meshing_peak < 0.8 * plain.nbytes
    # The grid path (block=1) pads the same way.
    one = carve_field(sils, cams, LO, HI, 2 * VOXEL, block=1, pad=1)
    assert np.array_equal(
        one[1:-1, 1:-1, 1:-1], carve_field(sils, cams, LO, HI, 2 * VOXEL, block=1)
    )


def test_visual_hull_reports_its_stages_on_stderr(tiny_dataset, tmp_path, capsys):
    """The rule's log showed nothing for the 45 s of a paper-scale hull (now
    at most 6 s apart there: the marching cubes, one library call; the depth map and
    the writes took 7.1 s after one line, now two). Shown as the command line shows
    them (:func:`show_progress`); a library call prints nothing."""
    visual_hull(tiny_dataset, "statue", 0, tmp_path / "b.ply")
    assert capsys.readouterr() == ("", "")
    show_progress()
    info = visual_hull(
        tiny_dataset, "statue", 0, tmp_path / "a.ply", out_depth_h5=tmp_path / "a.h5"
    )
    out, err = capsys.readouterr()
    grid = " x ".join(map(str, info["grid"]))
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert out == "" and f"visual hull: carving {grid} voxels" in err
    assert "visual hull: marching cubes [" in err and "carving near the outline" in err
    assert "carving: block centres: 100%" in err
    assert "carving: blocks a frustum boundary crosses: 100%" in err
    assert " blocks near the outline; the field's " in err
    stages = [line for line in lines if line.startswith("visual hull")]
    assert len(stages) == 8 and all(line.endswith(" s]") for line in stages)
    assert "visual hull: orienting " in err
    assert "visual hull: writing a.ply and its depth map [" in err
