"""A whole dataset folder: :func:`open_dataset` checks its layout, :func:`validate` every image.

:func:`open_dataset` walks the layout the format specifies (rig.json,
``photometric/``, ``chromatic/``, ``scenes/`` with frames, masks, ground truth
and an optional scene.json) and returns a
:class:`~colourhs.capture.dataset.Dataset`; :func:`validate` also decodes every
image and summarises the dataset (the ``colourhs validate`` command).
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from colourhs.capture.base import _NAME, COLOURS, FORMAT, CaptureFormatError
from colourhs.capture.dataset import Dataset, Scene, _known
from colourhs.capture.jsonvalues import _as_object, _as_str, _read_json, _show
from colourhs.capture.png import (
    _check_image_header,
    _check_mask_header,
    _read_png_header,
    read_image,
    read_mask,
)
from colourhs.capture.rig import light_offset_warning, reciprocity_defect_deg
from colourhs.capture.rigjson import load_rig
from colourhs.common.progress import bar

_FRAME = re.compile(r"[0-9]{6}")
_STATIC_FRAME = "000000"


def open_dataset(
    root: str | Path, check_images: bool = True, scenes: Iterable[str] | None = None
) -> Dataset:
    """Validate a whole dataset folder and describe its contents.

    Parameters
    ----------
    root : str or Path
        The dataset folder (or its rig.json).
    check_images : bool
        Also check every listed PNG's header: valid PNG, channels, bit depth and size.
        Only headers are read (pixel data is decoded by :func:`read_image`).
    scenes : iterable of str, optional
        Read only these scenes' folders and scene.json (each must exist; an empty
        one reads none), so that a stage reads no file of the scenes it does not
        use (the workflow's rules declare what they read); default every scene.

    Returns
    -------
    Dataset

    Raises
    ------
    CaptureFormatError
        At the first violation of the format found, naming the file and the problem.
        Files and folders the format does not list are ignored, as are hidden ones
        (names starting with ".").
    """
    root = Path(root)
    if root.is_file() and root.name == "rig.json":
        root = root.parent
    if not root.is_dir():
        raise CaptureFormatError(root, "dataset folder not found")
    rig = load_rig(root / "rig.json")
    poses, pose_images = _find_poses(root / "photometric", rig.camera_names)
    objects, chromatic_images = _find_chromatic(root / "chromatic", rig.camera_names)
    scenes, frame_images, masks = _find_scenes(root / "scenes", rig.camera_names, objects, scenes)
    if check_images:
        for image in (*pose_images, *chromatic_images, *frame_images):
            _check_image_header(image, _read_png_header(image, "image file"), rig.image)
        for mask in masks:
            _check_mask_header(mask, _read_png_header(mask, "mask file"), rig.image)
    return Dataset(root, rig, poses, objects, scenes)


def _subfolders(folder: Path) -> list[Path]:
    """Non-hidden sub-folders of ``folder``, by name."""
    return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))


def _check_name(folder: Path, what: str) -> str:
    if not _NAME.fullmatch(folder.name):
        raise CaptureFormatError(
            folder,
            f"{what} name {folder.name!r} has characters other than letters, digits, '_' and '-'",
        )
    return folder.name


def _camera_images(folder: Path, cameras: tuple[str, ...], what: str) -> list[Path]:
    """``folder/<camera>.png`` for every camera, refusing a missing one."""
    if not folder.is_dir():
        raise CaptureFormatError(folder, f"missing folder ({what})")
    paths = [folder / f"{name}.png" for name in cameras]
    for path, name in zip(paths, cameras, strict=True):
        if not path.is_file():
            raise CaptureFormatError(path, f"missing image of camera {name!r} ({what})")
    return paths


def _find_poses(folder: Path, cameras: tuple[str, ...]) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        raise CaptureFormatError(folder, "missing photometric/ folder (at least 3 board poses)")
    poses = [_check_name(p, "pose") for p in _subfolders(folder)]
    if len(poses) < 3:
        raise CaptureFormatError(folder, f"found {len(poses)} poses, at least 3 are required")
    images = [
        path
        for pose in poses
        for path in _camera_images(folder / pose, cameras, f"photometric pose {pose}")
    ]
    return tuple(poses), images


def _find_chromatic(folder: Path, cameras: tuple[str, ...]) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        return (), []
    objects = [_check_name(p, "chromatic object") for p in _subfolders(folder)]
    if objects and "white" not in objects:
        raise CaptureFormatError(
            folder / "white", "missing white reference folder (required when chromatic/ is used)"
        )
    images = [
        path
        for obj in objects
        for colour in COLOURS
        for path in _camera_images(
            folder / obj / colour, cameras, f"chromatic {obj} under {colour} light"
        )
    ]
    return tuple(objects), images


def _find_scenes(
    folder: Path,
    cameras: tuple[str, ...],
    objects: tuple[str, ...],
    wanted: Iterable[str] | None = None,
) -> tuple[dict[str, Scene], list[Path], list[Path]]:
    scenes: dict[str, Scene] = {}
    images: list[Path] = []
    masks: list[Path] = []
    wanted = None if wanted is None else tuple(wanted)
    if not folder.is_dir() or wanted == ():
        return scenes, images, masks
    folders = _subfolders(folder)
    if wanted is not None:
        for name in wanted:
            _known(name, tuple(f.name for f in folders), "scene")
        folders = [f for f in folders if f.name in wanted]
    for scene_dir in folders:
        scene, scene_images, scene_masks = _find_scene(scene_dir, cameras, objects)
        scenes[scene.name] = scene
        images += scene_images
        masks += scene_masks
    return scenes, images, masks


def _find_scene(
    folder: Path, cameras: tuple[str, ...], objects: tuple[str, ...]
) -> tuple[Scene, list[Path], list[Path]]:
    name = _check_name(folder, "scene")
    frames_dir = folder / "frames"
    if not frames_dir.is_dir():
        raise CaptureFormatError(frames_dir, f"scene {name!r} has no frames (missing folder)")
    frames = []
    for frame_dir in _subfolders(frames_dir):
        if not _FRAME.fullmatch(frame_dir.name):
            raise CaptureFormatError(
                frame_dir, f"frame folder name {frame_dir.name!r} is not a 6-digit index"
            )
        frames.append(frame_dir.name)
    if not frames:
        raise CaptureFormatError(frames_dir, f"scene {name!r} has no frames")
    meta = _read_scene_json(folder / "scene.json", objects)
    dynamic = meta.get("dynamic", frames != [_STATIC_FRAME])
    if not dynamic and frames != [_STATIC_FRAME]:
        raise CaptureFormatError(
            folder / "scene.json",
            f"static scene (dynamic: false) must have the single frame {_STATIC_FRAME}, "
            f"found frames {', '.join(frames)}",
        )
    images = [
        path
        for frame in frames
        for path in _camera_images(frames_dir / frame, cameras, f"scene {name} frame {frame}")
    ]
    masks_dir = folder / "masks"
    masks = (
        [
            path
            for frame in frames
            for path in _camera_images(masks_dir / frame, cameras, f"mask of scene {name}")
        ]
        if masks_dir.is_dir()
        else []
    )
    gt_dir = folder / "gt"
    if gt_dir.is_dir():
        for frame in frames:
            if not (gt_dir / f"{frame}.ply").is_file():
                raise CaptureFormatError(
                    gt_dir / f"{frame}.ply", f"missing ground-truth mesh of frame {frame}"
                )
    scene = Scene(
        name=name,
        frames=tuple(frames),
        chromatic=meta.get("chromatic"),
        dynamic=bool(dynamic),
        description=meta.get("description", ""),
        has_masks=masks_dir.is_dir(),
        has_gt=gt_dir.is_dir(),
    )
    return scene, images, masks


def _read_scene_json(path: Path, objects: tuple[str, ...]) -> dict[str, Any]:
    """Validated keys of an optional scene.json ({} when absent); unknown keys are ignored."""
    if not path.exists():
        return {}
    obj = _as_object(_read_json(path, "scene.json"), "scene.json", path)
    meta: dict[str, Any] = {}
    chromatic = obj.get("chromatic")
    if chromatic is not None:
        chromatic = _as_str(chromatic, "chromatic", path)
        if not _NAME.fullmatch(chromatic) or chromatic not in objects:
            raise CaptureFormatError(
                path, f"chromatic object {chromatic!r} has no folder chromatic/{chromatic}"
            )
        meta["chromatic"] = chromatic
    if "dynamic" in obj:
        if not isinstance(obj["dynamic"], bool):
            raise CaptureFormatError(
                path, f"dynamic must be true or false, got {_show(obj['dynamic'])}"
            )
        meta["dynamic"] = obj["dynamic"]
    if obj.get("description") is not None:
        meta["description"] = _as_str(obj["description"], "description", path)
    return meta


def all_images(ds: Dataset) -> list[Path]:
    """Every image and silhouette the dataset lists, in a stable order."""
    cams = ds.rig.camera_names
    paths = [ds.photometric_image(p, c) for p in ds.poses for c in cams]
    paths += [
        ds.chromatic_image(o, col, c) for o in ds.chromatic_objects for col in COLOURS for c in cams
    ]
    for name, scene in sorted(ds.scenes.items()):
        for f in scene.frames:
            paths += [ds.frame_image(name, f, c) for c in cams]
            if scene.has_masks:
                paths += [ds.mask_image(name, f, c) for c in cams]
    return paths


def validate(
    dataset: str | Path, summary_json: str | Path | None = None, progress: bool = False
) -> dict:
    """Validate a whole dataset, decoding every image, and summarise it.

    Parameters
    ----------
    dataset : the dataset folder (capture format, version 1).
    summary_json : optional path of a JSON summary to write (written only
        when the dataset is valid, atomically).
    progress : a bar over the images decoded, on stderr (:mod:`colourhs.common.progress`).

    Returns
    -------
    dict summary: cameras with their light colours, reciprocal pairs, board
    poses, chromatic objects, scenes with their frame counts, image count, the
    fraction of saturated pixels, the lights' reciprocity defect at the rig's
    fixation point (degrees, :func:`colourhs.capture.rig.reciprocity_defect_deg`)
    and ``warnings``: what is valid but costs accuracy
    (:func:`colourhs.capture.rig.light_offset_warning`).

    Raises
    ------
    CaptureFormatError naming the first offending file.
    """
    ds = open_dataset(dataset)
    masks = {
        ds.mask_image(s, f, c)
        for s, sc in ds.scenes.items()
        if sc.has_masks
        for f in sc.frames
        for c in ds.rig.camera_names
    }
    n_pixels = n_saturated = 0
    paths = all_images(ds)
    for path in bar(paths, "validating images", enabled=progress, unit="image"):
        if path in masks:
            read_mask(path, ds.rig.image)
            continue
        _, saturated = read_image(path, ds.rig.image)
        n_pixels += saturated.size
        n_saturated += int(saturated.sum())
    summary = {
        "dataset": str(Path(dataset).resolve()),
        "format": FORMAT,
        "image": {
            "width": ds.rig.image.width,
            "height": ds.rig.image.height,
            "bit_depth": ds.rig.image.bit_depth,
        },
        "cameras": {c.name: c.light_colour for c in ds.rig.cameras},
        "reciprocal_pairs": [
            [p.cam_a, COLOURS[p.channel_a], p.cam_b, COLOURS[p.channel_b]]
            for p in ds.rig.reciprocal_pairs()
        ],
        "poses": list(ds.poses),
        "chromatic_objects": list(ds.chromatic_objects),
        "scenes": {
            n: {
                "frames": len(s.frames),
                "dynamic": s.dynamic,
                "chromatic": s.chromatic,
                "masks": s.has_masks,
                "ground_truth": s.has_gt,
            }
            for n, s in sorted(ds.scenes.items())
        },
        "images": len(paths),
        "saturated_fraction": n_saturated / max(n_pixels, 1),
        "reciprocity_defect_deg": reciprocity_defect_deg(ds.rig),
        "warnings": [w for w in (light_offset_warning(ds.rig),) if w],
    }
    if summary_json is not None:
        from colourhs.common.files import write_json

        write_json(summary_json, summary)
    return summary
