"""Lights beside the lenses: the half-vector defect of a reciprocal pair, what it
predicts of a glossy BRDF, and where the pipeline reports it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from capture_helpers import edit_json, make_dataset

from colourhs.capture import load_rig
from colourhs.capture.rig import light_offset_warning, reciprocity_defect_deg
from colourhs.cli.parser import main
from colourhs.common.geometry import half_vector_defect
from colourhs.synth.brdf import Material

# A symmetric pair 0.8 m from the point X = 0, 0.4 m apart (28 degrees).
C_A, C_B = np.array([-0.2, 0.0, -0.8]), np.array([0.2, 0.0, -0.8])
X = np.zeros(3)


def _unit(v):
    return v / np.linalg.norm(v)


def test_collocated_lights_have_no_defect_and_an_offset_its_first_order_angle():
    """0 with each light at its lens; one light 30 mm beside its lens, perpendicular to
    the pair's plane, turns that reading's light direction by delta / r and the
    half-vector by half of that over cos(theta / 2), theta the pair's angle at X:
    0.01875 rad here (second order: (delta / r)^2, about 0.1 % of it)."""
    assert half_vector_defect(X, C_A, C_A, C_B, C_B) == 0.0
    delta = 0.03
    r = np.linalg.norm(C_A)
    half = np.arctan(0.2 / 0.8)
    first_order = delta / r / (2 * np.cos(half))
    got = half_vector_defect(X, C_A, C_A + [0, delta, 0], C_B, C_B)
    assert got == pytest.approx(first_order, rel=2e-3)
    # symmetric in the pair, vectorised over points
    pts = np.array([X, [0.01, 0.02, 0.0]])
    both = half_vector_defect(pts, C_B, C_B, C_A, C_A + [0, delta, 0])
    assert both.shape == (2,) and both[0] == pytest.approx(got, rel=1e-12)


def test_the_defect_predicts_a_glossy_pairs_disagreement():
    """Helmholtz reciprocity of a GGX lobe (roughness 0.1, no diffuse part) at a
    normal between the pair's specular directions. With collocated lights the pair's
    two BRDF readings agree to the bit. With one light beside its lens the defect is
    of first order in the offset, with both lights beside their lenses in the same
    direction (the half-vectors move together) of second order; either way the
    readings' disagreement follows the defect, not the offset: at 3 and 0.3 mm
    (where the lobe is about linear over the defect) the ten times smaller offset
    gives a ten (first order) or a hundred (second order) times smaller
    disagreement, as its defect (measured 9.4 against 10.0, and 107 against 100).
    At 30 mm one light alone makes the readings disagree by 9 %."""
    glossy = Material(kd=0.0, specular="ggx", ks=1.0, roughness=0.1, f0=0.04)
    n = _unit(np.array([0.02, 0.01, -1.0]))

    def disagreement(l_a, l_b):
        """|log| of camera a's reading (lit by b's light) over camera b's (lit by
        a's), and the pair's defect at X."""
        f_ab = glossy.evaluate(n[None], _unit(l_b - X)[None], _unit(C_A - X)[None])[0]
        f_ba = glossy.evaluate(n[None], _unit(l_a - X)[None], _unit(C_B - X)[None])[0]
        return abs(np.log(f_ab / f_ba)), float(half_vector_defect(X, C_A, l_a, C_B, l_b))

    assert disagreement(C_A, C_B) == (0.0, 0.0)
    up = np.array([0.0, 0.03, 0.0])
    assert disagreement(C_A + up, C_B)[0] > 0.08  # a share no calibration removes
    alone = [disagreement(C_A + k * up, C_B) for k in (0.1, 0.01)]
    together = [disagreement(C_A + k * up, C_B + k * up) for k in (0.1, 0.01)]
    for big, small in (alone, together):
        assert big[0] / small[0] == pytest.approx(big[1] / small[1], rel=0.1)
    assert alone[0][1] / alone[1][1] == pytest.approx(10, rel=0.01)  # first order
    assert together[0][1] / together[1][1] == pytest.approx(100, rel=0.02)  # second order


def test_rig_reports_its_lights_defect(tmp_path):
    """The test rig's third light sits 54 mm beside its lens: each pair with that
    camera has a defect at the fixation point, the other pair none; the warning names
    rig.json and the angle; with collocated lights there is neither."""
    root = make_dataset(tmp_path / "d")
    rig = load_rig(root)
    defect = np.degrees(rig.reciprocity_defect(rig.fixation_point()))
    pairs = [(p.cam_a, p.cam_b) for p in rig.reciprocal_pairs()]
    assert defect.shape == (3,)
    for (a, b), d in zip(pairs, defect, strict=True):
        assert (d > 0.5) if "cam3" in (a, b) else (d == 0.0), (a, b, d)
    assert reciprocity_defect_deg(rig) == pytest.approx(defect.max())
    text = light_offset_warning(rig)
    assert text.startswith(f"{rig.path}: the lights sit up to 54 mm beside the lenses")
    assert f"{defect.max():.2f} degrees" in text
    assert light_offset_warning(rig, tolerance_deg=defect.max() + 0.01) is None

    def collocate(doc):
        for cam in doc["cameras"]:
            cam["light"]["offset"] = [0.0, 0.0, 0.0]

    edit_json(root / "rig.json", collocate)
    rig = load_rig(root)
    assert reciprocity_defect_deg(rig) == 0.0 and light_offset_warning(rig) is None


def test_report_states_where_the_lights_are(tmp_path):
    from colourhs.capture import open_dataset
    from colourhs.report.provenance import rig_summary

    root = make_dataset(tmp_path / "d")
    line = rig_summary(open_dataset(root))["lights"]
    defect = reciprocity_defect_deg(load_rig(root))
    assert line.startswith(
        "up to 54 mm beside the lenses; the reciprocal pairs' half-vectors up to "
        f"{defect:.2f} deg apart"
    )
    assert line.endswith(
        "(over the tolerance: a glossy surface's depth can be off by more than its sigma)"
    )


def test_validate_summary_carries_the_defect_and_warns(tmp_path, capsys):
    root = make_dataset(tmp_path / "d")
    summary = tmp_path / "summary.json"
    assert main(["validate", str(root), "--summary", str(summary)]) == 0
    data = json.loads(summary.read_text())
    assert data["reciprocity_defect_deg"] == pytest.approx(reciprocity_defect_deg(load_rig(root)))
    assert data["warnings"] == [light_offset_warning(load_rig(root))]
    assert f"warning: {root / 'rig.json'}: the lights sit" in capsys.readouterr().err


def test_validate_refuses_lights_too_far_beside_their_lenses(tmp_path, capsys):
    """Beyond RECIPROCITY_DEFECT_LIMIT_DEG at the fixation point the rig is refused,
    naming rig.json, the offset and the angle; within it only warned about."""
    from colourhs.capture import validate
    from colourhs.capture.base import CaptureFormatError
    from colourhs.capture.rig import RECIPROCITY_DEFECT_LIMIT_DEG, light_offset_problem

    root = make_dataset(tmp_path / "d")
    rig = load_rig(root)
    assert reciprocity_defect_deg(rig) < RECIPROCITY_DEFECT_LIMIT_DEG
    assert light_offset_problem(rig) is None

    def far(doc):
        doc["cameras"][2]["light"]["offset"] = [0.0, 0.3, 0.0]

    edit_json(root / "rig.json", far)
    rig = load_rig(root)
    defect = reciprocity_defect_deg(rig)
    assert defect > RECIPROCITY_DEFECT_LIMIT_DEG
    with pytest.raises(CaptureFormatError) as err:
        validate(root)
    assert err.value.path == root / "rig.json"
    text = str(err.value)
    assert "300 mm beside the lenses" in text and f"{defect:.1f} degrees" in text
    assert light_offset_problem(rig, limit_deg=defect + 0.1) is None
    assert main(["validate", str(root), "--no-rig-check"]) == 1
    assert "limit 5)" in capsys.readouterr().err
