"""Test plans: what a run does, as validated frozen settings loaded from TOML.

Two kinds of plan exist:

- :class:`SteppedSinePlan` (``kind = "stepped-sine"``): force-controlled stepped multi-sine
  steps over frequency ranges and force levels (the nonlinear test of the paper);
- :class:`RandomPlan` (``kind = "random"``): band-limited random excitation at a low level for
  the H1 FRFs of the linear test.

A plan names the lab setup it expects (:mod:`rig.config.setup`) and the measurement points it
records;
the drive point is the setup's. Built-in plans live in ``rig/plans/*.toml`` (``paper``,
``quick``, ``linear``); :func:`load_plan` also reads any plan file (:mod:`rig.config.plan_files`).
The plan classes are in :mod:`rig.config.plan_types`, their parts in
:mod:`rig.config.plan_settings`; this
module gathers them. The engine turns a plan into commands
(:mod:`rig.procedures.stepped_sine`, :mod:`rig.procedures.random_test`); the plan objects only
describe.

File layout of a stepped-sine plan (every table optional except ``excitation`` and
``frequencies``; defaults as in the dataclasses)::

    name = "paper"
    kind = "stepped-sine"
    setup = "reference"              # built-in setup name or a setup file
    points = [3, 6, 7]               # accelerometer points recorded (plus the drive force)

    [excitation]                     # ExcitationSettings
    orders = [1, 2, 3]               # rationals as strings: "1/2"
    relative_amplitudes = [1.0, 0.02, 0.02]
    levels_n = [2.0, 4.0, 6.0, 8.0]

    [frequencies]                    # FrequencyPlan
    direction = "up"                 # up | down | up-down | down-up
    ranges = [{start_hz = 21.0, stop_hz = 40.0, step_hz = 1.0}, ...]

    [acquisition]                    # AcquisitionSettings
    [control]                        # ControlPolicy and any ControlSettings field
    [limits]                         # Limits: drive_peak_v and [[limits.response]]
    [pretest]                        # PretestSettings
"""

from __future__ import annotations

from rig.config.plan_files import builtin_plans, describe_plan, load_plan, plan_from_dict
from rig.config.plan_settings import (
    DIRECTIONS,
    MAX_PLAN_STEPS,
    AcquisitionSettings,
    ControlPolicy,
    ControlSettings,
    ExcitationSettings,
    FrequencyPlan,
    FrequencyRange,
    Limits,
    PlanTooLarge,
    PretestSettings,
    RandomAcquisition,
    RandomExcitation,
    ResponseLimit,
)
from rig.config.plan_types import Plan, PlannedStep, RandomPlan, SteppedSinePlan
from rig.config.tomlconfig import ConfigError

__all__ = [
    "DIRECTIONS",
    "MAX_PLAN_STEPS",
    "PlanTooLarge",
    "AcquisitionSettings",
    "ConfigError",
    "ControlPolicy",
    "ControlSettings",
    "ExcitationSettings",
    "FrequencyPlan",
    "FrequencyRange",
    "Limits",
    "Plan",
    "PlannedStep",
    "PretestSettings",
    "RandomAcquisition",
    "RandomExcitation",
    "RandomPlan",
    "ResponseLimit",
    "SteppedSinePlan",
    "builtin_plans",
    "describe_plan",
    "load_plan",
    "plan_from_dict",
]
