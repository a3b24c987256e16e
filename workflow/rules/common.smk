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
