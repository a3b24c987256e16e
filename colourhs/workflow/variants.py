"""The paper's ablation (Figure 7): the variants every scene is reconstructed with.

One table for the package, the workflow (``colourhs/workflow/plan.py``), the
CLI and the report. Each variant id (the results contract's) has its method
and the calibrations it uses, and the paper's name for it (Section IV-A).
"""

from __future__ import annotations

#: id -> method (``vh``: the visual hull; ``ml``, ``bayes``: colour HS), whether
#: the photometric (mu, eqs. 6-8) and chromaticity (eq. 12) calibrations are
#: applied (``tracked``: the chromaticity carried to each frame), and the paper's
#: name. In the paper's order, then ``bayes_dyn`` (beyond the paper).
VARIANTS = {
    "vh": {"method": "vh", "photometric": False, "chromaticity": False, "label": "VH"},
    "ml_full": {
        "method": "ml",
        "photometric": True,
        "chromaticity": True,
        "label": "ML_HS_wPh&ChromCalib",
    },
    "bayes_nocalib": {
        "method": "bayes",
        "photometric": False,
        "chromaticity": False,
        "label": "BayesianHS_w/oCalib",
    },
    "bayes_ph": {
        "method": "bayes",
        "photometric": True,
        "chromaticity": False,
        "label": "BayesianHS_wPhCalib",
    },
    "bayes_full": {
        "method": "bayes",
        "photometric": True,
        "chromaticity": True,
        "label": "BayesianHS_wPh&ChromCalib",
    },
    # Beyond the paper: the chromaticity carried to each frame of a moving object
    # (colourhs.calibration.chromaticity_tracking) instead of the chromatic frame's.
    "bayes_dyn": {
        "method": "bayes",
        "photometric": True,
        "chromaticity": True,
        "tracked": True,
        "label": "BayesianHS_wPh&TrackedChrom",
    },
}

#: The variant ids in the paper's order.
VARIANT_ORDER = tuple(VARIANTS)
#: The paper's ablation (Figure 7): every variant but those beyond it.
PAPER_VARIANTS = tuple(k for k, v in VARIANTS.items() if not v.get("tracked"))
#: id -> the paper's name.
VARIANT_LABELS = {k: v["label"] for k, v in VARIANTS.items()}
#: The colour HS variants' ids as a regular expression (the workflow's ``variant``
#: wildcard of the reconstruction rule; ``vh`` has its own rule).
HS_VARIANT_PATTERN = "|".join(k for k, v in VARIANTS.items() if v["method"] != "vh")


def parse_variants(text: str) -> list[str]:
    """Variant ids from a comma-separated list; ValueError naming unknown ones."""
    ids = [v.strip() for v in text.split(",") if v.strip()]
    unknown = [v for v in ids if v not in VARIANTS]
    if unknown or not ids:
        raise ValueError(
            f"unknown variant(s) {', '.join(map(repr, unknown)) or '(none given)'}; "
            f"variants: {', '.join(VARIANTS)}"
        )
    return ids


def same_as(variant: str, chromatic_object: bool, moving: bool = False) -> str | None:
    """The variant whose results ``variant``'s equal on a scene, or None.

    On a scene without a chromatic object the chromaticity calibration has
    nothing to apply (p = 1 everywhere, eq. 9 with white albedo), so a
    variant that uses it equals the one with the same method and photometric
    calibration without it (``bayes_full`` is ``bayes_ph``): the workflow
    computes it once and copies the results (beyond the paper: a saving). A
    tracked chromaticity differs from the calibrated one only on a ``moving``
    scene (a sequence of several frames): elsewhere ``bayes_dyn`` is
    ``bayes_full`` (or, without a chromatic object, what that equals).
    """
    v = VARIANTS[variant]
    if v.get("tracked") and not (chromatic_object and moving):
        untracked = next(
            k
            for k, w in VARIANTS.items()
            if not w.get("tracked")
            and (w["method"], w["photometric"], w["chromaticity"])
            == (v["method"], v["photometric"], v["chromaticity"])
        )
        return same_as(untracked, chromatic_object) or untracked
    if chromatic_object or not v["chromaticity"]:
        return None
    for other, w in VARIANTS.items():
        if w["method"] == v["method"] and w["photometric"] == v["photometric"]:
            if not w["chromaticity"]:
                return other
    return None
