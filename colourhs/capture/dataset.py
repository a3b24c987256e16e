"""A validated dataset's types: :class:`Scene` and :class:`Dataset` (paths by name).

:class:`Dataset` is what :func:`colourhs.capture.layout.open_dataset` returns:
the rig plus the names of the photometric poses, chromatic objects and scenes,
with methods that turn names into the paths the format lays out; an unknown
name is an :class:`~colourhs.capture.base.UnknownNameError` naming the known
ones. Re-exported by :mod:`colourhs.capture`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from colourhs.capture.base import COLOURS, UnknownNameError
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
    """

    root: Path
    rig: Rig
    poses: tuple[str, ...]
    chromatic_objects: tuple[str, ...]
    scenes: dict[str, Scene]

    def scene(self, name: str) -> Scene:
        """The scene ``name``; :class:`UnknownNameError` naming the dataset's scenes."""
        _known(name, tuple(self.scenes), "scene")
        return self.scenes[name]

    def photometric_image(self, pose: str, camera: str) -> Path:
        """Path of ``photometric/<pose>/<camera>.png``."""
        _known(pose, self.poses, "photometric pose")
        self.rig.camera(camera)
        return self.root / "photometric" / pose / f"{camera}.png"

    def chromatic_image(self, obj: str, colour: str, camera: str) -> Path:
        """Path of ``chromatic/<obj>/<colour>/<camera>.png``."""
        _known(obj, self.chromatic_objects, "chromatic object")
        _known(colour, COLOURS, "colour")
        self.rig.camera(camera)
        return self.root / "chromatic" / obj / colour / f"{camera}.png"

    def frame_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """Path of ``scenes/<scene>/frames/<frame>/<camera>.png``; ``frame`` may be an int."""
        frame = self._frame(scene, frame)
        self.rig.camera(camera)
        return self.root / "scenes" / scene / "frames" / frame / f"{camera}.png"

    def mask_image(self, scene: str, frame: str | int, camera: str) -> Path:
        """Path of ``scenes/<scene>/masks/<frame>/<camera>.png``.

        Raises
        ------
        KeyError
            If the scene has no masks (or the scene, frame or camera is unknown).
        """
        frame = self._frame(scene, frame)
        if not self.scene(scene).has_masks:
            raise UnknownNameError(f"scene {scene!r} has no masks")
        self.rig.camera(camera)
        return self.root / "scenes" / scene / "masks" / frame / f"{camera}.png"

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


def _known(name: str, names: tuple[str, ...], what: str) -> None:
    if name not in names:
        raise UnknownNameError(f"unknown {what} {name!r}; known: {', '.join(names) or 'none'}")
