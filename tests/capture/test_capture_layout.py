"""Tests of colourhs.capture: dataset layout violations (scenes, frames, chromatic
objects), each a one-line CaptureFormatError."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from capture_helpers import assign, edit_json, raises

from colourhs.capture import open_dataset

# --------------------------------------------------------------------------------------------
# Layout violations


def remove(rel: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        path = root / rel
        shutil.rmtree(path) if path.is_dir() else path.unlink()

    return change


def rename(rel: str, new_name: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).rename((root / rel).with_name(new_name))


def make_dir(rel: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).mkdir(parents=True)


def write_scene_json(rel: str, text: str) -> Callable[[Path], None]:
    return lambda root: (root / rel).write_text(text)


def edit_scene(rel: str, change: Callable[[Any], Any]) -> Callable[[Path], None]:
    return lambda root: edit_json(root / rel, change)


def copy_frame(scene: str, source: str, target: str) -> Callable[[Path], None]:
    frames = f"scenes/{scene}/frames"
    return lambda root: shutil.copytree(root / frames / source, root / frames / target)


def remove_all(*rels: str) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        for rel in rels:
            remove(rel)(root)

    return change


TOY_JSON = "scenes/toy/scene.json"

# id: (change, offending path relative to the dataset, phrase of the problem)
LAYOUT_CASES = {
    "no-photometric": (remove("photometric"), "photometric", "missing photometric/ folder"),
    "two-poses": (
        remove("photometric/pose_c"),
        "photometric",
        "found 2 poses, at least 3 are required",
    ),
    "pose-missing-camera": (
        remove("photometric/pose_b/cam2.png"),
        "photometric/pose_b/cam2.png",
        "missing image of camera 'cam2' (photometric pose pose_b)",
    ),
    "pose-name": (
        rename("photometric/pose_a", "pose a"),
        "photometric/pose a",
        "pose name 'pose a' has characters other than letters, digits",
    ),
    "white-missing-colour": (
        remove("chromatic/white/green"),
        "chromatic/white/green",
        "missing folder (chromatic white under green light)",
    ),
    "white-missing-camera": (
        remove("chromatic/white/red/cam3.png"),
        "chromatic/white/red/cam3.png",
        "missing image of camera 'cam3' (chromatic white under red light)",
    ),
    "no-white": (
        remove("chromatic/white"),
        "chromatic/white",
        "missing white reference folder",
    ),
    "object-missing-colour": (
        remove("chromatic/slinky/blue"),
        "chromatic/slinky/blue",
        "missing folder (chromatic slinky under blue light)",
    ),
    "object-missing-camera": (
        remove("chromatic/slinky/green/cam1.png"),
        "chromatic/slinky/green/cam1.png",
        "missing image of camera 'cam1'",
    ),
    "object-name": (
        rename("chromatic/slinky", "sl!nky"),
        "chromatic/sl!nky",
        "chromatic object name 'sl!nky' has characters",
    ),
    "no-chromatic-but-referenced": (
        remove("chromatic"),
        TOY_JSON,
        "chromatic object 'slinky' has no folder chromatic/slinky",
    ),
    "scene-json-unknown-object": (
        edit_scene(TOY_JSON, assign("chromatic", value="teapot")),
        TOY_JSON,
        "chromatic object 'teapot' has no folder chromatic/teapot",
    ),
    "scene-json-path-object": (
        edit_scene(TOY_JSON, assign("chromatic", value="../photometric")),
        TOY_JSON,
        "chromatic object '../photometric' has no folder",
    ),
    "scene-json-invalid": (
        write_scene_json(TOY_JSON, "{chromatic: slinky}"),
        TOY_JSON,
        "not valid JSON",
    ),
    "scene-json-list": (
        write_scene_json(TOY_JSON, "[]"),
        TOY_JSON,
        "scene.json must be a JSON object",
    ),
    "scene-json-dynamic-string": (
        edit_scene(TOY_JSON, assign("dynamic", value="no")),
        TOY_JSON,
        'dynamic must be true or false, got "no"',
    ),
    "scene-json-chromatic-number": (
        edit_scene(TOY_JSON, assign("chromatic", value=3)),
        TOY_JSON,
        "chromatic must be a string",
    ),
    "scene-json-description-number": (
        edit_scene(TOY_JSON, assign("description", value=5)),
        TOY_JSON,
        "description must be a string",
    ),
    "static-scene-two-frames": (
        copy_frame("toy", "000000", "000001"),
        TOY_JSON,
        "static scene (dynamic: false) must have the single frame 000000",
    ),
    "frame-name-short": (
        rename("scenes/wave/frames/000001", "1"),
        "scenes/wave/frames/1",
        "frame folder name '1' is not a 6-digit index",
    ),
    "frame-name-word": (
        rename("scenes/wave/frames/000001", "frame01"),
        "scenes/wave/frames/frame01",
        "is not a 6-digit index",
    ),
    "frame-name-long": (
        rename("scenes/wave/frames/000001", "0000001"),
        "scenes/wave/frames/0000001",
        "is not a 6-digit index",
    ),
    "frame-missing-camera": (
        remove("scenes/wave/frames/000001/cam3.png"),
        "scenes/wave/frames/000001/cam3.png",
        "missing image of camera 'cam3' (scene wave frame 000001)",
    ),
    "scene-no-frames": (
        remove_all("scenes/wave/frames/000000", "scenes/wave/frames/000001"),
        "scenes/wave/frames",
        "scene 'wave' has no frames",
    ),
    "scene-no-frames-folder": (
        remove("scenes/wave/frames"),
        "scenes/wave/frames",
        "scene 'wave' has no frames",
    ),
    "scene-name": (
        rename("scenes/wave", "wave.v2"),
        "scenes/wave.v2",
        "scene name 'wave.v2' has characters",
    ),
    "mask-missing-camera": (
        remove("scenes/toy/masks/000000/cam2.png"),
        "scenes/toy/masks/000000/cam2.png",
        "missing image of camera 'cam2' (mask of scene toy)",
    ),
    "mask-folder-missing-frame": (
        make_dir("scenes/wave/masks"),
        "scenes/wave/masks/000000",
        "missing folder (mask of scene wave)",
    ),
    "gt-missing-mesh": (
        make_dir("scenes/wave/gt"),
        "scenes/wave/gt/000000.ply",
        "missing ground-truth mesh of frame 000000",
    ),
}


@pytest.mark.parametrize(
    ("change", "rel", "phrase"), LAYOUT_CASES.values(), ids=LAYOUT_CASES.keys()
)
def test_layout_violation(root: Path, change: Callable[[Path], Any], rel: str, phrase: str) -> None:
    change(root)
    with raises(root / rel, phrase) as info:
        open_dataset(root, check_images=False)
    assert info.value.path == root / rel
