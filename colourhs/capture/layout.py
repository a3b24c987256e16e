"""A whole dataset folder: :func:`open_dataset` checks its layout, :func:`validate` every image.

:func:`open_dataset` walks the layout the format specifies (rig.json,
``photometric/``, the optional ``geometric/``, ``chromatic/``, ``scenes/`` with
frames, masks, ground truth and an optional scene.json) and returns a
:class:`~colourhs.capture.dataset.Dataset`; :func:`validate` also decodes every
image and summarises the dataset (the ``colourhs validate`` command).
Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from colourhs.capture.base import (
    _NAME,
    COLOURS,
    FORMAT,
    IMAGE_FORMATS,
    CaptureFormatError,
    CaptureFormatProblems,
)
from colourhs.capture.dataset import Dataset, Scene, _known, capture_file, capture_files
from colourhs.capture.jsonvalues import _as_object, _as_str, _read_json, _show
from colourhs.capture.png import (
    _check_image_header,
    _check_mask_header,
    _read_header,
    read_image,
    read_mask,
)
from colourhs.capture.rig import (
    Rig,
    light_offset_problem,
    light_offset_warning,
    reciprocity_defect_deg,
)
from colourhs.capture.rigjson import load_rig
from colourhs.common.progress import bar

_FRAME = re.compile(r"[0-9]{6}")
_STATIC_FRAME = "000000"


def _note(problems: list | None, error: CaptureFormatError) -> None:
    """Raise ``error``, or, collecting every problem (``problems`` a list), note it."""
    if problems is None:
        raise error
    problems.append(error)


def _problem(problems: list | None, path: Path, text: str) -> None:
    """:func:`_note` the problem ``text`` of ``path``."""
    _note(problems, CaptureFormatError(path, text))


def _near_miss(folder: Path, camera: str) -> str:
    """A hint when ``folder``, which holds no capture of ``camera``, holds a file of
    that name under another case or suffix (``cam1.PNG``, ``cam1.TIF``, ``cam1.jpg``,
    ``CAM1.png``): the names it should have."""
    found = sorted(p.name for p in folder.iterdir() if p.stem.lower() == camera.lower())
    if not found:
        return ""
    names = [f"{camera}{suffix}" for suffix in IMAGE_FORMATS]
    expected = f"{', '.join(names[:-1])} or {names[-1]}"
    return f"; found {', '.join(found)}: images are PNG or TIFF files named {expected}"


def open_dataset(
    root: str | Path,
    check_images: bool = True,
    scenes: Iterable[str] | None = None,
    problems: list | None = None,
    rig_json: str | Path | None = None,
) -> Dataset:
    """Validate a whole dataset folder and describe its contents.

    Parameters
    ----------
    root : str or Path
        The dataset folder (or its rig.json).
    check_images : bool
        Also check every listed image's header (PNG or TIFF): readable, channels,
        unsigned samples, bit depth and size. Only headers are read (pixel data is
        decoded by :func:`read_image`).
    scenes : iterable of str, optional
        Read only these scenes' folders and scene.json (each must exist; an empty
        one reads none), so that a stage reads no file of the scenes it does not
        use (the workflow's rules declare what they read); default every scene.
    problems : list, optional
        Collect every violation found here instead of raising at the first (what
        :func:`validate` reports); the parts of the dataset that break the format
        are left out of the result. A rig.json that cannot be read still raises.
    rig_json : str or Path, optional
        Read the rig from this file instead of the dataset's own rig.json (a rig
        calibrated from the dataset's ``geometric/`` captures, ``colourhs
        calibrate-rig``'s output); the dataset is checked against it.

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
    rig = load_rig(Path(rig_json) if rig_json is not None else root / "rig.json")
    cams = rig.camera_names
    poses, pose_images = _find_poses(root / "photometric", cams, problems)
    geometric, geometric_images = _find_geometric(root / "geometric", rig, problems)
    objects, chromatic_images = _find_chromatic(root / "chromatic", cams, problems)
    scenes, frame_images, masks = _find_scenes(root / "scenes", cams, objects, scenes, problems)
    if check_images:
        captures = (*pose_images, *geometric_images, *chromatic_images)
        checks = [(p, "image file", _check_image_header) for p in captures]
        checks += [(p, "image file", _check_image_header) for p in frame_images]
        checks += [(p, "mask file", _check_mask_header) for p in masks]
        for path, what, check in checks:
            try:
                check(path, _read_header(path, what), rig.image)
            except CaptureFormatError as error:
                _note(problems, error)
    return Dataset(root, rig, poses, objects, scenes, geometric)


def dataset_of(dataset: str | Path | Dataset, scenes: Iterable[str] | None = None) -> Dataset:
    """``dataset`` itself when it is a :class:`Dataset` (opened by the caller, e.g. with
    another rig.json), else :func:`open_dataset` of the folder without opening an image,
    reading only ``scenes`` (default every scene): how each stage takes its dataset."""
    if isinstance(dataset, Dataset):
        return dataset
    return open_dataset(dataset, check_images=False, scenes=scenes)


def _subfolders(folder: Path) -> list[Path]:
    """Non-hidden sub-folders of ``folder``, by name."""
    return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))


def _check_name(folder: Path, what: str, problems: list | None = None) -> str:
    if not _NAME.fullmatch(folder.name):
        _problem(
            problems,
            folder,
            f"{what} name {folder.name!r} has characters other than letters, digits, '_' and '-'",
        )
    return folder.name


def _camera_images(
    folder: Path, cameras: tuple[str, ...], what: str, problems: list | None = None
) -> list[Path]:
    """Every camera's capture file in ``folder`` (:func:`capture_file`: PNG or TIFF),
    refusing (or noting) a missing one, with a hint at near misses, and a camera with
    more than one file."""
    if not folder.is_dir():
        _problem(problems, folder, f"missing folder ({what})")
        return []
    paths = []
    for name in cameras:
        found = capture_files(folder, name)
        if len(found) == 1:
            paths += found
        elif not found:
            hint = _near_miss(folder, name)
            path = capture_file(folder, name)
            _problem(problems, path, f"missing image of camera {name!r} ({what}){hint}")
        else:
            files = " and ".join(p.name for p in found)
            _problem(
                problems,
                found[0],
                f"{len(found)} images of camera {name!r} ({what}): {files}; keep one",
            )
    return paths


def _find_poses(
    folder: Path, cameras: tuple[str, ...], problems: list | None = None
) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        _problem(problems, folder, "missing photometric/ folder (at least 3 board poses)")
        return (), []
    poses = [_check_name(p, "pose", problems) for p in _subfolders(folder)]
    if len(poses) < 3:
        _problem(problems, folder, f"found {len(poses)} poses, at least 3 are required")
    images = [
        path
        for pose in poses
        for path in _camera_images(folder / pose, cameras, f"photometric pose {pose}", problems)
    ]
    return tuple(poses), images


def _find_geometric(
    folder: Path, rig: Rig, problems: list | None = None
) -> tuple[tuple[str, ...], list[Path]]:
    """The poses of the ChArUco target under ``folder`` (``geometric/``) and their images.

    Optional: no folder, no poses. A folder needs rig.json's ``geometric_board`` (what
    the captures show) and at least one pose; each pose holds one image per camera,
    as a photometric pose does (a camera that does not see the target in a pose
    still has its image).
    """
    if not folder.is_dir():
        return (), []
    if rig.geometric_board is None:
        _problem(
            problems,
            folder,
            f"geometric/ holds captures of a ChArUco target, but {rig.path} has no "
            "geometric_board (the target's description): add it, or remove geometric/",
        )
        return (), []
    poses = [_check_name(p, "geometric pose", problems) for p in _subfolders(folder)]
    if not poses:
        _problem(problems, folder, "geometric/ holds no pose folders (at least 1 is required)")
    images = [
        path
        for pose in poses
        for path in _camera_images(
            folder / pose, rig.camera_names, f"geometric pose {pose}", problems
        )
    ]
    return tuple(poses), images


def _find_chromatic(
    folder: Path, cameras: tuple[str, ...], problems: list | None = None
) -> tuple[tuple[str, ...], list[Path]]:
    if not folder.is_dir():
        return (), []
    objects = [_check_name(p, "chromatic object", problems) for p in _subfolders(folder)]
    if objects and "white" not in objects:
        _problem(
            problems,
            folder / "white",
            "missing white reference folder (required when chromatic/ is used)",
        )
    images = [
        path
        for obj in objects
        for colour in COLOURS
        for path in _camera_images(
            folder / obj / colour, cameras, f"chromatic {obj} under {colour} light", problems
        )
    ]
    return tuple(objects), images


def _find_scenes(
    folder: Path,
    cameras: tuple[str, ...],
    objects: tuple[str, ...],
    wanted: Iterable[str] | None = None,
    problems: list | None = None,
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
        found = _find_scene(scene_dir, cameras, objects, problems)
        if found is None:  # noted in problems: nothing of it to list
            continue
        scene, scene_images, scene_masks = found
        scenes[scene.name] = scene
        images += scene_images
        masks += scene_masks
    return scenes, images, masks


def _find_scene(
    folder: Path, cameras: tuple[str, ...], objects: tuple[str, ...], problems: list | None = None
) -> tuple[Scene, list[Path], list[Path]] | None:
    """The scene in ``folder``, its images and masks; None when it has no frames to
    list (only while collecting ``problems``, where that is noted)."""
    name = _check_name(folder, "scene", problems)
    frames_dir = folder / "frames"
    if not frames_dir.is_dir():
        _problem(problems, frames_dir, f"scene {name!r} has no frames (missing folder)")
        return None
    frames = []
    for frame_dir in _subfolders(frames_dir):
        if not _FRAME.fullmatch(frame_dir.name):
            _problem(
                problems,
                frame_dir,
                f"frame folder name {frame_dir.name!r} is not a 6-digit index",
            )
            continue
        frames.append(frame_dir.name)
    if not frames:
        _problem(problems, frames_dir, f"scene {name!r} has no frames")
        return None
    try:
        meta = _read_scene_json(folder / "scene.json", objects, tuple(frames))
    except CaptureFormatError as error:
        _note(problems, error)
        meta = {}
    dynamic = meta.get("dynamic", frames != [_STATIC_FRAME])
    if not dynamic and frames != [_STATIC_FRAME]:
        _problem(
            problems,
            folder / "scene.json",
            f"static scene (dynamic: false) must have the single frame {_STATIC_FRAME}, "
            f"found frames {', '.join(frames)}",
        )
    images = [
        path
        for frame in frames
        for path in _camera_images(
            frames_dir / frame, cameras, f"scene {name} frame {frame}", problems
        )
    ]
    masks_dir = folder / "masks"
    masks = (
        [
            path
            for frame in frames
            for path in _camera_images(
                masks_dir / frame, cameras, f"mask of scene {name}", problems
            )
        ]
        if masks_dir.is_dir()
        else []
    )
    gt_dir = folder / "gt"
    if gt_dir.is_dir():
        for frame in frames:
            if not (gt_dir / f"{frame}.ply").is_file():
                _problem(
                    problems,
                    gt_dir / f"{frame}.ply",
                    f"missing ground-truth mesh of frame {frame}",
                )
    scene = Scene(
        name=name,
        frames=tuple(frames),
        chromatic=meta.get("chromatic"),
        chromatic_frame=meta.get("chromatic_frame", frames[0]),
        dynamic=bool(dynamic),
        description=meta.get("description", ""),
        has_masks=masks_dir.is_dir(),
        has_gt=gt_dir.is_dir(),
    )
    return scene, images, masks


def _read_scene_json(
    path: Path, objects: tuple[str, ...], frames: tuple[str, ...] = ()
) -> dict[str, Any]:
    """Validated keys of an optional scene.json ({} when absent); unknown keys are ignored.

    ``chromatic_frame`` (a frame folder name or its index) must name one of ``frames``
    (the scene's); it is returned as the folder name."""
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
    if obj.get("chromatic_frame") is not None:
        meta["chromatic_frame"] = _chromatic_frame(obj["chromatic_frame"], frames, path)
    if "dynamic" in obj:
        if not isinstance(obj["dynamic"], bool):
            raise CaptureFormatError(
                path, f"dynamic must be true or false, got {_show(obj['dynamic'])}"
            )
        meta["dynamic"] = obj["dynamic"]
    if obj.get("description") is not None:
        meta["description"] = _as_str(obj["description"], "description", path)
    return meta


def _chromatic_frame(value: Any, frames: tuple[str, ...], path: Path) -> str:
    """scene.json's ``chromatic_frame``: a 6-digit frame name or a non-negative integer,
    naming a frame of the scene (one of ``frames``), as the frame's folder name."""
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        name = f"{value:06d}"
    elif isinstance(value, str) and _FRAME.fullmatch(value):
        name = value
    else:
        raise CaptureFormatError(
            path,
            f"chromatic_frame must be a 6-digit frame name or a frame index, got {_show(value)}",
        )
    if name not in frames:
        shown = ", ".join(frames) if len(frames) <= 4 else f"{frames[0]} to {frames[-1]}"
        raise CaptureFormatError(
            path,
            f"chromatic_frame {name} is not a frame of the scene (frames/ holds "
            f"{len(frames)}: {shown})",
        )
    return name


def all_images(ds: Dataset) -> list[Path]:
    """Every image and silhouette the dataset lists, in a stable order."""
    cams = ds.rig.camera_names
    paths = [ds.photometric_image(p, c) for p in ds.poses for c in cams]
    paths += [ds.geometric_image(p, c) for p in ds.geometric_poses for c in cams]
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
    dataset: str | Path, summary_json: str | Path | None = None, rig_json: str | Path | None = None
) -> dict:
    """Validate a whole dataset, decoding every image, and summarise it.

    Shows a bar over the images decoded (:func:`colourhs.common.progress.bar`).

    Parameters
    ----------
    dataset : the dataset folder (capture format, version 1).
    summary_json : optional path of a JSON summary to write (written only
        when the dataset is valid, atomically).
    rig_json : optional rig.json to check the dataset against instead of its own
        (:func:`open_dataset`).

    Returns
    -------
    dict summary: cameras with their light colours, reciprocal pairs, board
    poses, the ChArUco target's poses (``geometric_poses``, empty without
    ``geometric/``), chromatic objects, scenes with their frame counts, image count, the
    fraction of saturated pixels, the lights' reciprocity defect at the rig's
    fixation point (degrees, :func:`colourhs.capture.rig.reciprocity_defect_deg`)
    and ``warnings``: what is valid but costs accuracy
    (:func:`colourhs.capture.rig.light_offset_warning`).

    Raises
    ------
    CaptureFormatError
        Naming the offending file; where several break the format,
        :class:`CaptureFormatProblems` naming every one (a rig.json that cannot be
        read stops the check at once: the rest is read against it).
    """
    problems: list[CaptureFormatError] = []
    ds = open_dataset(dataset, problems=problems, rig_json=rig_json)
    headers_bad = {p.path for p in problems}
    masks = {
        ds.mask_image(s, f, c)
        for s, sc in ds.scenes.items()
        if sc.has_masks
        for f in sc.frames
        for c in ds.rig.camera_names
    }
    n_pixels = n_saturated = 0
    paths = all_images(ds)
    paths = [p for p in paths if p.is_file() and p not in headers_bad]
    for path in bar(paths, "validating images", unit="image"):
        try:
            if path in masks:
                read_mask(path, ds.rig.image)
                continue
            _, saturated = read_image(path, ds.rig.image)
        except CaptureFormatError as error:
            problems.append(error)
            continue
        n_pixels += saturated.size
        n_saturated += int(saturated.sum())
    offset = light_offset_problem(ds.rig)
    if offset is not None:
        problems.append(CaptureFormatError(ds.rig.path, offset))
    if len(problems) == 1:
        raise problems[0]
    if problems:
        raise CaptureFormatProblems(ds.root, problems)
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
        "geometric_poses": list(ds.geometric_poses),
        "chromatic_objects": list(ds.chromatic_objects),
        "scenes": {
            n: {
                "frames": len(s.frames),
                "dynamic": s.dynamic,
                "chromatic": s.chromatic,
                "chromatic_frame": s.chromatic_frame if s.chromatic else None,
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
