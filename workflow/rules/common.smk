import json
import sys
from pathlib import Path

PYTHON = sys.executable
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


CALIBRATION_DEFAULTS = {
    "unmix_crosstalk": True,
    "photometric": {},
    "chromaticity": {"min_signal": 0.01},
}


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
    opts = [f"--crosstalk {crosstalk}"] if crosstalk else []
    for key, value in sorted(calibration(name)["photometric"].items()):
        if value is not None:
            opts.append(f"--{key.replace('_', '-')} {value}")
    return " ".join(opts)


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
    ]
    if unmix_crosstalk(name):
        out.append(f"results/{name}/calib/crosstalk.json")
    out += [
        f"results/{name}/calib/chromaticity/{obj}.h5" for obj in chromatic_objects(name)
    ]
    return out


# The paper's ablation (Figure 7) with the results contract's ids; `vh` comes
# with the surfaces stage.
VARIANTS = {
    "ml_full": {"method": "ml", "photometric": True, "chromaticity": True},
    "bayes_nocalib": {"method": "bayes", "photometric": False, "chromaticity": False},
    "bayes_ph": {"method": "bayes", "photometric": True, "chromaticity": False},
    "bayes_full": {"method": "bayes", "photometric": True, "chromaticity": True},
}


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
    out = {}
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
        opts.append(f"--{key} {path}")
    for key, value in sorted(
        config.get("reconstruction", {}).get("params", {}).items()
    ):
        if value is not None:
            opts.append(f"--{key.replace('_', '-')} {value}")
    return " ".join(opts)


def reconstruction_targets(name):
    variants = config.get("reconstruction", {}).get("variants") or list(VARIANTS)
    out = []
    for scene, (frames, _) in selected_scenes(name).items():
        for variant in variants:
            if variant in VARIANTS:
                out += [
                    f"results/{name}/{scene}/{variant}/depth/{f}.h5" for f in frames
                ]
    return out
