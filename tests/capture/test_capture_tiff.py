"""Tests of colourhs.capture: TIFF capture images (``<camera>.tif`` or ``.tiff``), read
and checked as PNG ones are, and the file names a capture may have."""

from __future__ import annotations

import shutil
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from capture_helpers import HEIGHT, WIDTH, make_dataset, raises, test_image, write_png

from colourhs.capture import (
    CaptureFormatProblems,
    ImageSpec,
    all_images,
    open_dataset,
    read_image,
    read_mask,
    validate,
)
from colourhs.capture.base import _ImageHeader
from colourhs.capture.tiff import parse_tiff_header

SPEC16 = ImageSpec(WIDTH, HEIGHT, 16, 0, 65535)
SPEC8 = ImageSpec(WIDTH, HEIGHT, 8, 0, 255)


def write_image(path: Path, pixels: np.ndarray) -> None:
    """Write R, G, B (or grey) pixels in the format of ``path``'s suffix (cv2 picks it)."""
    write_png(path, pixels)


def as_tiff(root: Path, suffix: Callable[[Path], str | None]) -> None:
    """Rewrite each PNG of the dataset at ``root`` as a TIFF of the same pixels, under
    the suffix ``suffix(png)`` gives (None: keep the PNG)."""
    for png in sorted(root.rglob("*.png")):
        new = suffix(png.relative_to(root))
        if new is None:
            continue
        pixels = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        assert cv2.imwrite(str(png.with_suffix(new)), pixels)
        png.unlink()


def mixed_suffix(rel: Path) -> str | None:
    """A dataset of every kind: pose_a stays PNG, chromatic captures become ``.tiff``,
    everything else (poses, frames, masks) ``.tif``."""
    if rel.parts[:2] == ("photometric", "pose_a"):
        return None
    return ".tiff" if rel.parts[0] == "chromatic" else ".tif"


def tiff_file(
    tags: dict[int, tuple[int, ...]], order: str = "<", big: bool = False, next_ifd: int = 0
) -> bytes:
    """The header and first directory of a TIFF holding ``tags`` (SHORT values), no pixels.

    Classic TIFF or BigTIFF, little (``"<"``) or big (``">"``) endian: what a camera's
    writer may produce, for what OpenCV does not write.
    """
    count_fmt, offset_fmt, inline = ("Q", "Q", 8) if big else ("H", "I", 4)
    head = (b"II" if order == "<" else b"MM") + struct.pack(order + "H", 43 if big else 42)
    head += struct.pack(order + "HHQ", 8, 0, 16) if big else struct.pack(order + "I", 8)
    entry_size = 4 + 2 * inline
    extra_at = len(head) + struct.calcsize(count_fmt) + len(tags) * entry_size + inline
    entries, extra = b"", b""
    for tag in sorted(tags):
        data = struct.pack(f"{order}{len(tags[tag])}H", *tags[tag])
        if len(data) <= inline:
            field = data.ljust(inline, b"\0")
        else:
            field = struct.pack(order + offset_fmt, extra_at + len(extra))
            extra += data
        entries += struct.pack(order + "HH" + offset_fmt, tag, 3, len(tags[tag])) + field
    ifd = struct.pack(order + count_fmt, len(tags)) + entries
    return head + ifd + struct.pack(order + offset_fmt, next_ifd) + extra


#: A 16-bit RGB image of the test size: width, height, bits, photometric RGB, 3 samples.
RGB16_TAGS = {256: (WIDTH,), 257: (HEIGHT,), 258: (16, 16, 16), 262: (2,), 277: (3,)}


def tags(**changes: tuple[int, ...] | None) -> dict[int, tuple[int, ...]]:
    """:data:`RGB16_TAGS` with tags set or removed (None), by name ``t<number>``."""
    out: dict[int, tuple[int, ...] | None] = {**RGB16_TAGS}
    for name, value in changes.items():
        out[int(name[1:])] = value
    return {tag: value for tag, value in out.items() if value is not None}


def parse(data: bytes, path: Path = Path("cam1.tif")) -> _ImageHeader:
    return parse_tiff_header(path, lambda offset, size: data[offset : offset + size])


# --------------------------------------------------------------------------------------------
# A TIFF dataset reads as the PNG one


@pytest.mark.parametrize("bit_depth", [8, 16])
def test_tiff_dataset_reads_exactly_as_the_png_one(tmp_path: Path, bit_depth: int) -> None:
    """The same pixels as TIFF (8 and 16 bit, mixed with PNG, ``.tif`` and ``.tiff``,
    masks too) validate and decode to bit-identical images, saturation and masks."""
    png_root = make_dataset(tmp_path / "png", bit_depth)
    tif_root = Path(shutil.copytree(png_root, tmp_path / "tif"))
    as_tiff(tif_root, mixed_suffix)
    png_ds, tif_ds = open_dataset(png_root), open_dataset(tif_root)
    assert (tif_ds.poses, tif_ds.chromatic_objects) == (png_ds.poses, png_ds.chromatic_objects)
    assert tif_ds.scenes == png_ds.scenes
    assert validate(tif_root)["images"] == validate(png_root)["images"]
    png_paths, tif_paths = all_images(png_ds), all_images(tif_ds)
    assert {p.suffix for p in tif_paths} == {".png", ".tif", ".tiff"}
    assert [p.relative_to(png_root).with_suffix("") for p in png_paths] == [
        p.relative_to(tif_root).with_suffix("") for p in tif_paths
    ]
    masks = {p for p in png_paths if "masks" in p.parts}
    assert masks
    for png, tif in zip(png_paths, tif_paths, strict=True):
        if png in masks:
            np.testing.assert_array_equal(
                read_mask(tif, tif_ds.rig.image), read_mask(png, png_ds.rig.image)
            )
            continue
        (image, saturated), (expected, expected_saturated) = (
            read_image(tif, tif_ds.rig.image),
            read_image(png, png_ds.rig.image),
        )
        assert image.dtype == expected.dtype and np.array_equal(image, expected), tif
        assert np.array_equal(saturated, expected_saturated), tif


def test_dataset_paths_name_the_tiff_files(root: Path) -> None:
    """Every accessor resolves a capture's file, whatever its format: frames of a
    TIFF scene are listed and their paths are the ``.tif`` files."""
    as_tiff(root, lambda rel: ".tif" if rel.parts[:3] == ("scenes", "wave", "frames") else None)
    data = open_dataset(root)
    assert data.scenes["wave"].frames == ("000000", "000001")
    assert data.frame_image("wave", 1, "cam2") == root / "scenes/wave/frames/000001/cam2.tif"
    assert data.frame_image("toy", 0, "cam2") == root / "scenes/toy/frames/000000/cam2.png"
    image, _ = read_image(data.frame_image("wave", 0, "cam1"), data.rig.image)
    raw = test_image(16, seed=0).astype(np.float32)
    np.testing.assert_allclose(image, (raw - 1024) / (60000 - 1024), rtol=1e-6)


# --------------------------------------------------------------------------------------------
# The same checks as PNG


@pytest.mark.parametrize(
    ("pixels", "phrase"),
    [
        (np.zeros((HEIGHT, WIDTH), np.uint16), "wrong channels: 1 channel(s) (greyscale TIFF)"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint16), "4 channel(s) (RGBA TIFF), expected 3"),
        (np.zeros((HEIGHT, WIDTH, 3), np.uint8), "wrong bit depth: 8-bit TIFF, expected 16-bit"),
        (
            np.zeros((HEIGHT, WIDTH, 3), np.float32),
            "wrong sample format: 32-bit floating-point TIFF, expected unsigned 16-bit integers",
        ),
        (
            np.zeros((HEIGHT, WIDTH, 3), np.int32),
            "wrong sample format: 32-bit signed TIFF, expected unsigned 16-bit",
        ),
        (np.zeros((HEIGHT, 31, 3), np.uint16), "wrong image size: found 31x24, expected 32x24"),
    ],
    ids=["grey", "rgba", "8-bit", "float", "int32", "size"],
)
def test_read_image_refuses_tiff(tmp_path: Path, pixels: np.ndarray, phrase: str) -> None:
    path = tmp_path / "cam1.tif"
    write_image(path, pixels)
    with raises(path, phrase):
        read_image(path, SPEC16)


def test_sixteen_bit_tiff_in_an_eight_bit_rig(tmp_path: Path) -> None:
    """The error names the file and both depths, at open and at read."""
    root = make_dataset(tmp_path / "d8", bit_depth=8)
    path = root / "photometric" / "pose_b" / "cam2.tif"
    (root / "photometric" / "pose_b" / "cam2.png").unlink()
    write_image(path, test_image(16))
    with raises(path, "wrong bit depth: 16-bit TIFF, expected 8-bit") as info:
        open_dataset(root)
    assert info.value.path == path
    with raises(path, "wrong bit depth: 16-bit TIFF, expected 8-bit"):
        read_image(path, SPEC8)


def test_read_image_refuses_a_multi_page_tiff(tmp_path: Path) -> None:
    path = tmp_path / "cam1.tif"
    assert cv2.imwritemulti(str(path), [test_image(16), test_image(16, seed=1)])
    with raises(path, "unsupported TIFF: more than one image (multi-page TIFF)"):
        read_image(path, SPEC16)


@pytest.mark.parametrize(
    ("pixels", "phrase"),
    [
        (np.zeros((HEIGHT, WIDTH), np.uint16), "wrong bit depth: 16-bit TIFF, expected 8-bit"),
        (np.zeros((HEIGHT, WIDTH, 4), np.uint8), "4 channel(s) (RGBA TIFF), expected 1 or 3"),
        (np.zeros((10, WIDTH), np.uint8), "found 32x10, expected 32x24"),
    ],
    ids=["16-bit", "rgba", "size"],
)
def test_read_mask_refuses_tiff(tmp_path: Path, pixels: np.ndarray, phrase: str) -> None:
    path = tmp_path / "cam1.tiff"
    write_image(path, pixels)
    with raises(path, phrase):
        read_mask(path, SPEC16)


def test_read_mask_one_and_three_channel_tiffs(tmp_path: Path) -> None:
    grey = np.zeros((HEIGHT, WIDTH), np.uint8)
    grey[2:5, 3:9] = 255
    colour = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    colour[2:5, 3:9, 2] = 1  # non-zero in one channel only
    for name, pixels in (("grey.tif", grey), ("colour.tiff", colour)):
        write_image(tmp_path / name, pixels)
        np.testing.assert_array_equal(read_mask(tmp_path / name, SPEC16), grey != 0)


@pytest.mark.parametrize(
    ("name", "content", "phrase"),
    [
        ("cam1.tif", "png", "unreadable TIFF: the file holds PNG data; name it cam1.png"),
        ("cam1.png", "tif", "unreadable PNG: the file holds TIFF data; name it cam1.tif"),
        ("cam1.tif", b"not a tiff", "unreadable TIFF: not a TIFF file"),
        ("cam1.tiff", b"", "unreadable TIFF: not a TIFF file"),
        ("cam1.jpg", "png", "not an image file name: expected a suffix .png, .tif, .tiff"),
    ],
    ids=["png-as-tif", "tif-as-png", "not-tiff", "empty", "jpg"],
)
def test_the_suffix_names_the_format(tmp_path: Path, name: str, content: Any, phrase: str) -> None:
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        write_image(tmp_path / f"data.{content}", test_image(16))
        (tmp_path / f"data.{content}").rename(path)
    with raises(path, phrase):
        read_image(path, SPEC16)


def test_read_image_refuses_a_truncated_tiff(tmp_path: Path) -> None:
    path = tmp_path / "cam1.tif"
    write_image(path, test_image(16))
    path.write_bytes(path.read_bytes()[:6])
    with raises(path, "unreadable TIFF: truncated header"):
        read_image(path, SPEC16)


# --------------------------------------------------------------------------------------------
# TIFF headers OpenCV does not write


@pytest.mark.parametrize("big", [False, True], ids=["classic", "bigtiff"])
@pytest.mark.parametrize("order", ["<", ">"], ids=["little-endian", "big-endian"])
def test_tiff_header_byte_orders_and_bigtiff(order: str, big: bool) -> None:
    header = parse(tiff_file(RGB16_TAGS, order, big))
    assert header == _ImageHeader(WIDTH, HEIGHT, 16, 3, "RGB", "TIFF", "unsigned")


@pytest.mark.parametrize(
    "options",
    [
        {"tile": (16, 16)},
        {"bigtiff": True},
        {"byteorder": ">"},
        {"compression": "zlib", "rowsperstrip": 5},
    ],
    ids=["tiled", "bigtiff", "big-endian", "deflate-strips"],
)
@pytest.mark.parametrize("bit_depth", [8, 16])
def test_tiffs_of_other_writers_read_exactly(
    tmp_path: Path, bit_depth: int, options: dict[str, Any]
) -> None:
    """Layouts a camera's software may write and OpenCV does not (tifffile writes them
    here): the same values as the PNG of the same pixels."""
    tifffile = pytest.importorskip("tifffile")
    spec = ImageSpec(WIDTH, HEIGHT, bit_depth, 0, 2**bit_depth - 1)
    rgb = test_image(bit_depth)
    write_image(tmp_path / "cam1.png", rgb)
    tifffile.imwrite(tmp_path / "cam1.tif", rgb, photometric="rgb", **options)
    image, saturated = read_image(tmp_path / "cam1.tif", spec)
    expected, expected_saturated = read_image(tmp_path / "cam1.png", spec)
    assert np.array_equal(image, expected) and np.array_equal(saturated, expected_saturated)


def test_tiff_header_of_opencv_files(tmp_path: Path) -> None:
    for name, pixels, expected in (
        ("rgb16.tif", test_image(16), (WIDTH, HEIGHT, 16, 3, "RGB")),
        ("rgb8.tif", test_image(8), (WIDTH, HEIGHT, 8, 3, "RGB")),
        ("grey8.tif", test_image(8)[..., 0], (WIDTH, HEIGHT, 8, 1, "greyscale")),
    ):
        write_image(tmp_path / name, pixels)
        assert parse((tmp_path / name).read_bytes())[:5] == expected, name


@pytest.mark.parametrize(
    ("data", "phrase"),
    [
        (tiff_file(tags(t274=(3,))), "unsupported TIFF: orientation 3 (pixels stored rotated"),
        (tiff_file(tags(t259=(7,))), "unsupported TIFF: lossy JPEG compression"),
        (tiff_file(tags(t262=(32803,), t277=(1,), t258=(16,))), "raw Bayer mosaic"),
        (tiff_file(tags(t262=(6,))), "unsupported TIFF colour model: YCbCr with 3 sample(s)"),
        (tiff_file(tags(t284=(2,))), "unsupported TIFF: separate colour planes"),
        (tiff_file(tags(t262=None)), "unreadable TIFF: no PhotometricInterpretation tag"),
        (tiff_file(tags(t256=None)), "unreadable TIFF: no ImageWidth tag"),
        (tiff_file(RGB16_TAGS, next_ifd=8), "more than one image (multi-page TIFF)"),
        (tiff_file(tags(t258=(16, 16, 8))), "samples of different types (bits [8, 16])"),
        (tiff_file(RGB16_TAGS)[:40], "unreadable TIFF: truncated header"),
        (b"II*\0\0\0\0\0", "unreadable TIFF: image directory of 0 entries"),
    ],
    ids=[
        "orientation",
        "jpeg",
        "bayer",
        "ycbcr",
        "planar",
        "no-photometric",
        "no-width",
        "multi-page",
        "mixed-bits",
        "truncated",
        "no-directory",
    ],
)
def test_tiff_header_refuses(data: bytes, phrase: str) -> None:
    with raises(Path("cam1.tif"), phrase):
        parse(data)


def test_open_dataset_checks_tiff_headers(root: Path) -> None:
    """A 32-bit unsigned TIFF (which OpenCV does not write) is refused from its header."""
    frame = root / "scenes" / "toy" / "frames" / "000000"
    (frame / "cam3.png").unlink()
    (frame / "cam3.tif").write_bytes(tiff_file(tags(t258=(32, 32, 32))))
    with raises(frame / "cam3.tif", "wrong bit depth: 32-bit TIFF, expected 16-bit"):
        open_dataset(root)


# --------------------------------------------------------------------------------------------
# File names: one file per camera, hints at near misses


def test_png_and_tiff_of_one_camera_is_an_error_naming_both(root: Path) -> None:
    pose = root / "photometric" / "pose_a"
    write_image(pose / "cam1.tif", test_image(16))
    with raises(
        pose / "cam1.png",
        "2 images of camera 'cam1' (photometric pose pose_a): cam1.png and cam1.tif; keep one",
    ):
        open_dataset(root, check_images=False)


def test_validate_names_a_duplicate_among_other_problems(root: Path) -> None:
    """Every problem at once: the duplicate (a .tif beside a .tiff mask) and a near miss."""
    masks = root / "scenes" / "toy" / "masks" / "000000"
    as_tiff(root, lambda rel: ".tif" if rel.parts[:3] == ("scenes", "toy", "masks") else None)
    shutil.copy(masks / "cam2.tif", masks / "cam2.tiff")
    frame = root / "scenes" / "wave" / "frames" / "000001"
    (frame / "cam3.png").rename(frame / "cam3.TIFF")
    with pytest.raises(CaptureFormatProblems) as info:
        validate(root)
    problems = sorted(str(p) for p in info.value.problems)
    assert len(problems) == 2, problems
    assert problems[0].startswith(f"{masks / 'cam2.tif'}: 2 images of camera 'cam2'")
    assert "cam2.tif and cam2.tiff" in problems[0]
    assert problems[1].startswith(f"{frame / 'cam3.png'}: missing image of camera 'cam3'")


@pytest.mark.parametrize("near_miss", ["cam1.TIF", "cam1.TIFF", "cam1.PNG", "cam1.jpg", "CAM1.tif"])
def test_near_miss_names_the_expected_names(root: Path, near_miss: str) -> None:
    frame = root / "scenes" / "wave" / "frames" / "000000"
    (frame / "cam1.png").rename(frame / near_miss)
    with raises(
        frame / "cam1.png",
        f"missing image of camera 'cam1' (scene wave frame 000000); found {near_miss}: "
        "images are PNG or TIFF files named cam1.png, cam1.tif or cam1.tiff",
    ):
        open_dataset(root, check_images=False)


@pytest.mark.parametrize("suffix", [".tif", ".tiff"])
def test_a_tiff_is_no_near_miss(root: Path, suffix: str) -> None:
    """``cam1.tif`` is a capture, not a misnamed ``cam1.png``."""
    as_tiff(root, lambda rel: suffix if rel == Path("photometric/pose_c/cam1.png") else None)
    data = open_dataset(root)
    assert data.photometric_image("pose_c", "cam1") == root / f"photometric/pose_c/cam1{suffix}"
