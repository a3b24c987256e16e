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
