"""Render whole synthetic datasets in the capture format (``capture-format.md``).

A dataset holds: board poses for photometric calibration, views of a ChArUco
target for a geometric calibration (``geometric/``, the target in rig.json's
``geometric_board``: :mod:`colourhs.synth.geometric_target`), chromatic
captures of the white reference and of every coloured object under red,
green and blue light, the scenes ``plane`` (a held-out board pose),
``statue``, ``toy`` and ``sheet`` (dynamic), ground-truth meshes per frame,
silhouettes, the true mu maps (``gt/photometric.h5``) and, as optional
extensions of the format, the full rig model (``gt/rig_model.json``), the
true board poses (``gt/board_poses.json``), the true target poses
(``gt/geometric_poses.json``) and true chromaticity maps
(``scenes/<scene>/gt/chromaticity.h5``).

The ``dynamic`` presets (``dynamic``, ``dynamic-tiny``, ``random-dynamic``,
``random-dynamic-tiny``, ``corner-dynamic``, ``corner-dynamic-tiny``) hold
instead of the statue, toy and sheet the sequences of
:mod:`colourhs.synth.dynamicscenes` (``moving-toy``, ``cloth``,
``turning-metal``: multi-coloured objects that move or deform), each with
chromatic captures of one frame (scene.json's ``chromatic_frame``), true
chromaticity maps per frame (``scenes/<scene>/gt/chromaticity/<frame>.h5``)
and, for the rigid ones, the true motion (``scenes/<scene>/gt/motion.json``).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import json
import logging
import multiprocessing
import os
import shutil
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import h5py
import numpy as np

from colourhs.common.ply import write_ply
from colourhs.common.progress import bar, stage
from colourhs.common.raycast import raycasting_scene
from colourhs.synth import scenes as sc
from colourhs.synth.geometric_target import N_POSES, GeometricCaptures, geometric_captures
from colourhs.synth.groundtruth import true_mu_maps
from colourhs.synth.groundtruth import true_poses_csv as true_poses_csv  # re-exported
from colourhs.synth.image_formation import (
    camera_rays,
    channel_signal,
    light_transport,
    trace_camera,
)
from colourhs.synth.poses import board_poses
from colourhs.synth.simulated_rig import COLOURS, Nuisances, RigModel, make_rig, sensor

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from colourhs.synth.randomranges import RandomRanges

FORMAT = "colourhs-capture/1"


def _board(markers: dict, length: float, size=(0.26, 0.2)) -> dict:
    return {
        "dictionary": "DICT_4X4_50",
        "marker_length": length,
        "size": list(size),
        "markers": {str(k): list(v) for k, v in markers.items()},
    }


DEMO_BOARD = _board(
    {
        0: (0.0275, 0.0275),
        1: (0.13, 0.0275),
        2: (0.2325, 0.0275),
        3: (0.2325, 0.1725),
        4: (0.13, 0.1725),
        5: (0.0275, 0.1725),
    },
    0.035,
)
TINY_BOARD = _board(
    {0: (0.045, 0.045), 1: (0.215, 0.045), 2: (0.215, 0.155), 3: (0.045, 0.155)}, 0.07
)


@dataclass(frozen=True)
class Preset:
    """Size and content of a synthetic dataset.

    A ``randomised`` preset draws its rig, board, encoding and scenes from the
    seed, from the ranges ``randomrig.RANGES_BY_NAME[random_ranges]`` (see
    :mod:`colourhs.synth.randomrig`; ``focal_px``, ``board``, ``bit_depth``,
    ``black_level`` and ``white_level`` are then ignored). ``bit_depth`` is the
    PNGs' (8 or 16); ``white_level`` the raw value of full scale, None for
    ``2**bit_depth - 1`` (4095 for 12-bit data in 16-bit PNGs).
    ``geometric_poses``: poses of the ChArUco target under ``geometric/``
    (:mod:`colourhs.synth.geometric_target`). ``scene_set``: ``"static"`` (the
    scenes ``plane``, ``statue``, ``toy`` and ``sheet``) or ``"dynamic"`` (``plane``
    and the sequences of :mod:`colourhs.synth.dynamicscenes`, ``sheet_frames``
    frames each).
    """

    name: str
    width: int
    height: int
    focal_px: float
    supersample: int
    n_poses: int = 7
    sheet_frames: int = 12
    statue_level: int = 6
    board: dict = field(default_factory=lambda: DEMO_BOARD)
    bit_depth: int = 16
    black_level: int = 512
    white_level: int | None = None
    randomised: bool = False
    random_ranges: str = "random"
    geometric_poses: int = N_POSES
    scene_set: str = "static"


PRESETS = {
    "tiny": Preset("tiny", 160, 120, 312.5, 3, sheet_frames=3, statue_level=5, board=TINY_BOARD),
    "demo": Preset("demo", 640, 480, 1250.0, 2, sheet_frames=12),
    "paper": Preset("paper", 1280, 960, 2500.0, 2, sheet_frames=201),
    "random": Preset("random", 640, 480, 0.0, 2, sheet_frames=4, randomised=True),
    "random-tiny": Preset(
        "random-tiny",
        160,
        120,
        0.0,
        3,
        sheet_frames=4,
        statue_level=5,
        randomised=True,
        random_ranges="random-tiny",
    ),
}
# random-tiny with skewed cameras and rational and thin-prism lens terms
# (randomranges.RANGES_BY_NAME), for the camera model's less common coefficients.
PRESETS["random-tiny-lens"] = replace(
    PRESETS["random-tiny"], name="random-tiny-lens", random_ranges="random-tiny-lens"
)
# The hard ends of the ranges combined (randomranges.CORNER_RANGES), at the
# random presets' sizes.
PRESETS["corner"] = replace(PRESETS["random"], name="corner", random_ranges="corner")
PRESETS["corner-tiny"] = replace(
    PRESETS["random-tiny"], name="corner-tiny", random_ranges="corner-tiny"
)
# Moving and deforming multi-coloured objects (colourhs.synth.dynamicscenes), 12
# frames each, on the fixed rig (at the tiny and demo sizes), on the random rigs and
# on the corner rigs (the ranges' hard ends combined).
PRESETS.update(
    {
        name: replace(PRESETS[base], name=name, sheet_frames=12, scene_set="dynamic")
        for name, base in (
            ("dynamic-tiny", "tiny"),
            ("dynamic", "demo"),
            ("random-dynamic", "random"),
            ("random-dynamic-tiny", "random-tiny"),
            ("corner-dynamic", "corner"),
            ("corner-dynamic-tiny", "corner-tiny"),
        )
    }
)


@dataclass(frozen=True)
class Content:
    """What a dataset's captures show, beyond the rig and the board poses.

    Builders are callables returning a :class:`~colourhs.synth.scenes.SceneGeometry`
    (``sheet`` takes the phase in [0, 1]); ``statue``, ``toy`` and ``sheet`` are None
    in a dynamic preset, whose scenes are ``sequences``
    (:class:`~colourhs.synth.dynamicscenes.Sequence`). ``mask_mode``: ``"exact"``
    (coverage >= 0.5), ``"none"`` (no ``masks/`` folder), ``"dilated"`` or
    ``"eroded"`` (by 1 px, 3x3). ``extra_gt``: more about the draw for
    ``gt/rig_model.json`` (key ``draw``). ``geometric``: the ChArUco target and its
    poses (None: no ``geometric/`` and no ``geometric_board``).
    """

    white: object
    statue: object
    toy: object
    sheet: object
    mask_mode: str = "exact"
    scene_meta: dict = field(default_factory=lambda: SCENE_META)
    extra_gt: dict | None = None
    geometric: GeometricCaptures | None = None
    sequences: tuple = ()


def fixed_content(preset: Preset) -> Content:
    """The scenes of the fixed presets (tiny, demo, paper; dynamic-tiny, dynamic)."""
    if preset.scene_set == "dynamic":
        from colourhs.synth.dynamicscenes import fixed_sequences, scene_meta

        seqs = fixed_sequences(preset.sheet_frames)
        meta = scene_meta(seqs, SCENE_META["plane"])
        return Content(sc.white_reference, None, None, None, scene_meta=meta, sequences=seqs)
    return Content(
        white=sc.white_reference,
        statue=lambda: sc.statue(preset.statue_level),
        toy=sc.toy,
        sheet=sc.sheet,
    )


PARTS = ("photometric", "chromatic", "scenes", "geometric")


def rig_json(
    rig: RigModel, preset: Preset, board: dict, geometric_board: dict | None = None
) -> dict:
    """The dataset's rig.json (capture format, version 1), with the ChArUco target's
    ``geometric_board`` when one is given."""
    return {
        "format": FORMAT,
        "units": "m",
        "image": {
            "width": preset.width,
            "height": preset.height,
            "bit_depth": preset.bit_depth,
            "black_level": preset.black_level,
            "white_level": _white_level(preset),
        },
        "cameras": [c.to_json() for c in rig.cameras],
        "board": board,
        **({} if geometric_board is None else {"geometric_board": geometric_board}),
        "chromatic_light": {"position": rig.chromatic_lights["red"].position.tolist()},
    }


def _white_level(preset: Preset) -> int:
    """The preset's raw value of full scale: its ``white_level``, else ``2**bit_depth - 1``."""
    return 2**preset.bit_depth - 1 if preset.white_level is None else preset.white_level


def _image_rng(seed: int, relpath: str) -> np.random.Generator:
    digest = hashlib.sha256(f"{seed}:{relpath}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


def write_png(path: Path, rgb: np.ndarray) -> None:
    """Write an R, G, B image (H, W, 3) as PNG (OpenCV stores B, G, R)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1])):
        raise OSError(f"{path}: could not write PNG")


@dataclass(frozen=True)
class _Job:
    """One geometry seen by every camera, and the images to make of it."""

    geometry: object  # callable () -> SceneGeometry (built lazily)
    frames: tuple[str, ...] = ()  # relpaths (without camera) of all-lights-on images
    chromatic: str | None = None  # relpath prefix of red/green/blue chromatic captures
    mask: str | None = None  # relpath prefix of silhouettes
    gt_mesh: str | None = None  # relpath of the ground-truth mesh
    gt_chroma: str | None = None  # relpath of the true chromaticity maps


def _jobs(preset: Preset, poses, parts, content: Content | None = None, frames=None) -> list[_Job]:
    content = fixed_content(preset) if content is None else content
    masks = content.mask_mode != "none"
    board = preset.board
    jobs = []
    if "photometric" in parts:
        for k, (R, t) in enumerate(poses[:-1]):
            jobs.append(
                _Job(lambda R=R, t=t: sc.board_geometry(board, R, t), (f"photometric/pose{k:02d}",))
            )
    if "chromatic" in parts:
        jobs.append(_Job(content.white, chromatic="chromatic/white"))
    if "scenes" in parts:
        R, t = poses[-1]
        jobs.append(
            _Job(
                lambda R=R, t=t: sc.board_geometry(board, R, t, name="plane"),
                ("scenes/plane/frames/000000",),
                mask="scenes/plane/masks/000000" if masks else None,
                gt_mesh="scenes/plane/gt/000000.ply",
            )
        )
    for name, build in (("statue", content.statue), ("toy", content.toy)):
        if build is None:
            continue
        jobs.append(
            _Job(
                build,
                ("scenes/" + name + "/frames/000000",) if "scenes" in parts else (),
                chromatic=f"chromatic/{name}" if "chromatic" in parts else None,
                mask=f"scenes/{name}/masks/000000" if "scenes" in parts and masks else None,
                gt_mesh=f"scenes/{name}/gt/000000.ply" if "scenes" in parts else None,
                gt_chroma=f"scenes/{name}/gt/chromaticity.h5" if "scenes" in parts else None,
            )
        )
    if "scenes" in parts and content.sheet is not None:
        n = preset.sheet_frames
        for f in range(n) if frames is None else frames:
            jobs.append(
                _Job(
                    lambda f=f: content.sheet(f / max(n - 1, 1)),
                    (f"scenes/sheet/frames/{f:06d}",),
                    mask=f"scenes/sheet/masks/{f:06d}" if masks else None,
                    gt_mesh=f"scenes/sheet/gt/{f:06d}.ply",
                )
            )
    for seq in content.sequences:
        jobs += _sequence_jobs(seq, parts, masks, frames)
    geometric = content.geometric
    if "geometric" in parts and geometric is not None:
        target = geometric.target
        for name, (R, t) in zip(geometric.names, geometric.poses, strict=True):
            jobs.append(
                _Job(
                    lambda R=R, t=t: sc.board_geometry(target, R, t, name="charuco"),
                    (f"geometric/{name}",),
                )
            )
    return [j for j in jobs if j.frames or j.chromatic]


def _sequence_jobs(seq, parts, masks: bool, frames=None) -> list[_Job]:
    """The jobs of a dynamic preset's sequence: its ``frames`` (default all) and always
    its chromatic frame, which the chromatic captures show (scene.json names it, so a
    dataset of some frames stays valid); a frame's files equal a full render's."""
    chosen = range(seq.frames) if frames is None else sorted({*frames, seq.chromatic_frame})
    scenes = "scenes" in parts
    out = []
    for f in chosen:
        chromatic = f == seq.chromatic_frame and "chromatic" in parts
        rel = f"scenes/{seq.name}/{{}}/{f:06d}"
        out.append(
            _Job(
                lambda f=f, build=seq.build: build(f),
                (rel.format("frames"),) if scenes else (),
                chromatic=f"chromatic/{seq.name}" if chromatic else None,
                mask=rel.format("masks") if scenes and masks else None,
                gt_mesh=rel.format("gt") + ".ply" if scenes else None,
                gt_chroma=f"scenes/{seq.name}/gt/chromaticity/{f:06d}.h5" if scenes else None,
            )
        )
    return out


def _scene_of(job: _Job) -> str | None:
    """The scene (or chromatic object) a job renders; None for the board and white captures."""
    path = (job.frames or (job.chromatic,))[0]
    parts = path.split("/")
    return parts[1] if parts[0] in ("scenes", "chromatic") and parts[1] != "white" else None


# One description per scene for every preset (true whatever a random draw's
# materials), so scene.json tells nothing about the preset.
SCENE_META = {
    "plane": {
        "chromatic": None,
        "dynamic": False,
        "description": "held-out pose of the white marker board",
    },
    "statue": {
        "chromatic": "statue",
        "dynamic": False,
        "description": "white monster head with smooth dirt",
    },
    "toy": {
        "chromatic": "toy",
        "dynamic": False,
        "description": "multi-coloured toy dog: pure colours, specular plastic, metal",
    },
    "sheet": {"chromatic": None, "dynamic": True, "description": "white sheet folding and doming"},
}


@dataclass(frozen=True)
class RenderSelection:
    """Which of a dataset's captures :func:`synthesise` renders.

    A subset's files equal those of a full render: every image's noise is drawn
    from the seed and the image's own path.

    Attributes
    ----------
    parts : subset of :data:`PARTS` (``"photometric"``, ``"chromatic"``,
        ``"scenes"``, ``"geometric"``) to render; names. Default all four: a
        complete dataset in the capture format, on any rig. rig.json (with its
        ``geometric_board``) and ``gt/`` are the same whatever the parts.
    scenes : render only these of ``plane``, ``statue``, ``toy``, ``sheet`` (their
        frames and chromatic captures); names. Default (None) all four: every
        preset, fixed or randomised, has them. A dynamic preset's scenes are
        ``plane``, ``moving-toy``, ``cloth`` and ``turning-metal`` instead.
    frames : render only these frames of the sheet's sequence, indices in
        ``range(preset.sheet_frames)`` (e.g. ``range(40, 60)``). Default (None)
        all: the count is the preset's, not the rig's. A frame's shape (its phase
        is ``i / (sheet_frames - 1)``) and noise do not depend on which other
        frames are rendered. In a dynamic preset: these frames of every
        sequence, and always its chromatic frame.
    """

    parts: tuple[str, ...] = PARTS
    scenes: tuple[str, ...] | None = None
    frames: Iterable[int] | None = None


@dataclass(frozen=True)
class DrawOverrides:
    """Changes to a randomised preset's draw; the fixed presets ignore them.

    Attributes
    ----------
    ranges : a :class:`colourhs.synth.randomranges.RandomRanges` to draw from
        instead of the preset's named ranges (one range moved at a time, as
        ``benchmarks/light_offset.py`` does; a quantity with its own random
        stream, as the light offsets, leaves the rest of the seed's draw as it
        was). Default (None): the preset's own ranges (``Preset.random_ranges``).
    exact : force 16-bit images and exact masks, keeping the rest of the seed's
        draw (for consistency tests); a switch. Default off: the encoding and
        masks the seed drew. The fixed presets are always exact.
    """

    ranges: RandomRanges | None = None
    exact: bool = False


def synthesise(
    out: str | Path,
    preset: str | Preset = "demo",
    seed: int = 0,
    nuisances: Nuisances | None = None,
    selection: RenderSelection = RenderSelection(),
    overwrite: bool = False,
    workers: int | None = None,
    draw: DrawOverrides = DrawOverrides(),
) -> Path:
    """Render a synthetic colour HS dataset into ``out`` (capture format v1).

    The dataset is written to a sibling folder and moved into place at the
    end, so an interrupted run leaves no partial dataset behind. The same
    ``seed`` and preset give the same images, whatever ``selection`` asks.
    Logs a line at INFO before the ground-truth mu maps and shows bars over the
    camera rays and the views (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    out : dataset folder to create.
    preset : a name of :data:`PRESETS` (``"tiny"``, ``"demo"``, ``"paper"``,
        ``"random"``, ``"random-tiny"``, ``"random-tiny-lens"``, ``"corner"``,
        ``"corner-tiny"``, ``"dynamic-tiny"``, ``"dynamic"``, ``"random-dynamic"``,
        ``"random-dynamic-tiny"``, ``"corner-dynamic"``, ``"corner-dynamic-tiny"``) or a
        :class:`Preset`.
    seed : seed of every random choice (rig, poses, noise; with a randomised
        preset also the rig's design, board, encoding, masks and scenes).
    nuisances : effects to simulate (default: all on, :class:`Nuisances`). With a
        randomised preset only its switches count (and ``gain_spread``,
        ``chromatic_filter_tilt`` as magnitudes); the geometry, scenes, poses
        and encoding drawn do not depend on it.
    selection : the parts, scenes and sheet frames to render (:class:`RenderSelection`;
        default all). A frame's files equal those of a full render.
    overwrite : replace an existing ``out``.
    workers : processes rendering views in parallel (default: CPU count).
    draw : randomised presets: other ranges, or exact encoding and masks
        (:class:`DrawOverrides`; default the preset's own draw).

    Returns
    -------
    Path of the dataset.
    """
    out = Path(out)
    p = PRESETS[preset] if isinstance(preset, str) else preset
    nuis = Nuisances() if nuisances is None else nuisances
    parts, scenes, frames = selection.parts, selection.scenes, selection.frames
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"unknown parts {sorted(unknown)}; choose from {PARTS}")
    known, moving = _scene_names(p)
    if scenes is not None and set(scenes) - set(known):
        unknown = sorted(set(scenes) - set(known))
        raise ValueError(f"unknown scenes {unknown}; scenes: {', '.join(known)}")
    if frames is not None and ("scenes" not in parts or not set(moving) & set(scenes or moving)):
        what = "the sheet, which is" if moving == ("sheet",) else ", ".join(moving) + ", none"
        raise ValueError(f"frames selects frames of {what} not rendered")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out}: already exists (pass overwrite=True to replace it)")
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    selection = replace(selection, frames=_frame_selection(p, frames))
    if p.randomised:
        from colourhs.synth.randomrig import RANGES_BY_NAME, describe, draw_random

        ranges = RANGES_BY_NAME[p.random_ranges] if draw.ranges is None else draw.ranges
        d = draw_random(
            seed,
            p.width,
            p.height,
            nuis,
            ranges,
            n_poses=p.n_poses,
            sheet_frames=p.sheet_frames,
            statue_level=p.statue_level,
            exact=draw.exact,
        )
        rig, poses = d.rig, d.poses
        p = replace(
            p,
            board=d.board,
            bit_depth=d.bit_depth,
            black_level=d.black_level,
            white_level=d.white_level,
        )
        nuis = rig.nuisances
        b = d.builders
        content = Content(
            b["white"],
            b["statue"],
            b["toy"],
            b["sheet"],
            d.mask_mode,
            SCENE_META,
            describe(d),
        )
        if p.scene_set == "dynamic":
            content = _random_dynamic(content, d, seed, ranges, p)
    else:
        rng = np.random.default_rng(seed)
        rig = make_rig(p.width, p.height, p.focal_px, rng, nuis)
        poses = board_poses(rig, p.board, p.n_poses + 1, rng)
        content = fixed_content(p)
    content = replace(content, geometric=geometric_captures(rig, p.geometric_poses, seed))
    tmp = out.with_name(out.name + ".partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    try:
        with _single_threaded_blas():
            _write_dataset(tmp, rig, p, poses, content, seed, nuis, selection, workers)
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def synthesise_exact(
    out: str | Path,
    preset: str | Preset,
    seed: int = 0,
    selection: RenderSelection = RenderSelection(),
    workers: int | None = None,
) -> Path:
    """:func:`synthesise` the data that must give exact answers: no sensor noise and no
    cross-talk, 16-bit images and exact masks (``DrawOverrides(exact=True)``); every
    other nuisance stays on, since the true calibration (``gt/photometric.h5``, the
    true chromaticity) undoes it. Returns the dataset folder."""
    return synthesise(
        out,
        preset,
        seed=seed,
        nuisances=Nuisances().without("noise", "crosstalk"),
        selection=selection,
        workers=workers,
        draw=DrawOverrides(exact=True),
    )


def noise_free_chromatic(
    dataset: str | Path,
    out: str | Path,
    preset: str | Preset,
    seed: int = 0,
    scenes: tuple[str, ...] | None = None,
    workers: int | None = None,
    nuisances: Nuisances | None = None,
) -> Path:
    """``dataset`` (rendered by :func:`synthesise` from ``preset``, ``seed`` and
    ``nuisances``, default all on) with its chromatic captures rendered again with the
    sensor noise alone off: every other nuisance, the rig, the poses and the scenes the
    same. ``out`` gets the new captures
    of ``scenes``' chromatic objects (None: every scene's) under ``out/render`` and the
    dataset folder ``out/noise_free``, which it returns: links to them and to every
    other entry of ``dataset`` (another object's chromatic captures stay the noisy
    ones). The chromaticity that eq. (12) gives from it is the map's own
    definition without the noise its error bar propagates (beyond the paper: what that
    error bar claims to cover)."""
    dataset, out = Path(dataset).resolve(), Path(out)
    render = synthesise(
        out / "render",
        preset,
        seed=seed,
        nuisances=(Nuisances() if nuisances is None else nuisances).without("noise"),
        selection=RenderSelection(parts=("chromatic",), scenes=scenes),
        workers=workers,
    )
    folder = out / "noise_free"
    (folder / "chromatic").mkdir(parents=True)
    for entry in dataset.iterdir():
        if entry.name != "chromatic":
            (folder / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    for entry in (dataset / "chromatic").iterdir():
        target = render / "chromatic" / entry.name
        target = target if target.exists() else entry  # not rendered: the noisy captures
        (folder / "chromatic" / entry.name).symlink_to(target.resolve(), target_is_directory=True)
    return folder


def preset_chromatic_objects(preset: str | Preset) -> list[str]:
    """The chromatic objects (but ``white``) of ``preset``'s datasets, known before one
    is rendered (the workflow plans their chromaticity maps from them)."""
    p = PRESETS[preset] if isinstance(preset, str) else preset
    if p.scene_set == "dynamic":
        from colourhs.synth.dynamicscenes import DYNAMIC_SCENES

        return sorted(DYNAMIC_SCENES)  # each sequence is its own chromatic object
    return sorted({m["chromatic"] for m in SCENE_META.values() if m["chromatic"]})


def _scene_names(preset: Preset) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The scenes of ``preset``'s datasets, and those of them whose frames
    ``RenderSelection.frames`` selects."""
    if preset.scene_set == "dynamic":
        from colourhs.synth.dynamicscenes import DYNAMIC_SCENES

        return ("plane", *DYNAMIC_SCENES), DYNAMIC_SCENES
    if preset.scene_set != "static":
        raise ValueError(f"preset {preset.name}: unknown scene_set {preset.scene_set!r}")
    return tuple(SCENE_META), ("sheet",)


def _random_dynamic(content: Content, d, seed: int, ranges, p: Preset) -> Content:
    """A random draw's content with the dynamic sequences in place of the statue, toy
    and sheet (:func:`colourhs.synth.dynamicscenes.random_sequences`; what they drew
    under ``dynamic`` in ``gt/rig_model.json``'s ``draw``)."""
    from colourhs.synth.dynamicscenes import random_sequences, scene_meta
    from colourhs.synth.simulated_rig import jsonable

    seqs = random_sequences(
        seed, d.rig, d.description["scenes"], ranges, p.sheet_frames, p.statue_level
    )
    return replace(
        content,
        statue=None,
        toy=None,
        sheet=None,
        scene_meta=scene_meta(seqs, SCENE_META["plane"]),
        extra_gt=content.extra_gt | {"dynamic": jsonable({s.name: s.draw for s in seqs})},
        sequences=seqs,
    )


def _frame_selection(preset: Preset, frames=None) -> tuple[int, ...] | None:
    """The sheet frames to render, checked: sorted unique indices in
    ``range(preset.sheet_frames)``, or None (all)."""
    if frames is None:
        return None
    out = tuple(sorted({int(f) for f in frames}))
    bad = [f for f in out if not 0 <= f < preset.sheet_frames]
    if bad or not out:
        what = "sheet has" if preset.scene_set == "static" else "sequences have"
        raise ValueError(
            f"frames {bad or '(none)'}: the {preset.name} preset's {what} frames "
            f"0-{preset.sheet_frames - 1}"
        )
    return out


def _write_dataset(root, rig, p, poses, content, seed, nuis, selection, workers):
    """Write the dataset of a drawn rig, preset, board poses and content into ``root``:
    rig.json, the ground truth and the images ``selection`` (its frames checked) asks."""
    parts, scenes = selection.parts, selection.scenes
    geometric = content.geometric
    target = None if geometric is None else geometric.target
    (root / "rig.json").write_text(json.dumps(rig_json(rig, p, p.board, target), indent=2))
    gt = root / "gt"
    gt.mkdir()
    model = rig.to_json()
    if content.extra_gt is not None:
        model["draw"] = content.extra_gt
    (gt / "rig_model.json").write_text(json.dumps(model, indent=1))
    names = [f"pose{k:02d}" for k in range(len(poses) - 1)] + ["plane"]
    (gt / "board_poses.json").write_text(_poses_json(names, poses))
    if geometric is not None:
        (gt / "geometric_poses.json").write_text(_poses_json(geometric.names, geometric.poses))
    stage(log, f"synth {p.name}: ground-truth mu maps (gt/photometric.h5)")
    with h5py.File(gt / "photometric.h5", "w") as f:
        f.attrs["note"] = "mu = rho / sigma (eq. 2) on pixel centres; one scale per pair is free"
        for key, mu in true_mu_maps(rig).items():
            f.create_dataset(key, data=mu, compression="gzip")
    if "scenes" in parts:
        for name, meta in content.scene_meta.items():
            if scenes is not None and name not in scenes:
                continue
            d = root / "scenes" / name
            d.mkdir(parents=True, exist_ok=True)
            (d / "scene.json").write_text(json.dumps(meta, indent=2))
        for seq in content.sequences:
            if seq.motion is not None and (scenes is None or seq.name in scenes):
                path = root / "scenes" / seq.name / "gt" / "motion.json"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(seq.motion.to_json(seq.frames), indent=1))
    jobs = _jobs(p, poses, parts, content, selection.frames)
    if scenes is not None:
        jobs = [j for j in jobs if _scene_of(j) in (None, *scenes)]
    cams = bar(rig.cameras, f"synth {p.name}: camera rays", unit="camera")
    rays = [camera_rays(c, p.width, p.height, p.supersample) for c in cams]
    args = [(root, rig, rays, p, job, seed, nuis, content.mask_mode) for job in jobs]
    views = bar(None, f"synth {p.name}", len(jobs), unit="view")
    _render_all(args, workers, views)
    views.close()


def _poses_json(names, poses) -> str:
    """True poses as JSON: name -> {"R": 3x3, "t": [3]} (world X = R X_board + t, metres)."""
    return json.dumps(
        {n: {"R": R.tolist(), "t": t.tolist()} for n, (R, t) in zip(names, poses, strict=True)}
    )


def _render_all(args, workers, bar):
    if workers <= 1:
        for a in args:
            _render_job(*a)
            bar.update()
    else:
        # Jobs hold closures, so workers are forked rather than spawned.
        global _ARGS
        _ARGS = args
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            for _ in pool.map(_render_indexed, range(len(args))):
                bar.update()
        _ARGS = None


_ARGS = None


@contextlib.contextmanager
def _single_threaded_blas():
    """Run the block with NumPy's bundled OpenBLAS on one thread, if it can be found.

    The renderer's (M, 3) x (3, 3) products are several times slower with
    OpenBLAS's threads (they compete with the worker processes for the cores);
    one thread gives the same results. Without a bundled OpenBLAS this does
    nothing.
    """
    lib = None
    try:
        libs = sorted((Path(np.__file__).parent.parent / "numpy.libs").glob("*openblas*.so*"))
        if libs:
            lib = ctypes.CDLL(str(libs[0]))
            get = lib.scipy_openblas_get_num_threads64_
            put = lib.scipy_openblas_set_num_threads64_
            before = int(get())
            put(1)
    except (OSError, AttributeError):
        lib = None
    try:
        yield
    finally:
        if lib is not None:
            put(before)


def _render_indexed(k: int) -> None:
    _render_job(*_ARGS[k])


def _render_job(root, rig, rays, p, job, seed, nuis, mask_mode="exact"):
    geom = job.geometry()
    scene = raycasting_scene(geom.vertices, geom.triangles)
    if job.gt_mesh:
        write_ply(root / job.gt_mesh, geom.vertices, geom.triangles, geom.vertex_normals)
    chroma_maps = {}
    for cam, cam_rays in zip(rig.cameras, rays, strict=True):
        hits = trace_camera(geom, scene, cam_rays)
        sens = cam.sensitivity(hits.xy[hits.sample])  # (M, 3)
        if job.frames:
            transports = {
                light.colour: light.radiance(hits.points)
                * light_transport(geom, scene, hits, light.position)[:, COLOURS.index(light.colour)]
                for light in rig.lights
            }
            signal = channel_signal(hits, cam, transports, sensitivity=sens)
            for rel in job.frames:
                _write_image(root, f"{rel}/{cam.name}.png", signal, seed, nuis, p)
        if job.chromatic:
            base = light_transport(geom, scene, hits, rig.chromatic_lights["red"].position)
            for colour, light in rig.chromatic_lights.items():
                T = light.radiance(hits.points) * base[:, COLOURS.index(colour)]
                signal = channel_signal(hits, cam, {colour: T}, cam.chromatic_crosstalk, sens)
                rel = f"{job.chromatic}/{colour}/{cam.name}.png"
                _write_image(root, rel, signal, seed, nuis, p)
        if job.mask:
            mask = _mask(hits.coverage(), mask_mode)
            path = root / f"{job.mask}/{cam.name}.png"
            path.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(path), mask)
        if job.gt_chroma:
            cov = hits.coverage()
            p_mean = hits.pixel_mean(hits.albedo / sc.WHITE_ALBEDO)
            with np.errstate(invalid="ignore", divide="ignore"):
                p_map = p_mean / cov[..., None]
            p_map[cov < 0.999] = np.nan
            chroma_maps[cam.name] = p_map.astype(np.float32)
    if job.gt_chroma:
        path = root / job.gt_chroma
        path.parent.mkdir(parents=True, exist_ok=True)
        with h5py.File(path, "w") as f:
            f.attrs["note"] = (
                "diffuse surface reflectance per light band relative to the white "
                "reference, (1, 1, 1) = white; pixel mean over fully covered pixels, NaN "
                "elsewhere; a white or metallic specular lobe is not in it"
            )
            for name, m in chroma_maps.items():
                f.create_dataset(name, data=m, compression="gzip")


def _mask(coverage: np.ndarray, mode: str) -> np.ndarray:
    """8-bit silhouette (0 / 255) from sample coverage: exact, or dilated / eroded by 1 px."""
    mask = (coverage >= 0.5).astype(np.uint8) * 255
    kernel = np.ones((3, 3), np.uint8)
    if mode == "dilated":
        mask = cv2.dilate(mask, kernel)
    elif mode == "eroded":
        mask = cv2.erode(mask, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    elif mode != "exact":
        raise ValueError(f"unknown mask mode {mode!r}")
    return mask


def _write_image(root, rel, signal, seed, nuis, p):
    rng = _image_rng(seed, rel)
    dn = sensor(signal, rng, nuis, p.bit_depth, p.black_level, _white_level(p))
    if dn.dtype.kind == "f":
        raise ValueError("datasets are written quantised: Nuisances.quantise must be on")
    write_png(root / rel, dn)
