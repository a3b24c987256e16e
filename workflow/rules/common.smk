import json
import shlex
import sys
from pathlib import Path

# Rules run the package with the Python that runs Snakemake (the project's
# venv); with `--sdm conda` with the Python of the rule's conda environment
# (workflow/envs/colourhs.yaml), which Snakemake activates before the command.
from snakemake_interface_executor_plugins.settings import DeploymentMethod

from colourhs.variants import VARIANTS, same_as  # the paper's ablation, one table

_settings = getattr(workflow, "deployment_settings", None)
if _settings is not None and DeploymentMethod.CONDA in _settings.deployment_method:
    shell.prefix("export COLOURHS_PYTHON=python; ")
else:
    shell.prefix(f"export COLOURHS_PYTHON={shlex.quote(sys.executable)}; ")
DATASETS = config.get("only") or list(config["datasets"])
_unknown = sorted(set(DATASETS) - set(config["datasets"]))
if _unknown:
    raise ValueError(f"config: `only` names unknown datasets {_unknown}")


SYNTH_ROOT = "data/synthetic"


def dataset_path(name):
    """The dataset folder of a configured dataset (synthetic ones: data/synthetic/<name>)."""
    entry = config["datasets"][name]
    if "synth" in entry:
        return f"{SYNTH_ROOT}/{name}"
    return entry["path"]


def dataset_root(name):
    """The dataset folder, once it exists (a synthetic one: after its checkpoint)."""
    if "synth" in config["datasets"][name]:
        return checkpoints.synth_dataset.get(name=name).output[0]
    return dataset_path(name)


def _files(name, pattern):
    """Sorted files of a dataset matching a glob pattern (inputs, so reruns follow them)."""
    return sorted(str(p) for p in Path(dataset_root(name)).glob(pattern))


def photometric_inputs(name):
    """rig.json and every photometric board image."""
    return _files(name, "rig.json") + _files(name, "photometric/*/*.png")


def chromatic_inputs(name, obj):
    """rig.json and one chromatic object's captures."""
    return _files(name, "rig.json") + _files(name, f"chromatic/{obj}/*/*.png")


def capture_files(name):
    """Every file of a dataset that validation reads (JSON metadata, images, masks, meshes)."""
    return sorted(
        set(_files(name, "rig.json"))
        | set(_files(name, "**/*.png"))
        | set(_files(name, "scenes/*/scene.json"))
        | set(_files(name, "scenes/*/gt/*.ply"))
    )


def chromaticity_inputs(name, obj):
    """What `colourhs chromaticity` reads: rig.json, the object's and the white
    reference's captures, every scene.json (to find the object's scene) and
    the first frame's masks of the scenes that show the object (its silhouette,
    chromaticity.object_silhouette)."""
    out = chromatic_inputs(name, obj) + _files(name, f"chromatic/white/*/*.png")
    out += _files(name, "scenes/*/scene.json")
    for scene, (frames, chromatic) in scene_info(name).items():
        if chromatic == obj and frames:
            out += _files(name, f"scenes/{scene}/masks/{frames[0]}/*.png")
    return out


def silhouette_inputs(name, scene, frame):
    """rig.json and a frame's masks; the frame's images when the scene has no masks."""
    masks = _files(name, f"scenes/{scene}/masks/{frame}/*.png")
    images = masks or _files(name, f"scenes/{scene}/frames/{frame}/*.png")
    return _files(name, "rig.json") + images


def frame_inputs(name, scene, frame):
    """rig.json, a frame's images and its silhouettes (when the scene has masks)."""
    return (
        _files(name, "rig.json")
        + _files(name, f"scenes/{scene}/frames/{frame}/*.png")
        + _files(name, f"scenes/{scene}/masks/{frame}/*.png")
    )


def gt_mesh(name, scene, frame):
    """The frame's ground-truth mesh as a list (empty without ground truth)."""
    return _files(name, f"scenes/{scene}/gt/{frame}.ply")


def synth_settings(name):
    """The dataset's `synth` entry."""
    entry = config["datasets"].get(name, {}).get("synth")
    if entry is None:
        raise ValueError(
            f"config: dataset {name!r} is not synthetic (no `synth` entry)"
        )
    return entry


for _name, _entry in config["datasets"].items():
    if "synth" in _entry and _entry.get("path", dataset_path(_name)) != dataset_path(
        _name
    ):
        raise ValueError(
            f"config: datasets.{_name}: a synthetic dataset lives at {dataset_path(_name)}; "
            "drop `path` or the `synth` entry"
        )
    if "synth" not in _entry and "path" not in _entry:
        raise ValueError(f"config: datasets.{_name}: needs `path` (or a `synth` entry)")


def _check_layout(name):
    """A path dataset's folders, rig.json and scene.json files against the capture
    format, before the jobs are planned (cheap: no image is opened; the images are
    checked by check_captures when the run starts)."""
    from colourhs.capture import CaptureFormatError, open_dataset

    try:
        open_dataset(dataset_path(name), check_images=False)
    except CaptureFormatError as e:
        raise ValueError(
            f"dataset {name!r} is malformed, no stage was run: {e}"
        ) from None


for _name in DATASETS:
    if "synth" not in config["datasets"][_name]:
        _check_layout(_name)


# Settings the config may leave out (the package's own defaults apply to the rest).
CALIBRATION_DEFAULTS = {"unmix_crosstalk": True, "photometric": {}, "chromaticity": {}}


def calibration(name):
    """Calibration settings of a dataset: defaults < config `calibration` < dataset's own."""
    out = {
        k: (dict(v) if isinstance(v, dict) else v)
        for k, v in CALIBRATION_DEFAULTS.items()
    }
    for layer in (
        config.get("calibration", {}),
        config["datasets"][name].get("calibration", {}),
    ):
        for key, value in layer.items():
            if isinstance(value, dict):
                out[key].update(value)
            else:
                out[key] = value
    return out


def unmix_crosstalk(name):
    return bool(calibration(name)["unmix_crosstalk"])


def photometric_options(name, crosstalk):
    """Command-line options of `colourhs photometric` (plain values, no arrays)."""
    opts = [f"--crosstalk {shlex.quote(crosstalk)}"] if crosstalk else []
    return " ".join(opts + [cli_options(calibration(name)["photometric"])])


def chromatic_objects(name):
    """Coloured objects of a dataset: folders of chromatic/ but `white`.

    A synthetic dataset not rendered yet has its preset's objects.
    """
    root = Path(dataset_path(name)) / "chromatic"
    if root.is_dir():
        return sorted(
            p.name for p in root.iterdir() if p.is_dir() and p.name != "white"
        )
    if "synth" in config["datasets"][name]:
        from colourhs.synth.dataset import SCENE_META

        return sorted({m["chromatic"] for m in SCENE_META.values() if m["chromatic"]})
    return []


def calibration_targets(name):
    out = [
        f"results/{name}/calib/marker_poses.csv",
        f"results/{name}/calib/photometric.h5",
        f"results/{name}/calib/noise.json",
    ]
    if unmix_crosstalk(name):
        out.append(f"results/{name}/calib/crosstalk.json")
    out += [
        f"results/{name}/calib/chromaticity/{obj}.h5" for obj in chromatic_objects(name)
    ]
    return out


def scene_info(name):
    """scene -> (frames, chromatic object) of a dataset, waiting for synthesis if needed."""
    root = Path(dataset_path(name))
    if "synth" in config["datasets"][name]:
        root = Path(checkpoints.synth_dataset.get(name=name).output[0])
    out = {}
    for sdir in sorted((root / "scenes").iterdir()):
        if not (sdir / "frames").is_dir():
            continue
        meta = {}
        if (sdir / "scene.json").exists():
            meta = json.loads((sdir / "scene.json").read_text())
        frames = sorted(p.name for p in (sdir / "frames").iterdir() if p.is_dir())
        out[sdir.name] = (frames, meta.get("chromatic"))
    return out


def selected_scenes(name):
    wanted = config.get("reconstruction", {}).get("scenes")
    info = scene_info(name)
    return {s: v for s, v in info.items() if not wanted or s in wanted}


def variant_calibration(name, scene, variant):
    """Calibration files a variant reads (inputs, so reruns follow their changes)."""
    v = VARIANTS[variant]
    out = {} if v["method"] == "vh" else {"noise": f"results/{name}/calib/noise.json"}
    if v["photometric"]:
        out["photometric"] = f"results/{name}/calib/photometric.h5"
        if unmix_crosstalk(name):
            out["crosstalk"] = f"results/{name}/calib/crosstalk.json"
    obj = scene_info(name)[scene][1]
    if v["chromaticity"] and obj:
        out["chromaticity"] = f"results/{name}/calib/chromaticity/{obj}.h5"
    return out


def reconstruct_options(name, scene, variant):
    """Command-line options of `colourhs reconstruct` (plain values)."""
    opts = [f"--method {VARIANTS[variant]['method']}"]
    for key, path in variant_calibration(name, scene, variant).items():
        opts.append(f"--{key} {shlex.quote(path)}")
    return " ".join(
        opts + [cli_options(config.get("reconstruction", {}).get("params", {}))]
    )


def same_result(name, scene, variant, frame, kind):
    """[the equal result of another variant] (colourhs.variants.same_as), or [].

    ``kind``: depth, mesh or eval (its JSON). On a scene without a chromatic
    object bayes_full equals bayes_ph: computed once, copied.
    """
    other = same_as(variant, bool(scene_info(name)[scene][1]))
    if other is None:
        return []
    ext = {"depth": "h5", "mesh": "ply", "eval": "json"}[kind]
    return [f"results/{name}/{scene}/{other}/{kind}/{frame}.{ext}"]


def same_option(input):
    """`--same-as PATH` when the rule's `same` input names an equal result."""
    return f"--same-as {shlex.quote(str(input.same))}" if input.same else ""


def hull_ply(name, scene, frame):
    """A frame's visual hull mesh (rule visual_hull)."""
    return f"results/{name}/{scene}/hull/{frame}.ply"


def reconstruction_hull(name, scene, frame):
    """The frame's visual hull as a list when the config takes the depth range from it."""
    if config.get("reconstruction", {}).get("depth_from_hull", False):
        return [hull_ply(name, scene, frame)]
    return []


def variants():
    return config.get("reconstruction", {}).get("variants") or list(VARIANTS)


def section(key):
    """A workflow config section (surfaces, evaluation), {} when absent."""
    return config.get(key) or {}


def mesh_uses_hull(variant):
    return variant == "vh" or bool(section("surfaces").get("mesh_with_hull", False))


def cli_options(values):
    """`--key value` options of the non-null entries of a dict (plain values, quoted):
    the one formatter of the config's options."""
    return " ".join(
        f"--{k.replace('_', '-')} {shlex.quote(str(v))}"
        for k, v in sorted(values.items())
        if v is not None
    )


def reconstruction_targets(name):
    out = []
    for scene, (frames, _) in selected_scenes(name).items():
        for variant in variants():
            out += [f"results/{name}/{scene}/{variant}/depth/{f}.h5" for f in frames]
    return out


def evaluation_targets(name):
    """Every frame's metrics JSON (which needs its mesh and depth)."""
    out = []
    for scene, (frames, _) in selected_scenes(name).items():
        for variant in variants():
            out += [f"results/{name}/{scene}/{variant}/eval/{f}.json" for f in frames]
    return out


def animation_variant():
    """The variant animated for a dynamic scene: the last of the configured ones."""
    return variants()[-1]


def figure_inputs(name, scene):
    """Depth files and meshes of a scene's first frame per variant, its ground truth,
    and the animated variant's meshes of every frame (dynamic scenes)."""
    frames = scene_info(name)[scene][0]
    f0 = frames[0]
    out = {
        "depth": [f"results/{name}/{scene}/{v}/depth/{f0}.h5" for v in variants()],
        "mesh": [f"results/{name}/{scene}/{v}/mesh/{f0}.ply" for v in variants()],
        "gt": gt_mesh(name, scene, f0),
        "animation": [],
        "coloured": [],
    }
    if out["gt"]:
        out["coloured"] = [
            f"results/{name}/{scene}/{v}/eval/{f0}.ply" for v in variants()
        ]
    if len(frames) > 1:
        a = animation_variant()
        out["animation"] = [f"results/{name}/{scene}/{a}/mesh/{f}.ply" for f in frames]
    return out


def figure_options(name, scene):
    """`colourhs figures` options: VARIANT=path pairs (plain strings)."""
    inp = figure_inputs(name, scene)
    frames = scene_info(name)[scene][0]
    opts = ["--depth"] + [f"{v}={p}" for v, p in zip(variants(), inp["depth"])]
    opts += ["--mesh"] + [f"{v}={p}" for v, p in zip(variants(), inp["mesh"])]
    if inp["gt"]:
        opts += ["--gt", inp["gt"][0]]
        opts += ["--coloured"] + [
            f"{v}={p}" for v, p in zip(variants(), inp["coloured"])
        ]
    if inp["animation"]:
        opts += ["--animate"] + [f"{f}={p}" for f, p in zip(frames, inp["animation"])]
    return shlex.join(opts)


def report_inputs(name):
    scenes = list(selected_scenes(name))
    return {
        "metrics": f"reports/{name}/metrics.csv",
        "config": f"results/{name}/config.yaml",
        "calibration": [
            f"results/{name}/calib/photometric.png",
            *[
                f"results/{name}/calib/chromaticity/{o}.png"
                for o in chromatic_objects(name)
            ],
        ],
        "figures": [f"reports/{name}/figures/{s}" for s in scenes],
    }


def report_targets(name):
    """The report, requested once the dataset's scenes are known (after synthesis)."""
    selected_scenes(name)
    return [f"reports/{name}/index.html"]


def unvalidated_captures():
    """Datasets (given by `path`) whose validation summary is missing or older than
    one of their capture files."""
    out = []
    for name in DATASETS:
        if "synth" in config["datasets"][name]:
            continue  # rendered by the workflow, then validated by its rule
        summary = Path(f"results/{name}/capture/summary.json")
        if not summary.exists():  # also a wrong path: validate names what is missing
            out.append(name)
        elif any(
            Path(f).stat().st_mtime > summary.stat().st_mtime
            for f in capture_files(name)
        ):
            out.append(name)
    return out


def check_captures():
    """Validate every path dataset that unvalidated_captures() names; a malformed
    one raises a WorkflowError with the validator's message (file and problem)."""
    from snakemake.exceptions import WorkflowError

    from colourhs.capture import CaptureFormatError, validate

    for name in unvalidated_captures():
        try:
            validate(dataset_path(name))
        except CaptureFormatError as e:
            raise WorkflowError(f"dataset {name!r} is malformed, no stage was run: {e}")
