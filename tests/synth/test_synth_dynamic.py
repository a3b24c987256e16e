"""Dynamic multi-coloured scenes: sequences in the capture format
whose chromaticity follows the surface, and scene.json's ``chromatic_frame``."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
from capture_helpers import edit_json, make_dataset, raises

from colourhs.capture import CaptureFormatError, load_rig, open_dataset, validate
from colourhs.common.geometry import axis_angle, project
from colourhs.common.ply import load_mesh
from colourhs.synth import dynamicscenes as dyn
from colourhs.synth.poses import in_view
from colourhs.synth.randomrig import RANGES_BY_NAME, draw_random
from colourhs.synth.scenes import WHITE_ALBEDO
from colourhs.synth.simulated_rig import Nuisances
from colourhs.synth.synthesise import PRESETS, RenderSelection, synthesise

FRAMES = 12
SEQUENCES = ("moving-toy", "cloth", "turning-metal")
TOY_EYE = (0.13, -0.045, -0.033)  # centre of a dark eye of scenes.toy (reflectance 0.06)


@pytest.fixture(scope="module")
def dynamic_tiny(tmp_path_factory):
    """The dynamic-tiny preset (seed 0) without the geometric captures."""
    parts = ("photometric", "chromatic", "scenes")
    out = tmp_path_factory.mktemp("dynamic") / "dynamic-tiny"
    return synthesise(out, "dynamic-tiny", selection=RenderSelection(parts=parts), workers=2)


def _frame_names(n=FRAMES):
    return [f"{f:06d}" for f in range(n)]


def _chroma(root, scene, frame):
    with h5py.File(root / "scenes" / scene / "gt" / "chromaticity" / f"{frame}.h5") as f:
        return {cam: f[cam][()] for cam in f}


def test_dynamic_presets_add_scenes_and_leave_the_others_static():
    dynamic = ("dynamic-tiny", "dynamic", "random-dynamic", "random-dynamic-tiny")
    for name in dynamic + ("corner-dynamic", "corner-dynamic-tiny"):
        p = PRESETS[name]
        assert (p.scene_set, p.sheet_frames) == ("dynamic", FRAMES)
    assert (PRESETS["dynamic-tiny"].width, PRESETS["dynamic"].width) == (160, 640)
    assert PRESETS["random-dynamic"].randomised and not PRESETS["dynamic"].randomised
    for size in ("", "-tiny"):  # the corner rigs, at the random presets' sizes
        corner, static = PRESETS[f"corner-dynamic{size}"], PRESETS[f"corner{size}"]
        assert (corner.random_ranges, corner.width) == (static.random_ranges, static.width)
    others = [p for n, p in PRESETS.items() if "dynamic" not in n]
    assert {p.scene_set for p in others} == {"static"}
    with pytest.raises(ValueError, match="unknown scenes \\['toy'\\]"):
        synthesise("/nonexistent", "dynamic-tiny", selection=RenderSelection(scenes=("toy",)))


@pytest.mark.slow
def test_sequences_validate(dynamic_tiny):
    root = dynamic_tiny
    summary = validate(root)
    chromatic_frames = {"moving-toy": "000000", "cloth": "000000", "turning-metal": "000005"}
    for name in SEQUENCES:
        s = summary["scenes"][name]
        assert (s["frames"], s["dynamic"], s["chromatic"]) == (FRAMES, True, name)
        assert s["chromatic_frame"] == chromatic_frames[name]
        assert s["masks"] and s["ground_truth"]
        names = sorted(p.stem for p in (root / "scenes" / name / "gt" / "chromaticity").iterdir())
        assert names == _frame_names()
    assert summary["scenes"]["plane"]["chromatic_frame"] is None
    assert set(summary["scenes"]) == {"plane", *SEQUENCES}
    ds = open_dataset(root)
    assert set(ds.chromatic_objects) == {"white", *SEQUENCES}
    assert ds.scene("turning-metal").chromatic_frame == "000005"
    assert ds.scene("plane").chromatic_frame == "000000"
    assert ds.gt_mesh("cloth", 11).is_file()


@pytest.mark.slow
def test_rigid_meshes_move_by_the_stated_motion(dynamic_tiny):
    root = dynamic_tiny
    cases = {
        "moving-toy": (dyn.TOY_MOTION_AXIS, 20.0, np.array([-0.025, 0.012, 0.02])),
        "turning-metal": (None, 90.0, np.zeros(3)),
    }
    for name, (axis, angle, shift) in cases.items():
        motion = json.loads((root / "scenes" / name / "gt" / "motion.json").read_text())
        assert motion["angle_deg"] == angle
        np.testing.assert_allclose(motion["translation_m"], shift, atol=1e-12)
        if axis is not None:
            np.testing.assert_allclose(motion["axis"], np.array(axis) / np.linalg.norm(axis))
        centre, unit = np.array(motion["centre"]), np.array(motion["axis"])
        first = load_mesh(root / "scenes" / name / "gt" / "000000.ply")[0]
        for k, frame in enumerate(_frame_names()):
            s = k / (FRAMES - 1)
            R = axis_angle(unit, np.deg2rad(angle * s))
            expected = (first - centre) @ R.T + centre + s * shift
            moved = load_mesh(root / "scenes" / name / "gt" / f"{frame}.ply")[0]
            assert np.abs(moved - expected).max() < 1e-6  # metres (float32 PLY)
            pose = motion["frames"][frame]
            stated = first @ np.array(pose["R"]).T + pose["t"]
            assert np.abs(moved - stated).max() < 1e-6
        # The last frame against the first: a rotation by ``angle`` (from the meshes).
        last = moved - moved.mean(0)
        u, _, vt = np.linalg.svd((first - first.mean(0)).T @ last)
        Rk = (u @ vt).T
        turned = np.rad2deg(np.arccos((np.trace(Rk) - 1) / 2))
        assert abs(turned - angle) < 1e-3
    toy_shift = np.linalg.norm(cases["moving-toy"][2])
    assert 0.02 <= toy_shift <= 0.05 and abs(toy_shift - 0.034191) < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("scene", SEQUENCES)
def test_a_surface_point_keeps_its_chromaticity(dynamic_tiny, scene):
    """Follow one surface point (one vertex of every frame's mesh) into every camera:
    its pixel's true chromaticity is the same in every frame, the colour of the point."""
    root = dynamic_tiny
    first = load_mesh(root / "scenes" / scene / "gt" / "000000.ply")[0]
    if scene == "moving-toy":  # an eye (the first frame is the toy's own frame)
        k = int(np.argmin(np.linalg.norm(first - TOY_EYE, axis=1)))
        p = np.full(3, 0.06)
    elif scene == "cloth":  # the centre of patch (column 3, row 2): red, diffuse
        k = (25 * 2 + 12) * 131 + 26 * 3 + 13
        p = np.array(dyn.CLOTH_COLOURS["red"])
    else:  # the middle of a copper stripe, 40 degrees above the equator (object frame)
        v = dyn.metal_shape()[0] / [1.0, 1.2, 1.0]
        up = np.deg2rad(40.0)
        k = int(np.argmax(v @ [0.0, -np.sin(up), -np.cos(up)] / np.linalg.norm(v, axis=1)))
        p = np.array(dyn.METALS["copper"])
    rig = load_rig(root / "rig.json")
    points, pixels = [], []
    for frame in _frame_names():
        x = load_mesh(root / "scenes" / scene / "gt" / f"{frame}.ply")[0][k]
        maps = _chroma(root, scene, frame)
        for cam in rig.cameras:
            u, v = project(x, cam.K, cam.dist, cam.R, cam.t)
            value = maps[cam.name][int(round(v)), int(round(u))]
            np.testing.assert_allclose(value, p / WHITE_ALBEDO, rtol=1e-6)
            pixels.append((u, v))
        points.append(x)
    moved = np.linalg.norm(np.array(points) - points[0], axis=1).max()
    assert moved > 0.02  # metres: the point moves, and its colour with it
    assert np.ptp(np.array(pixels)[:: len(rig.cameras)], axis=0).max() > 1.5  # pixels


def test_albedo_is_read_in_rest_coordinates():
    """Every sequence's reflectance at surface points (triangle centres) is the same in
    every frame, though the points move by centimetres."""
    for seq in dyn.fixed_sequences(FRAMES):
        g0 = seq.build(0)
        tri = np.arange(0, len(g0.triangles), 7)
        c0 = g0.vertices[g0.triangles[tri]].mean(1)
        p0 = g0.albedo(c0, tri)
        assert np.ptp(p0, axis=0).max() > 0.2  # several colours
        for f in (5, 11):
            g = seq.build(f)
            centres = g.vertices[g.triangles[tri]].mean(1)
            assert np.linalg.norm(centres - c0, axis=1).max() > 0.01  # metres
            np.testing.assert_allclose(g.albedo(centres, tri), p0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("preset", ["random-dynamic-tiny", "corner-dynamic-tiny"])
def test_random_dynamic_draw_moves_within_its_ranges(preset):
    p = PRESETS[preset]
    ranges = RANGES_BY_NAME[p.random_ranges]
    for seed in (0, 1):
        d = draw_random(seed, p.width, p.height, Nuisances(), ranges, sheet_frames=FRAMES)
        seqs = dyn.random_sequences(seed, d.rig, d.description["scenes"], ranges, FRAMES, 5)
        toy, cloth, metal = seqs
        shift = np.linalg.norm(toy.motion.translation_m)
        assert 0.02 <= shift <= 0.05 and 10 <= toy.motion.angle_deg <= 30
        assert 45 <= abs(metal.motion.angle_deg) <= 90 and metal.chromatic_frame == 5
        assert not np.any(metal.motion.translation_m)
        for seq in seqs:
            for f in (0, FRAMES - 1):
                assert in_view(d.rig, seq.build(f).vertices, ranges.margin_px)
        again = dyn.random_sequences(seed, d.rig, d.description["scenes"], ranges, FRAMES, 5)
        assert again[0].draw == toy.draw and again[2].draw == metal.draw


# ------------------------------------------------------------------ scene.json chromatic_frame
def test_chromatic_frame_defaults_to_the_first_frame(tmp_path):
    root = make_dataset(tmp_path / "d")
    ds = open_dataset(root)
    assert ds.scene("toy").chromatic_frame == "000000"
    assert ds.scene("wave").chromatic_frame == "000000"
    shutil.rmtree(root / "scenes" / "wave" / "frames" / "000000")
    assert open_dataset(root).scene("wave").chromatic_frame == "000001"


@pytest.mark.parametrize("value", ["000001", 1])
def test_chromatic_frame_is_read(tmp_path, value):
    root = make_dataset(tmp_path / "d")
    scene_json = root / "scenes" / "wave" / "scene.json"
    edit_json(scene_json, lambda doc: doc.update(chromatic="slinky", chromatic_frame=value))
    assert open_dataset(root).scene("wave").chromatic_frame == "000001"
    assert validate(root)["scenes"]["wave"]["chromatic_frame"] == "000001"


@pytest.mark.parametrize(
    ("value", "phrase"),
    [
        ("000002", "chromatic_frame 000002 is not a frame of the scene (frames/ holds 2: "),
        (7, "chromatic_frame 000007 is not a frame of the scene"),
        ("2", 'chromatic_frame must be a 6-digit frame name or a frame index, got "2"'),
        (-1, "chromatic_frame must be a 6-digit frame name or a frame index, got -1"),
        (True, "chromatic_frame must be a 6-digit frame name or a frame index, got true"),
    ],
)
def test_a_wrong_chromatic_frame_names_scene_json(tmp_path, value, phrase):
    root = make_dataset(tmp_path / "d")
    scene_json = root / "scenes" / "wave" / "scene.json"
    edit_json(scene_json, lambda doc: doc.update(chromatic_frame=value))
    with raises(scene_json, phrase):
        open_dataset(root)
    with pytest.raises(CaptureFormatError, match="chromatic_frame"):
        validate(root)


@pytest.mark.slow
def test_rendered_scene_without_chromatic_frame_reads_its_first(dynamic_tiny, tmp_path):
    root = tmp_path / "copy"
    shutil.copytree(dynamic_tiny, root)
    scene_json = root / "scenes" / "turning-metal" / "scene.json"
    edit_json(scene_json, lambda doc: doc.update(chromatic_frame=None))
    assert open_dataset(root, check_images=False).scene("turning-metal").chromatic_frame == "000000"
    edit_json(scene_json, lambda doc: doc.pop("chromatic_frame") and None)
    assert open_dataset(root, check_images=False).scene("turning-metal").chromatic_frame == "000000"


def test_a_frame_selection_keeps_the_chromatic_frame(tmp_path):
    """Some frames of a sequence: those, and the frame its chromatic captures show."""
    selection = RenderSelection(
        parts=("chromatic", "scenes"), scenes=("turning-metal",), frames=[0]
    )
    root = synthesise(tmp_path / "d", "dynamic-tiny", selection=selection, workers=2)
    scene = root / "scenes" / "turning-metal"
    assert sorted(p.name for p in (scene / "frames").iterdir()) == ["000000", "000005"]
    assert sorted(p.name for p in (scene / "gt" / "chromaticity").iterdir()) == [
        "000000.h5",
        "000005.h5",
    ]
    assert json.loads((scene / "scene.json").read_text())["chromatic_frame"] == "000005"
    motion = json.loads((scene / "gt" / "motion.json").read_text())
    assert sorted(motion["frames"]) == _frame_names()
    assert (root / "chromatic" / "turning-metal" / "blue").is_dir()
    assert not (root / "scenes" / "cloth").exists()
    with pytest.raises(ValueError, match="frames \\[12\\]: the dynamic-tiny preset's sequences"):
        synthesise(tmp_path / "e", "dynamic-tiny", selection=RenderSelection(frames=[12]))
