"""The Snakemake workflow's plan: datasets, targets, input files and command-line options.

``workflow/rules/common.smk`` makes one :class:`WorkflowPlan` of the run's config
(validated against ``workflow/schemas/config.schema.yaml`` by the Snakefile, which
fills in the schema's defaults) and the rules call its methods: the files a job
reads (its inputs, so that reruns follow them; listed by
:func:`colourhs.capture.open_dataset`, the one reader of the capture format), the
files a stage makes (the templates of :mod:`colourhs.workflow.paths`, filled in),
and the options of the ``colourhs`` subcommands (plain strings, quoted for the shell).

A synthetic dataset (a ``synth`` entry) is rendered by the workflow's checkpoint
into ``data/synthetic/<name>``: until then ``wait(name)`` raises Snakemake's
IncompleteCheckpointException, and only its preset's chromatic objects are known
(:meth:`WorkflowPlan.chromatic_objects`).
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from colourhs.capture import COLOURS, CaptureFormatError, Dataset, all_images, open_dataset
from colourhs.capture import validate as validate_dataset
from colourhs.workflow.paths import (
    CAPTURE_SUMMARY,
    CHROMATICITY,
    CHROMATICITY_PNG,
    CONFIG,
    CROSSTALK,
    FIGURES,
    FRAME_RESULTS,
    HULL,
    MARKER_POSES,
    METRICS,
    NOISE,
    PHOTOMETRIC,
    PHOTOMETRIC_PNG,
    REPORT,
    RIG,
    SYNTH_DATASET,
    TRACKED_CHROMATICITY,
    fill,
)
from colourhs.workflow.variants import (  # noqa: F401 (rules)
    HS_VARIANT_PATTERN,
    PAPER_VARIANTS,
    VARIANTS,
    same_as,
)


class MalformedDatasetError(ValueError):
    """A configured dataset breaks the capture format: no stage was run."""

    def __init__(self, name: str, error: CaptureFormatError) -> None:
        super().__init__(f"dataset {name!r} is malformed, no stage was run: {error}")


def cli_options(values: dict) -> str:
    """``--key value`` options of the non-null entries of a dict (plain values, quoted):
    the one formatter of the config's options."""
    return " ".join(
        f"--{k.replace('_', '-')} {shlex.quote(str(v))}"
        for k, v in sorted(values.items())
        if v is not None
    )


def same_option(input) -> str:
    """``--same-as PATH`` when the rule's ``same`` input names an equal result."""
    return f"--same-as {shlex.quote(str(input.same))}" if input.same else ""


def _paths(paths: Iterable[Path]) -> list[str]:
    """Path strings, sorted."""
    return sorted(str(p) for p in paths)


def _chromatic_images(ds: Dataset, obj: str) -> list[Path]:
    """A chromatic object's captures (every colour and camera); [] when it has no folder."""
    if obj not in ds.chromatic_objects:
        return []
    cams = ds.rig.camera_names
    return [ds.chromatic_image(obj, colour, c) for colour in COLOURS for c in cams]


def _scene_jsons(ds: Dataset) -> list[Path]:
    """The scenes' scene.json files (optional in the format)."""
    paths = (ds.root / "scenes" / s / "scene.json" for s in ds.scenes)
    return [p for p in paths if p.is_file()]


@dataclass
class WorkflowPlan:
    """The jobs' inputs, targets and options for one run's config.

    Parameters
    ----------
    config : dict
        The workflow config, validated with the schema's defaults set.
    wait : callable
        ``wait(name)``: the folder of synthetic dataset ``name`` once its checkpoint has
        rendered it (raises Snakemake's IncompleteCheckpointException before).

    Attributes
    ----------
    datasets : list of str
        The datasets to process: the config's ``only``, else every configured one.
    """

    config: dict
    wait: Callable[[str], str]
    datasets: list[str] = field(init=False)
    _layouts: dict[str, Dataset] = field(init=False, default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        entries = self.config["datasets"]
        self.datasets = self.config.get("only") or list(entries)
        unknown = sorted(set(self.datasets) - set(entries))
        if unknown:
            raise ValueError(f"config: `only` names unknown datasets {unknown}")
        for name, entry in entries.items():
            path = self.dataset_path(name)
            if self.synthetic(name) and entry.get("path", path) != path:
                raise ValueError(
                    f"config: datasets.{name}: a synthetic dataset lives at {path}; "
                    "drop `path` or the `synth` entry"
                )

    # ---------------------------------------------------------------- datasets

    def synthetic(self, name: str) -> bool:
        """Whether the workflow renders the dataset (a ``synth`` entry)."""
        return "synth" in self.config["datasets"][name]

    def dataset_path(self, name: str) -> str:
        """The dataset folder (a synthetic one: data/synthetic/<name>)."""
        if self.synthetic(name):
            return fill(SYNTH_DATASET, name=name)
        return self.config["datasets"][name]["path"]

    def synth_settings(self, name: str) -> dict:
        """The dataset's ``synth`` entry (preset, seed) and ``parts``, the captures to
        render: the geometric ones only where :meth:`calibrates_rig` (they cost render
        time and nothing else reads them)."""
        entry = self.config["datasets"].get(name, {}).get("synth")
        if entry is None:
            raise ValueError(f"config: dataset {name!r} is not synthetic (no `synth` entry)")
        from colourhs.synth.synthesise import PARTS

        parts = [p for p in PARTS if p != "geometric" or self.calibrates_rig(name)]
        return {**entry, "parts": ",".join(parts)}

    def _open(self, name: str, root: str) -> Dataset:
        """open_dataset(root) without opening an image, once per folder."""
        if root not in self._layouts:
            try:
                self._layouts[root] = open_dataset(root, check_images=False)
            except CaptureFormatError as e:
                raise MalformedDatasetError(name, e) from None
        return self._layouts[root]

    def layout(self, name: str) -> Dataset:
        """The dataset's rig, poses, chromatic objects and scenes (a synthetic one: once
        rendered); :class:`MalformedDatasetError` when its folders or JSON files break
        the capture format (images are checked by :meth:`check_captures`)."""
        root = self.wait(name) if self.synthetic(name) else self.dataset_path(name)
        return self._open(name, root)

    def check_layouts(self) -> None:
        """Check the layout of every dataset to process that exists before the run
        (given by ``path``), before any job is planned."""
        for name in self.datasets:
            if not self.synthetic(name):
                self.layout(name)

    def unvalidated_captures(self) -> list[str]:
        """Datasets (given by ``path``) whose validation summary is missing or older than
        one of their capture files."""
        out = []
        for name in self.datasets:
            if self.synthetic(name):
                continue  # rendered by the workflow, then validated by its rule
            summary = Path(fill(CAPTURE_SUMMARY, name=name))
            if not summary.exists():
                out.append(name)
            elif any(
                Path(f).stat().st_mtime > summary.stat().st_mtime for f in self.capture_files(name)
            ):
                out.append(name)
        return out

    def check_captures(self) -> None:
        """Validate (every image decoded, rig.json checked against the photometric
        captures: :func:`colourhs.calibration.rig_check.validate_rig`) each dataset
        :meth:`unvalidated_captures` names; :class:`MalformedDatasetError` with the
        validator's message (file and problem).
        What is valid but costs accuracy (the summary's ``warnings``) goes to stderr."""
        from colourhs.calibration.rig_check import validate_rig  # cv2 only when needed

        for name in self.unvalidated_captures():
            try:
                summary = validate_dataset(self.dataset_path(name))
                if not self.calibrates_rig(name):  # else rule calibrate_rig checks its rig
                    validate_rig(self._open(name, self.dataset_path(name)))
            except CaptureFormatError as e:
                raise MalformedDatasetError(name, e) from None
            for warning in summary["warnings"]:
                print(f"colourhs: dataset {name}: warning: {warning}", file=sys.stderr)

    def chromatic_objects(self, name: str) -> list[str]:
        """Coloured objects of a dataset: its chromatic objects but ``white``.

        Known before the run: a synthetic dataset not rendered yet has its preset's
        objects.
        """
        if Path(self.dataset_path(name)).is_dir():
            objects = self._open(name, self.dataset_path(name)).chromatic_objects
            return [obj for obj in objects if obj != "white"]
        if self.synthetic(name):
            from colourhs.synth.synthesise import preset_chromatic_objects

            return preset_chromatic_objects(self.synth_settings(name)["preset"])
        return []

    def selected_scenes(self, name: str) -> dict:
        """Scene name -> :class:`colourhs.capture.Scene` of the config's
        ``reconstruction.scenes`` (null: every scene)."""
        wanted = self.config["reconstruction"]["scenes"]
        scenes = self.layout(name).scenes
        return {s: scene for s, scene in scenes.items() if not wanted or s in wanted}

    # ---------------------------------------------------------------- input files

    def capture_files(self, name: str) -> list[str]:
        """Every file of a dataset that validation reads (JSON metadata, images, masks,
        meshes)."""
        ds = self.layout(name)
        gt = [ds.gt_mesh(s, f) for s, sc in ds.scenes.items() if sc.has_gt for f in sc.frames]
        return _paths({ds.rig.path, *all_images(ds), *_scene_jsons(ds), *gt})

    def rig_file(self, name: str) -> str:
        """The rig.json the stages read: the calibrated one (:data:`RIG`) where
        :meth:`calibrates_rig`, else the dataset's own."""
        if self.calibrates_rig(name):
            return fill(RIG, name=name)
        return str(self.layout(name).rig.path)

    def rig_option(self, name: str) -> str:
        """``--rig PATH`` (quoted) where the stages read the calibrated rig, else ""."""
        return f"--rig {shlex.quote(self.rig_file(name))}" if self.calibrates_rig(name) else ""

    def geometric_inputs(self, name: str) -> list[str]:
        """What ``colourhs calibrate-rig`` reads: the dataset's rig.json (the base it
        merges into), every geometric capture and the photometric captures (the
        calibrated rig is checked against them); a MalformedDatasetError where the
        dataset has no geometric captures."""
        ds = self.layout(name)
        cams = ds.rig.camera_names
        if not ds.geometric_poses:
            hint = f" (remove {ds.root} to render them)" if self.synthetic(name) else ""
            raise MalformedDatasetError(
                name,
                CaptureFormatError(
                    Path(ds.root) / "geometric",
                    "calibration.calibrate_rig is on but the dataset has no geometric "
                    f"captures (geometric/<pose>/<camera>.png){hint}",
                ),
            )
        images = [ds.geometric_image(p, c) for p in ds.geometric_poses for c in cams]
        images += [ds.photometric_image(p, c) for p in ds.poses for c in cams]
        return [str(ds.rig.path)] + _paths(images)

    def photometric_inputs(self, name: str) -> list[str]:
        """The rig.json the stages read (:meth:`rig_file`) and every photometric board
        image."""
        ds = self.layout(name)
        cams = ds.rig.camera_names
        images = [ds.photometric_image(pose, c) for pose in ds.poses for c in cams]
        return [self.rig_file(name)] + _paths(images)

    def chromatic_inputs(self, name: str, obj: str) -> list[str]:
        """The rig.json the stages read and one chromatic object's captures."""
        ds = self.layout(name)
        return [self.rig_file(name)] + _paths(_chromatic_images(ds, obj))

    def chromaticity_inputs(self, name: str, obj: str) -> list[str]:
        """What ``colourhs chromaticity`` reads: rig.json, the object's and the white
        reference's captures, every scene.json (to find the object's scene) and the
        chromatic frame's masks of the scenes that show the object (its silhouette,
        chromaticity.object_silhouette)."""
        ds = self.layout(name)
        out = self.chromatic_inputs(name, obj) + _paths(_chromatic_images(ds, "white"))
        out += _paths(_scene_jsons(ds))
        for s, scene in ds.scenes.items():
            if scene.chromatic == obj and scene.has_masks:
                frame = scene.chromatic_frame
                masks = [ds.mask_image(s, frame, c) for c in ds.rig.camera_names]
                out += _paths(masks)
        return out

    def _scene_files(self, name: str, scene: str) -> list[str]:
        """The rig.json the stages read and the scene's scene.json when it has one."""
        meta = Path(self.layout(name).root) / "scenes" / scene / "scene.json"
        return [self.rig_file(name)] + ([str(meta)] if meta.exists() else [])

    def silhouette_inputs(self, name: str, scene: str, frame: str) -> list[str]:
        """rig.json, the scene's scene.json (read when the dataset is opened) and a
        frame's masks; the frame's images when the scene has no masks."""
        ds = self.layout(name)
        image = ds.mask_image if ds.scene(scene).has_masks else ds.frame_image
        cams = ds.rig.camera_names
        return self._scene_files(name, scene) + _paths(image(scene, frame, c) for c in cams)

    def frame_inputs(self, name: str, scene: str, frame: str) -> list[str]:
        """rig.json, the scene's scene.json (read when the dataset is opened), a
        frame's images and its silhouettes (when the scene has masks)."""
        ds = self.layout(name)
        cams = ds.rig.camera_names
        out = self._scene_files(name, scene)
        out += _paths(ds.frame_image(scene, frame, c) for c in cams)
        if ds.scene(scene).has_masks:
            out += _paths(ds.mask_image(scene, frame, c) for c in cams)
        return out

    def gt_mesh(self, name: str, scene: str, frame: str) -> list[str]:
        """The frame's ground-truth mesh as a list (empty without ground truth)."""
        ds = self.layout(name)
        return [str(ds.gt_mesh(scene, frame))] if ds.scene(scene).has_gt else []

    # ---------------------------------------------------------------- calibration

    def calibration(self, name: str) -> dict:
        """Calibration settings of a dataset: the config's ``calibration`` (with the
        schema's defaults) < the dataset's own (which overrides only what it names)."""
        out = {
            k: (dict(v) if isinstance(v, dict) else v)
            for k, v in self.config["calibration"].items()
        }
        for key, value in self.config["datasets"][name].get("calibration", {}).items():
            out[key] = {**out.get(key, {}), **value} if isinstance(value, dict) else value
        return out

    def calibrates_rig(self, name: str) -> bool:
        """Whether the stages read a rig calibrated from the dataset's geometric captures
        (calibration.calibrate_rig) instead of its rig.json."""
        return bool(self.calibration(name).get("calibrate_rig", False))

    def unmix_crosstalk(self, name: str) -> bool:
        """Whether the dataset's images are unmixed (calibration.unmix_crosstalk)."""
        return bool(self.calibration(name)["unmix_crosstalk"])

    def crosstalk_file(self, name: str) -> list[str]:
        """[the cross-talk calibration] when the dataset's images are unmixed, else []."""
        return [fill(CROSSTALK, name=name)] if self.unmix_crosstalk(name) else []

    def photometric_options(self, name: str) -> str:
        """Command-line options of ``colourhs photometric`` (plain values, no arrays):
        the cross-talk calibration the rule reads (:meth:`crosstalk_file`) and the
        dataset's photometric settings."""
        opts = [f"--crosstalk {shlex.quote(p)}" for p in self.crosstalk_file(name)]
        return " ".join(opts + [cli_options(self.calibration(name)["photometric"])])

    def calibration_targets(self, name: str) -> list[str]:
        """The dataset's calibration files (known before the run, synthetic or not)."""
        out = [fill(t, name=name) for t in (MARKER_POSES, PHOTOMETRIC, NOISE)]
        out += [fill(RIG, name=name)] if self.calibrates_rig(name) else []
        out += self.crosstalk_file(name)
        out += [fill(CHROMATICITY, name=name, object=o) for o in self.chromatic_objects(name)]
        return out

    # ---------------------------------------------------------------- reconstruction

    def variants(self, name: str) -> list[str]:
        """The config's variants; null: the paper's, in its order, and ``bayes_dyn`` where
        a selected scene of the dataset carries its chromaticity frame to frame
        (:meth:`tracks_chromaticity`; elsewhere it would only copy ``bayes_full``)."""
        chosen = self.config["reconstruction"]["variants"]
        if chosen:
            return list(chosen)
        moving = any(self.tracks_chromaticity(name, s) for s in self.selected_scenes(name))
        return list(VARIANTS) if moving else list(PAPER_VARIANTS)

    def variant_calibration(
        self, name: str, scene: str, variant: str, frame: str | None = None
    ) -> dict:
        """Calibration files a variant reads (inputs, so reruns follow their changes); a
        tracked chromaticity (``bayes_dyn`` on a moving scene) is the frame's own."""
        v = VARIANTS[variant]
        out = {} if v["method"] == "vh" else {"noise": fill(NOISE, name=name)}
        if v["photometric"]:
            out["photometric"] = fill(PHOTOMETRIC, name=name)
            for path in self.crosstalk_file(name):
                out["crosstalk"] = path
        obj = self.layout(name).scene(scene).chromatic
        if v["chromaticity"] and obj:
            out["chromaticity"] = fill(CHROMATICITY, name=name, object=obj)
        if v.get("tracked") and self.tracks_chromaticity(name, scene):
            if frame is None:
                raise ValueError(f"{variant} on {scene}: its chromaticity is the frame's")
            out["chromaticity"] = fill(TRACKED_CHROMATICITY, name=name, scene=scene, frame=frame)
        return out

    def tracks_chromaticity(self, name: str, scene: str) -> bool:
        """Whether a scene's chromaticity is carried frame to frame (a chromatic object
        in a sequence of several frames: :func:`colourhs.workflow.variants.same_as`)."""
        sc = self.layout(name).scene(scene)
        return bool(sc.chromatic) and len(sc.frames) > 1

    def tracking_inputs(self, name: str, scene: str, frame: str) -> dict:
        """What ``colourhs track-chromaticity`` reads for a frame: the rig.json and
        scene.json, the images of the frame, of its neighbour towards the chromatic
        frame and of the chromatic frame, the object's calibrated maps and the
        neighbour's tracked maps (none for the chromatic frame: the chain starts there)."""
        from colourhs.calibration.chromaticity_tracking import tracking_neighbour

        ds = self.layout(name)
        sc = ds.scene(scene)
        neighbour = tracking_neighbour(sc.frames, sc.chromatic_frame, frame)
        frames = dict.fromkeys(f for f in (frame, neighbour, sc.chromatic_frame) if f)
        cams = ds.rig.camera_names
        images = [ds.frame_image(scene, f, c) for f in frames for c in cams]
        out = {
            "images": self._scene_files(name, scene) + _paths(images),
            "calibrated": fill(CHROMATICITY, name=name, object=sc.chromatic),
        }
        if neighbour is not None:
            out["neighbour"] = fill(TRACKED_CHROMATICITY, name=name, scene=scene, frame=neighbour)
        return out

    def reconstruct_options(
        self, name: str, scene: str, variant: str, frame: str | None = None
    ) -> str:
        """Command-line options of ``colourhs reconstruct`` (plain values)."""
        opts = [f"--method {VARIANTS[variant]['method']}"]
        for key, path in self.variant_calibration(name, scene, variant, frame).items():
            opts.append(f"--{key} {shlex.quote(path)}")
        return " ".join(opts + [cli_options(self.config["reconstruction"]["params"])])

    def reconstruction_hull(self, name: str, scene: str, frame: str) -> list[str]:
        """The frame's visual hull as a list when the config takes the depth range from
        it (reconstruction.depth_from_hull)."""
        if self.config["reconstruction"]["depth_from_hull"]:
            return [fill(HULL, name=name, scene=scene, frame=frame)]
        return []

    def same_result(self, name: str, scene: str, variant: str, frame: str, kind: str) -> list:
        """[the equal result of another variant] (colourhs.workflow.variants.same_as), or [].

        ``kind``: a key of :data:`colourhs.workflow.paths.FRAME_RESULTS` (depth, mesh,
        eval: the metrics JSON, coloured: the error-coloured mesh). On a scene without a
        chromatic object bayes_full equals bayes_ph: computed once, copied.
        """
        other = same_as(
            variant,
            bool(self.layout(name).scene(scene).chromatic),
            self.tracks_chromaticity(name, scene),
        )
        if other is None:
            return []
        return [self._frame_result(kind, name, scene, other, frame)]

    def mesh_uses_hull(self, variant: str) -> bool:
        """Whether a variant's meshes are closed with hull points (always for vh)."""
        return variant == "vh" or bool(self.config["surfaces"]["mesh_with_hull"])

    def mesh_hull(self, name: str, scene: str, variant: str, frame: str) -> list[str]:
        """The frame's visual hull as a list when the variant's mesh is closed with it
        (:meth:`mesh_uses_hull`)."""
        if self.mesh_uses_hull(variant):
            return [fill(HULL, name=name, scene=scene, frame=frame)]
        return []

    @staticmethod
    def _frame_result(kind: str, name: str, scene: str, variant: str, frame: str) -> str:
        """One frame's result of one variant (``kind``: a key of FRAME_RESULTS)."""
        return fill(FRAME_RESULTS[kind], name=name, scene=scene, variant=variant, frame=frame)

    def _frame_results(self, name: str, kind: str) -> list[str]:
        """One result per selected scene, variant and frame."""
        return [
            self._frame_result(kind, name, s, v, f)
            for s, scene in self.selected_scenes(name).items()
            for v in self.variants(name)
            for f in scene.frames
        ]

    def reconstruction_targets(self, name: str) -> list[str]:
        """Every selected frame's depth file per variant."""
        return self._frame_results(name, "depth")

    def evaluation_targets(self, name: str) -> list[str]:
        """Every frame's metrics JSON (which needs its mesh and depth)."""
        return self._frame_results(name, "eval")

    # ---------------------------------------------------------------- report

    def animation_variant(self, name: str) -> str:
        """The variant animated for a dynamic scene: the last of the dataset's."""
        return self.variants(name)[-1]

    def figure_inputs(self, name: str, scene: str) -> dict:
        """Depth files and meshes of a scene's first frame per variant, its ground truth,
        the animated variant's meshes of every frame (dynamic scenes), with ground
        truth the first frame's error-coloured meshes and the metrics JSON beside each
        (``scale``: its colour scale's top) and, where the scene's chromaticity is
        tracked and ``bayes_dyn`` is among the variants, every frame's tracked maps
        (``chromaticity``), the object's calibrated maps and the dataset's true maps
        per frame where it has them (``gt_chromaticity``)."""
        frames = self.layout(name).scene(scene).frames
        f0, variants = frames[0], self.variants(name)

        def first(kind: str) -> list[str]:
            return [self._frame_result(kind, name, scene, v, f0) for v in variants]

        gt = self.gt_mesh(name, scene, f0)
        out = {
            "depth": first("depth"),
            "mesh": first("mesh"),
            "gt": gt,
            "animation": [],
            "coloured": first("coloured") if gt else [],
            "scale": first("eval") if gt else [],
        }
        if len(frames) > 1:
            a = self.animation_variant(name)
            out["animation"] = [self._frame_result("mesh", name, scene, a, f) for f in frames]
        out |= {"chromaticity": [], "calibrated_chromaticity": [], "gt_chromaticity": []}
        tracked = any(VARIANTS[v].get("tracked") for v in variants)
        if tracked and self.tracks_chromaticity(name, scene):
            ds, obj = self.layout(name), self.layout(name).scene(scene).chromatic
            out["chromaticity"] = [
                fill(TRACKED_CHROMATICITY, name=name, scene=scene, frame=f) for f in frames
            ]
            out["calibrated_chromaticity"] = [fill(CHROMATICITY, name=name, object=obj)]
            truth = [
                Path(ds.root) / "scenes" / scene / "gt" / "chromaticity" / f"{f}.h5" for f in frames
            ]
            if all(p.is_file() for p in truth):
                out["gt_chromaticity"] = _paths(truth)
        return out

    def figure_options(self, name: str, scene: str) -> str:
        """``colourhs figures`` options: VARIANT=path pairs (plain strings)."""
        inp = self.figure_inputs(name, scene)
        frames, variants = self.layout(name).scene(scene).frames, self.variants(name)
        opts = ["--depth"] + [f"{v}={p}" for v, p in zip(variants, inp["depth"], strict=True)]
        opts += ["--mesh"] + [f"{v}={p}" for v, p in zip(variants, inp["mesh"], strict=True)]
        if inp["gt"]:
            opts += ["--gt", inp["gt"][0], "--coloured"]
            opts += [f"{v}={p}" for v, p in zip(variants, inp["coloured"], strict=True)]
        if inp["animation"]:
            opts += ["--animate"]
            opts += [f"{f}={p}" for f, p in zip(frames, inp["animation"], strict=True)]
        for key in ("chromaticity", "gt_chromaticity"):
            if inp[key]:
                opts += ["--" + key.replace("_", "-")]
                opts += [f"{f}={p}" for f, p in zip(frames, inp[key], strict=True)]
        if inp["calibrated_chromaticity"]:
            opts += ["--calibrated-chromaticity", inp["calibrated_chromaticity"][0]]
        return shlex.join(opts)

    def report_inputs(self, name: str) -> dict:
        """The report's metrics table, recorded config, calibration figures, the
        selected scenes' figure folders, the dataset's rig.json and scene.json, the
        calibration files its diagnostics read (:mod:`colourhs.report.calibration`: marker
        poses, cross-talk, photometric maps, and the dataset's true mu maps where it
        has them) and each scene's first-frame error-coloured meshes (its 3D view,
        :mod:`colourhs.report.view3d`)."""
        objects = self.chromatic_objects(name)
        calib = [fill(MARKER_POSES, name=name), fill(PHOTOMETRIC, name=name)]
        calib += self.crosstalk_file(name)
        truth = self.layout(name).gt_photometric
        scenes = self.selected_scenes(name)
        views = [
            self._frame_result("coloured", name, s, v, meta.frames[0])
            for s, meta in scenes.items()
            for v in self.variants(name)
        ]
        return {
            "metrics": fill(METRICS, name=name),
            "config": fill(CONFIG, name=name),
            "calibration": [
                fill(PHOTOMETRIC_PNG, name=name),
                *[fill(CHROMATICITY_PNG, name=name, object=o) for o in objects],
            ],
            "figures": [fill(FIGURES, name=name, scene=s) for s in scenes],
            # rig.json and every scene.json: the rig and scene summaries.
            "dataset": self._dataset_files(name),
            "calib": calib + ([str(truth)] if truth else []),
            "views": views,
        }

    def _dataset_files(self, name: str) -> list[str]:
        """The rig.json the stages read and the scene.json of every scene (what opening
        the dataset reads)."""
        ds = self.layout(name)
        out = [self.rig_file(name)]
        for scene in ds.scenes:
            meta = Path(ds.root) / "scenes" / scene / "scene.json"
            out += [str(meta)] if meta.exists() else []
        return out

    def report_targets(self, name: str) -> list[str]:
        """The report, requested once the dataset's scenes are known (after synthesis)."""
        self.selected_scenes(name)
        return [fill(REPORT, name=name)]
