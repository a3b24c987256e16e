"""Tests of colourhs.capture: reading images and masks, and image violations found by
open_dataset."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from capture_helpers import HEIGHT, WIDTH, raises, test_image, write_png

from colourhs.capture import ImageSpec, open_dataset, read_image, read_mask

# --------------------------------------------------------------------------------------------
# Reading images and masks


def test_read_image_values(tmp_path: Path) -> None:
    spec = ImageSpec(WIDTH, HEIGHT, 16, black_level=1024, white_level=60000)
    raw = np.full((HEIGHT, WIDTH, 3), 1024, np.uint16)
    raw[0, 0] = (1024, 30512, 60000)  # R at black, G mid scale, B at white (saturated)
    raw[0, 1] = (0, 65535, 2048)  # below black (clipped to 0), above white (1, saturated)
    raw[0, 2] = (59999, 1024, 1024)  # just below white: not saturated
    write_png(tmp_path / "cam1.png", raw)
    image, saturated = read_image(tmp_path / "cam1.png", spec)
    assert image.shape == (HEIGHT, WIDTH, 3) and image.dtype == np.float32
    assert saturated.shape == (HEIGHT, WIDTH) and saturated.dtype == bool
    np.testing.assert_allclose(image[0, 0], [0.0, 0.5, 1.0])
    np.testing.assert_allclose(image[0, 1], [0.0, 1.0, 1024 / 58976], rtol=1e-6)
    np.testing.assert_allclose(image[0, 2], [58975 / 58976, 0.0, 0.0], rtol=1e-6)
    assert saturated[0, 0] and saturated[0, 1] and not saturated[0, 2]
    assert saturated.sum() == 2
    assert np.all(image[1:] == 0.0)


def test_read_mask_one_and_three_channels(tmp_path: Path) -> None:
    spec = ImageSpec(WIDTH, HEIGHT, 16, 0, 65535)
    grey = np.zeros((HEIGHT, WIDTH), np.uint8)
    grey[2:5, 3:9] = 255
    colour = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    colour[2:5, 3:9, 1] = 1  # non-zero in one channel only
    write_png(tmp_path / "grey.png", grey)
    write_png(tmp_path / "colour.png", colour)
    for name in ("grey.png", "colour.png"):
        mask = read_mask(tmp_path / name, spec)
        assert mask.dtype == bool and mask.shape == (HEIGHT, WIDTH)
        np.testing.assert_array_equal(mask, grey != 0)


SPEC16 = ImageSpec(WIDTH, HEIGHT, 16, 0, 65535)


@pytest.mark.parametrize(
    ("content", "phrase"),
    [
        (None, "image file not found"),
        (b"not a png at all", "unreadable PNG"),
        (np.zeros((HEIGHT, WIDTH), np.uint16), "1 channel(s) (greyscale PNG), expected 3"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint16), "4 channel(s) (RGBA PNG), expected 3"),
        (np.zeros((HEIGHT, WIDTH, 3), np.uint8), "wrong bit depth: 8-bit PNG, expected 16-bit"),
        (np.zeros((HEIGHT, 31, 3), np.uint16), "found 31x24, expected 32x24"),
    ],
    ids=["missing", "not-png", "grey", "rgba", "bit-depth", "size"],
)
def test_read_image_refuses(tmp_path: Path, content: Any, phrase: str) -> None:
    path = tmp_path / "cam1.png"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        write_png(path, content)
    with raises(path, phrase):
        read_image(path, SPEC16)


def test_read_image_refuses_truncated_png(tmp_path: Path) -> None:
    path = tmp_path / "cam1.png"
    write_png(path, test_image())
    path.write_bytes(path.read_bytes()[:60])  # header intact, pixel data cut
    with raises(path, "unreadable PNG"):
        read_image(path, SPEC16)


@pytest.mark.parametrize(
    ("content", "phrase"),
    [
        (None, "mask file not found"),
        (np.zeros((HEIGHT, WIDTH), np.uint16), "wrong bit depth: 16-bit PNG, expected 8-bit"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint8), "4 channel(s) (RGBA PNG), expected 1 or 3"),
        (np.zeros((10, WIDTH), np.uint8), "found 32x10, expected 32x24"),
    ],
    ids=["missing", "bit-depth", "rgba", "size"],
)
def test_read_mask_refuses(tmp_path: Path, content: Any, phrase: str) -> None:
    path = tmp_path / "mask.png"
    if content is not None:
        write_png(path, content)
    with raises(path, phrase):
        read_mask(path, SPEC16)


# --------------------------------------------------------------------------------------------
# Image violations found by open_dataset


def overwrite(rel: str, content: np.ndarray | bytes) -> Callable[[Path], None]:
    def change(root: Path) -> None:
        if isinstance(content, bytes):
            (root / rel).write_bytes(content)
        else:
            write_png(root / rel, content)

    return change


RGB16 = np.zeros((HEIGHT, WIDTH, 3), np.uint16)

IMAGE_CASES = {
    "size": (
        "photometric/pose_b/cam1.png",
        np.zeros((HEIGHT, 16, 3), np.uint16),
        "wrong image size: found 16x24, expected 32x24 (width x height)",
    ),
    "size-chromatic": (
        "chromatic/slinky/red/cam2.png",
        np.zeros((HEIGHT + 1, WIDTH, 3), np.uint16),
        "found 32x25, expected 32x24",
    ),
    "bit-depth": (
        "scenes/wave/frames/000001/cam2.png",
        RGB16.astype(np.uint8),
        "wrong bit depth: 8-bit PNG, expected 16-bit",
    ),
    "not-png": ("photometric/pose_a/cam3.png", b"\xff\xd8\xff\xe0 JFIF", "unreadable PNG"),
    "empty-file": ("chromatic/white/blue/cam1.png", b"", "unreadable PNG"),
    "grey": (
        "scenes/toy/frames/000000/cam1.png",
        RGB16[..., 0],
        "wrong channels: 1 channel(s) (greyscale PNG), expected 3",
    ),
    "rgba": (
        "photometric/pose_c/cam2.png",
        np.zeros((HEIGHT, WIDTH, 4), np.uint16),
        "4 channel(s) (RGBA PNG), expected 3",
    ),
    "mask-16-bit": (
        "scenes/toy/masks/000000/cam1.png",
        RGB16[..., 0],
        "wrong bit depth: 16-bit PNG, expected 8-bit",
    ),
    "mask-size": (
        "scenes/toy/masks/000000/cam3.png",
        np.zeros((HEIGHT, WIDTH + 2), np.uint8),
        "found 34x24, expected 32x24",
    ),
    "mask-not-png": ("scenes/toy/masks/000000/cam3.png", b"mask", "unreadable PNG"),
}


@pytest.mark.parametrize(("rel", "content", "phrase"), IMAGE_CASES.values(), ids=IMAGE_CASES.keys())
def test_image_violation(root: Path, rel: str, content: Any, phrase: str) -> None:
    overwrite(rel, content)(root)
    open_dataset(root, check_images=False)  # the layout itself is fine
    with raises(root / rel, phrase) as info:
        open_dataset(root)
    assert info.value.path == root / rel


def test_corrupt_png_header_is_unreadable(root: Path) -> None:
    path = root / "photometric" / "pose_a" / "cam1.png"
    data = bytearray(path.read_bytes())
    data[17] ^= 0xFF  # flip a byte of the IHDR width: its CRC no longer matches
    path.write_bytes(bytes(data))
    with raises(path, "unreadable PNG: corrupt IHDR chunk"):
        open_dataset(root)
