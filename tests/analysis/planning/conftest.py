"""Shared fixtures: the reference rig at the paper's planning point and a reduced plan."""

from __future__ import annotations

import pytest

from analysis.model import load_model
from analysis.planning import (
    PAPER_LINEAR,
    Candidates,
    PlanSettings,
    paper_candidates,
    plan_tests,
)

#: A reduced candidate set that keeps the paper's structure: 4 sensors choose 2, two
#: actuators, 3 levels choose 2, the contact range and the second-resonance range.
REDUCED = Candidates(
    sensors=(3, 5, 6, 7),
    n_sensors=2,
    actuators=(2, 3),
    levels_n=(2.0, 4.0, 6.0),
    n_levels=2,
    ranges=(paper_candidates().ranges[0], paper_candidates().ranges[-1]),
)


@pytest.fixture(scope="session")
def rig():
    """The reference rig with Table 2's calibrated linear values, nominal contact."""
    return load_model().with_values(PAPER_LINEAR)


@pytest.fixture(scope="session")
def reduced_plan(rig):
    """The reduced plan, serial, without the refinement study."""
    return plan_tests(rig, REDUCED, executor=None, settings=PlanSettings(refine_band_hz=None))
