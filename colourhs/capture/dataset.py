"""A validated dataset's types: :class:`Scene` and :class:`Dataset` (paths by name).

:class:`Dataset` is what :func:`colourhs.capture.layout.open_dataset` returns:
the rig plus the names of the photometric poses, chromatic objects, scenes and
geometric poses,
with methods that turn names into the paths the format lays out; an unknown
name is an :class:`~colourhs.capture.base.UnknownNameError` naming the known
ones. A capture image's file is PNG or TIFF (``<camera>.png``, ``.tif`` or
``.tiff``); :func:`capture_file` is the one place that resolves which, for
these methods and the layout's checks alike. Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from colourhs.capture.base import COLOURS, IMAGE_FORMATS, UnknownNameError
from colourhs.capture.rig import Rig


@dataclass(frozen=True)
class Scene:
    """One scene of a dataset.

    Attributes
    ----------
    name : str
        Folder name under ``scenes/``.
    frames : tuple of str
        Frame folder names (6 digits), ascending; gaps are allowed.
    chromatic : str or None
        Folder under ``chromatic/`` with the object's coloured captures; None for a white
        surface.
    chromatic_frame : str
        The frame (folder name) whose pose of the object the chromatic captures show:
        scene.json's ``chromatic_frame``, by default (and when None is given) the first
        frame. The paper calibrates the surface chromaticity p (eq. 4) per pixel in
        that pose; in any other frame of a moving object it no longer lies on those
        pixels.
    dynamic : bool
        True for a sequence of a moving or deforming surface. Without a scene.json, or without
        its ``dynamic`` key, a scene is dynamic unless its only frame is ``000000``.
    description : str
        Free text ("" when absent).
    has_masks : bool
        Whether ``masks/`` exists (then every frame has a mask per camera).
    has_gt : bool
        Whether ``gt/`` exists (then every frame has ``gt/<frame>.ply``).
    """

    name: str
    frames: tuple[str, ...]
    chromatic: str | None
    dynamic: bool
    description: str
    has_masks: bool
    has_gt: bool
    chromatic_frame: str | None = None

    def __post_init__(self) -> None:
        if self.chromatic_frame is None and self.frames:
            object.__setattr__(self, "chromatic_frame", self.frames[0])


@dataclass(frozen=True, eq=False)
class Dataset:
    """A validated dataset: rig plus the names of everything captured.

    Attributes
    ----------
    root : Path
        The dataset folder.
    rig : Rig
        Contents of rig.json.
    poses : tuple of str
        Photometric board poses (folder names under ``photometric/``), ascending.
    chromatic_objects : tuple of str
        Folders under ``chromatic/`` (``"white"`` included when present), ascending.
    scenes : dict of str to Scene
        Scenes by name, ascending.
    geometric_poses : tuple of str
        Poses of the ChArUco target (folder names under ``geometric/``), ascending;
        empty without ``geometric/``.
    """

    root: Path
    rig: Rig
    poses: tuple[str, ...]
    chromatic_objects: tuple[str, ...]
    scenes: dict[str, Scene]
    geometric_poses: tuple[str, ...] = ()

    def scene(self, name: str) -> Scene:
        """The scene ``name``; :class:`UnknownNameError` naming the dataset's scenes."""
        _known(name, tuple(self.scenes), "scene")
        return self.scenes[name]

    def photometric_image(self, pose: str, camera: str) -> Path:
        """File of ``photometric/<pose>/<camera>.png`` (or ``.tif``: :func:`capture_file`)."""
        _known(pose, self.poses, "photometric pose")
        self.rig.camera(camera)
        return capture_file(self.root / "photometric" / pose, camera)

    def geometric_image(self, pose: str, camera: str) -> Path:
        """File of ``geometric/<pose>/<camera>.png`` (or ``.tif``: :func:`capture_file`),
        a view of the ChArUco target ``rig.geometric_board``."""
        _known(pose, self.geometric_poses, "geometric pose")
        self.rig.camera(camera)
        return capture_file(self.root / "geometric" / pose, camera)

    def chromatic_image(self, obj: str, colour: str, camera: str) -> Path:
        """File of ``chromatic/<obj>/<colour>/<camera>.png`` (or ``.tif``: :func:`capture_file`)."""
        _known(obj, self.chromatic_objects, "chromatic object")
        _known(colour, COLOURS, "colour")
        self.rig.camera(camera)
        return capture_file(self.root / "chromatic" / obj / colour, camera)

    def frame_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """File of ``scenes/<scene>/frames/<frame>/<camera>.png`` (or ``.tif``:
        :func:`capture_file`); ``frame`` may be an int."""
        frame = self._frame(scene, frame)
        self.rig.camera(camera)
        return capture_file(self.root / "scenes" / scene / "frames" / frame, camera)

    def mask_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """File of ``scenes/<scene>/masks/<frame>/<camera>.png`` (or ``.tif``:
        :func:`capture_file`).

        Raises
        ------
        KeyError
            If the scene has no masks (or the scene, frame or camera is unknown).
        """
        frame = self._frame(scene, frame)
        if not self.scene(scene).has_masks:
            raise UnknownNameError(f"scene {scene!r} has no masks")
        self.rig.camera(camera)
        return capture_file(self.root / "scenes" / scene / "masks" / frame, camera)

    def gt_mesh(self, scene: str, frame: str | int) -> Path:
        """Path of ``scenes/<scene>/gt/<frame>.ply``.

        Raises
        ------
        KeyError
            If the scene has no ground truth (or the scene or frame is unknown).
        """
        frame = self._frame(scene, frame)
        if not self.scene(scene).has_gt:
            raise UnknownNameError(f"scene {scene!r} has no ground-truth meshes")
        return self.root / "scenes" / scene / "gt" / f"{frame}.ply"

    @property
    def gt_photometric(self) -> Path | None:
        """Path of ``gt/photometric.h5`` when the dataset has it, else None."""
        path = self.root / "gt" / "photometric.h5"
        return path if path.is_file() else None

    def _frame(self, scene: str, frame: str | int) -> str:
        _known(scene, tuple(self.scenes), "scene")
        name = f"{frame:06d}" if isinstance(frame, int) else frame
        _known(name, self.scenes[scene].frames, f"frame of scene {scene!r}")
        return name


def capture_files(folder: Path, camera: str) -> list[Path]:
    """The files of ``camera``'s capture in ``folder`` that exist, in the order of
    :data:`~colourhs.capture.base.IMAGE_FORMATS` (``.png``, ``.tif``, ``.tiff``).

    A valid dataset has exactly one; more is a format error that the layout's
    check reports, naming them all.
    """
    paths = (folder / f"{camera}{suffix}" for suffix in IMAGE_FORMATS)
    return [path for path in paths if path.is_file()]


def capture_file(folder: Path, camera: str) -> Path:
    """The file of ``camera``'s capture image (or mask) in ``folder``.

    The format takes a capture as PNG or TIFF, per file: ``<camera>.png``,
    ``<camera>.tif`` or ``<camera>.tiff``, lower case (a dataset may mix them).
    Every reader of a capture's path goes through here.

    Returns
    -------
    Path
        The one of :func:`capture_files` (the first, where a malformed dataset has
        several); ``<camera>.png`` where none exists, the name a missing capture is
        reported under.
    """
    found = capture_files(folder, camera)
    return found[0] if found else folder / f"{camera}{next(iter(IMAGE_FORMATS))}"


def _known(name: str, names: tuple[str, ...], what: str) -> None:
    if name not in names:
        raise UnknownNameError(f"unknown {what} {name!r}; known: {', '.join(names) or 'none'}")
