"""Command line: ``colourhs synth``, ``colourhs validate``, ``colourhs run``."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import yaml

from colourhs.capture import CaptureFormatError, validate

PROJECT_ROOT = Path(__file__).resolve().parents[1]
SNAKEFILE = PROJECT_ROOT / "Snakefile"
NUISANCE_SWITCHES = ("light_falloff", "vignetting", "crosstalk", "noise", "saturate")


def _synth(args) -> int:
    from colourhs.synth.dataset import PRESETS, synthesise
    from colourhs.synth.rig import Nuisances

    if args.preset not in PRESETS:
        print(f"colourhs synth: unknown preset {args.preset!r}; choose from {sorted(PRESETS)}")
        return 2
    nuisances = Nuisances().without(*args.off)
    try:
        synthesise(
            args.out,
            args.preset,
            seed=args.seed,
            nuisances=nuisances,
            overwrite=args.overwrite,
            workers=args.workers,
        )
    except FileExistsError as e:
        print(f"colourhs synth: {e}", file=sys.stderr)
        return 1
    print(f"wrote {args.out}")
    return 0


def _validate(args) -> int:
    try:
        summary = validate(args.dataset, args.summary)
    except CaptureFormatError as e:
        print(f"colourhs validate: invalid dataset: {e}", file=sys.stderr)
        return 1
    print(json.dumps(summary, indent=2))
    return 0


def _run(args) -> int:
    dataset = Path(args.dataset).resolve()
    if not (dataset / "rig.json").exists():
        print(f"colourhs run: {dataset / 'rig.json'}: missing (not a capture-format dataset)")
        return 2
    name = args.name or dataset.name
    config_path = Path(args.directory) / "results" / name / "run-config.yaml"
    config_path.parent.mkdir(parents=True, exist_ok=True)
    config = {"datasets": {name: {"path": str(dataset)}}, "only": [name]}
    config_path.write_text(yaml.safe_dump(config))
    cmd = [
        sys.executable, "-m", "snakemake", "--snakefile", str(SNAKEFILE),
        "--directory", str(Path(args.directory).resolve()), "--cores", str(args.cores),
        "--configfile", str(PROJECT_ROOT / "config.yaml"), str(config_path.resolve()),
    ] + list(args.snakemake_args)  # fmt: skip
    return subprocess.call(cmd)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="colourhs", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("synth", help="render a synthetic dataset in the capture format")
    s.add_argument("out", type=Path, help="dataset folder to create")
    s.add_argument("--preset", default="demo", help="tiny, demo or paper (default demo)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    s.add_argument(
        "--off", nargs="*", default=[], choices=NUISANCE_SWITCHES, help="nuisances to switch off"
    )
    s.set_defaults(func=_synth)

    v = sub.add_parser("validate", help="check a dataset against the capture format")
    v.add_argument("dataset", type=Path)
    v.add_argument("--summary", type=Path, default=None, help="write a JSON summary here")
    v.set_defaults(func=_validate)

    r = sub.add_parser("run", help="run the whole workflow on a dataset")
    r.add_argument("dataset", type=Path)
    r.add_argument("--name", default=None, help="results name (default: the folder's name)")
    r.add_argument("--cores", type=int, default=2)
    r.add_argument("--directory", default=".", help="where results/ and reports/ go")
    r.set_defaults(func=_run)
    r.epilog = "Arguments after `--` are passed on to snakemake."
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = []
    if "--" in argv:
        k = argv.index("--")
        argv, extra = argv[:k], argv[k + 1 :]
    args = build_parser().parse_args(argv)
    args.snakemake_args = extra
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
