"""rig.json's JSON Schema, colourhs/capture/rig.schema.json.

The schema is the format's machine-readable spec and the reader's first check;
tests/capture/test_capture_rig.py holds the reader's malformed-rig cases, one message each.
"""

from __future__ import annotations

import json
import tomllib
from fnmatch import fnmatch
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from rig_examples import contract_example

from colourhs.capture import DIST_LENGTHS, CaptureFormatError, rig_from_dict, rig_schema
from colourhs.synth.simulated_rig import make_rig
from colourhs.synth.synthesise import PRESETS, rig_json

DOCS = Path(__file__).resolve().parents[2] / "docs" / "capture-format.md"


def demo_rig() -> dict[str, Any]:
    """The rig.json the synthetic renderer writes for the demo preset (seed 0), decoded."""
    p = PRESETS["demo"]
    rig = make_rig(p.width, p.height, p.focal_px, np.random.default_rng(0))
    return json.loads(json.dumps(rig_json(rig, p, p.board)))


def problem(data: Any) -> str:
    """The reader's message for ``data``, without the file name."""
    with pytest.raises(CaptureFormatError) as info:
        rig_from_dict(data, "rig.json")
    assert str(info.value).startswith("rig.json: ")
    return info.value.problem


def test_schema_is_a_valid_draft_2020_12_schema() -> None:
    schema = rig_schema()
    Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["required"] == ["format", "units", "image", "cameras", "board", "chromatic_light"]


@pytest.mark.parametrize("make", [demo_rig, contract_example], ids=["synth-demo", "contract"])
def test_written_rigs_validate(make) -> None:
    """A plain Draft 2020-12 validator (as any consumer would use) and the reader accept them."""
    data = make()
    assert list(Draft202012Validator(rig_schema()).iter_errors(data)) == []
    rig = rig_from_dict(data)
    assert [c.name for c in rig.cameras] == ["cam1", "cam2", "cam3"]
    assert rig.image.width == 640 and rig.image.bit_depth == 16


def test_schema_distortion_lengths_are_dist_lengths() -> None:
    validator = Draft202012Validator(rig_schema())
    data = contract_example()
    accepted = []
    for n in range(16):
        data["cameras"][0]["dist"] = [0.0] * n
        if validator.is_valid(data):
            accepted.append(n)
    assert tuple(accepted) == DIST_LENGTHS == (0, 4, 5, 8, 12, 14)


def test_other_keys_are_ignored() -> None:
    """The contract: keys it does not name are allowed (new optional keys stay compatible)."""
    data = contract_example()
    data["notes"] = "bench B"
    data["cameras"][0]["serial"] = 1234
    data["board"]["material"] = {"finish": "matte"}
    assert rig_from_dict(data).camera("cam1").name == "cam1"


def near(value: float, steps: int = 3) -> list[float]:
    """``value`` and the ``steps`` float64 neighbours on each side of it."""
    out = [value]
    for _ in range(steps):
        out = [float(np.nextafter(out[0], -np.inf)), *out, float(np.nextafter(out[-1], np.inf))]
    return out


@pytest.mark.parametrize(
    ("entry", "centre"), [((1, 0), 0.0), ((2, 1), 0.0), ((2, 2), 1.0)], ids=["K10", "K21", "K22"]
)
def test_k_bounds_are_the_old_readers(entry: tuple[int, int], centre: float) -> None:
    """The schema's K bounds accept exactly what ``abs(v - centre) <= 1e-12`` accepted
    before it, float64 by float64 on both sides of both bounds."""
    data = contract_example()
    verdicts = []
    for value in near(centre - 1e-12) + near(centre + 1e-12):
        data["cameras"][1]["K"][entry[0]][entry[1]] = value
        try:
            rig_from_dict(data)
            verdicts.append(True)
        except CaptureFormatError as err:
            assert err.problem.startswith(f"cameras[1].K[{entry[0]}][{entry[1]}] must be ")
            verdicts.append(False)
    old = [abs(v - centre) <= 1e-12 for v in near(centre - 1e-12) + near(centre + 1e-12)]
    assert verdicts == old and 4 <= sum(old) <= 10  # each side: its bound and 1-4 inner ones


def test_numbers_are_finite() -> None:
    """Python's json reads NaN and Infinity (not JSON); the reader's "number" refuses them,
    where a plain Draft 2020-12 validator would not."""
    data = contract_example()
    data["cameras"][0]["t"][1] = float("nan")
    assert Draft202012Validator(rig_schema()).is_valid(data)
    assert problem(data) == (
        "cameras[0].t must be a list of 3 numbers (m): the world-to-camera translation, "
        "got a list of 3: [0.0, NaN, 0.8]"
    )
    data["cameras"][0]["t"][1] = 0.0
    data["board"]["marker_length"] = float("inf")
    assert problem(data).startswith("board.marker_length must be a number > 0 (m)")
    data["board"]["marker_length"] = 2**1100  # an integer beyond float range
    assert problem(data).startswith("board.marker_length must be a number > 0 (m)")


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(format=1), "format is 1, expected 'colourhs-capture/1'"),
        (
            lambda d: d["image"].update(height=-1),
            "image.height must be an integer > 0 (pixels), got -1",
        ),
        (
            lambda d: d["cameras"][2]["light"].update(offset=[0, 0]),
            "cameras[2].light.offset must be a list of 3 numbers (m): the light's centre in "
            "camera coordinates, got a list of 2: [0, 0]",
        ),
        (
            lambda d: d["board"].update(size=[0.3, 0.0]),
            "board.size must be a list of 2 numbers > 0 (m): the board's width and height, "
            "got a list of 2: [0.3, 0.0]",
        ),
        (
            lambda d: d["board"]["markers"].update({"": [0.1, 0.1]}),
            "board.markers key '' must be a marker id (decimal digits)",
        ),
        (
            lambda d: d["chromatic_light"].update(position="above"),
            "chromatic_light.position must be a list of 3 numbers (m): the light's world "
            'position, got "above"',
        ),
        # Several problems: the shallowest is reported (units, not K).
        (
            lambda d: (d.pop("units"), d["cameras"][0].update(K=1)),
            "missing required key units",
        ),
    ],
    ids=[
        "format-int",
        "height-negative",
        "offset-2",
        "size-zero",
        "marker-id-empty",
        "position-text",
        "shallowest-first",
    ],
)
def test_schema_messages(edit, message: str) -> None:
    data = contract_example()
    edit(data)
    assert problem(data) == message
    assert not Draft202012Validator(rig_schema()).is_valid(data)


def test_schema_file_ships_with_the_package() -> None:
    """pyproject.toml's package-data lists the schema, so an installed package has it."""
    pyproject = tomllib.loads((DOCS.parents[1] / "pyproject.toml").read_text())
    patterns = pyproject["tool"]["setuptools"]["package-data"]["colourhs.capture"]
    assert any(fnmatch("rig.schema.json", p) for p in patterns)
