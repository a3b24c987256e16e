"""Builders of a small valid capture-format dataset, shared by the capture tests
(tests/capture/) and the workflow plan tests."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from colourhs.capture import COLOURS, CaptureFormatError

WIDTH, HEIGHT = 32, 24
CAMERAS = (("cam1", "blue"), ("cam2", "red"), ("cam3", "green"))
LEVELS = {16: (1024, 60000), 8: (16, 250)}
POSES = ("pose_a", "pose_b", "pose_c")

# --------------------------------------------------------------------------------------------
# Building a small valid dataset


def rot_y(degrees: float) -> np.ndarray:
    """Rotation about the y axis."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def pinhole(f: float, cx: float, cy: float):
    """A camera at the origin looking along +z without distortion (``K``, ``dist``,
    ``R``, ``t``, as the ray casting and projection read them); f, cx, cy in pixels."""
    from types import SimpleNamespace

    K = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    return SimpleNamespace(K=K, dist=np.zeros(5), R=np.eye(3), t=np.zeros(3))


def rig_dict(bit_depth: int = 16) -> dict[str, Any]:
    """A valid rig.json document: cam1 at the world origin's -z side, cam2/cam3 turned by ±20°."""
    black, white = LEVELS[bit_depth]
    angles = (0.0, 20.0, -20.0)
    cameras = []
    for (name, colour), angle in zip(CAMERAS, angles, strict=True):
        cameras.append(
            {
                "name": name,
                "K": [[40.0, 0.0, 15.5], [0.0, 40.0, 11.5], [0.0, 0.0, 1.0]],
                "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
                "R": rot_y(angle).tolist(),
                "t": [0.0 if angle == 0 else 0.01, 0.0, 0.8],
                "light": {"colour": colour, "offset": [0.0, 0.0, 0.0]},
            }
        )
    cameras[2]["light"]["offset"] = [0.05, -0.02, 0.0]
    return {
        "format": "colourhs-capture/1",
        "units": "m",
        "image": {
            "width": WIDTH,
            "height": HEIGHT,
            "bit_depth": bit_depth,
            "black_level": black,
            "white_level": white,
        },
        "cameras": cameras,
        "board": {
            "dictionary": "DICT_4X4_50",
            "marker_length": 0.04,
            "size": [0.30, 0.22],
            "markers": {"0": [0.03, 0.03], "1": [0.27, 0.03], "2": [0.27, 0.19], "3": [0.03, 0.19]},
        },
        "chromatic_light": {"position": [0.0, -0.3, -0.6]},
    }


def write_png(path: Path, rgb: np.ndarray) -> None:
    """Write an RGB(A) or single-channel image as PNG (cv2 wants B, G, R order)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if rgb.ndim == 3 and rgb.shape[2] == 3:
        pixels = rgb[..., ::-1]
    elif rgb.ndim == 3 and rgb.shape[2] == 4:
        pixels = rgb[..., [2, 1, 0, 3]]
    else:
        pixels = rgb
    assert cv2.imwrite(str(path), np.ascontiguousarray(pixels))


def test_image(bit_depth: int = 16, seed: int = 0) -> np.ndarray:
    """Random raw RGB values between the black and white levels."""
    black, white = LEVELS[bit_depth]
    dtype = np.uint16 if bit_depth == 16 else np.uint8
    rng = np.random.default_rng(seed)
    return rng.integers(black, white, size=(HEIGHT, WIDTH, 3)).astype(dtype)


test_image.__test__ = False  # a helper, not a test


def write_camera_images(folder: Path, bit_depth: int) -> None:
    for i, (name, _) in enumerate(CAMERAS):
        write_png(folder / f"{name}.png", test_image(bit_depth, seed=i))


def write_json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))


def make_dataset(root: Path, bit_depth: int = 16) -> Path:
    """Write a small valid dataset: 3 poses, chromatic white + slinky, scenes toy and wave."""
    write_json(root / "rig.json", rig_dict(bit_depth))
    for pose in POSES:
        write_camera_images(root / "photometric" / pose, bit_depth)
    for obj in ("white", "slinky"):
        for colour in COLOURS:
            write_camera_images(root / "chromatic" / obj / colour, bit_depth)
    toy = root / "scenes" / "toy"
    write_json(toy / "scene.json", {"chromatic": "slinky", "dynamic": False, "description": "toy"})
    write_camera_images(toy / "frames" / "000000", bit_depth)
    mask = np.zeros((HEIGHT, WIDTH), np.uint8)
    mask[5:15, 8:20] = 255
    for name, _ in CAMERAS:
        write_png(toy / "masks" / "000000" / f"{name}.png", mask)
    (toy / "gt").mkdir()
    (toy / "gt" / "000000.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    wave = root / "scenes" / "wave"
    write_json(wave / "scene.json", {"dynamic": True})
    for frame in ("000000", "000001"):
        write_camera_images(wave / "frames" / frame, bit_depth)
    (root / "notes.txt").write_text("extra files are ignored\n")
    return root


def add_geometric(root: Path, poses=("p0", "p1")) -> Path:
    """Give a :func:`make_dataset` folder ``geometric/<pose>/`` views (copies of its first
    board pose's images) and rig.json a ``geometric_board``: the layout of the
    geometric captures, not a calibratable set."""
    from colourhs.capture.targets import charuco_layout

    for pose in poses:
        shutil.copytree(root / "photometric" / POSES[0], root / "geometric" / pose)
    board = charuco_layout(7, 5, 0.04, 0.03, "DICT_4X4_50")
    edit_json(root / "rig.json", lambda rig: rig.update(geometric_board=board))
    return root


def edit_json(path: Path, change: Callable[[Any], Any]) -> None:
    """Apply ``change`` to a JSON document in place (its return value, if any, replaces it)."""
    data = json.loads(path.read_text())
    result = change(data)
    write_json(path, data if result is None else result)


def raises(path: Path, phrase: str) -> Any:
    """Expect a CaptureFormatError whose message is ``<path>: ...phrase...``."""
    return pytest.raises(
        CaptureFormatError, match=re.escape(f"{path}: ") + ".*" + re.escape(phrase)
    )


def delete(*keys: str | int) -> Callable[[Any], None]:
    """A change that removes ``doc[k0][k1]...[kn]``."""

    def change(doc: Any) -> None:
        for key in keys[:-1]:
            doc = doc[key]
        del doc[keys[-1]]

    return change


def assign(*keys: str | int, value: Any) -> Callable[[Any], None]:
    """A change that sets ``doc[k0][k1]...[kn] = value``."""

    def change(doc: Any) -> None:
        for key in keys[:-1]:
            doc = doc[key]
        doc[keys[-1]] = value

    return change


def render_exact(root, preset, seed: int, scenes, parts=("photometric", "scenes"), frames=None):
    """:func:`colourhs.synth.synthesise.synthesise_exact` of ``scenes`` (and ``frames``
    of a sequence) with ``parts``, two rendering processes."""
    from colourhs.synth.synthesise import RenderSelection, synthesise_exact

    selection = RenderSelection(parts=parts, scenes=scenes, frames=frames)
    return synthesise_exact(root, preset, seed, selection, workers=2)
