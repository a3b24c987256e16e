"""Shared fixtures: synthetic datasets rendered once per test session."""

from __future__ import annotations

import pytest

from colourhs.synth.dataset import Preset, synthesise
from colourhs.synth.rig import Nuisances

# 640x480 like the demo preset, with fewer board poses and sheet frames.
CHECK_PRESET = Preset("check", 640, 480, 1250.0, 2, n_poses=3, sheet_frames=1)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """The tiny preset with every nuisance on (seed 0)."""
    return synthesise(tmp_path_factory.mktemp("tiny") / "tiny", "tiny", progress=False)


@pytest.fixture(scope="session")
def clean_dataset(tmp_path_factory):
    """Demo resolution, noise and cross-talk off: equation (4) with mu and p only."""
    return synthesise(
        tmp_path_factory.mktemp("clean") / "clean",
        CHECK_PRESET,
        nuisances=Nuisances().without("noise", "crosstalk"),
        progress=False,
    )
