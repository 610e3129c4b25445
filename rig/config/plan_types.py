"""The plan classes: :class:`SteppedSinePlan`, :class:`RandomPlan`, :class:`PlannedStep`.

Their parts are in :mod:`rig.config.plan_settings`, reading and writing plan files in
:mod:`rig.config.plan_files`; :mod:`rig.config.plans` is where users import all of them from (its
docstring
has the file layout).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, ClassVar

import numpy as np

from rig.config.plan_settings import (
    MAX_PLAN_STEPS,
    AcquisitionSettings,
    ControlPolicy,
    ExcitationSettings,
    FrequencyPlan,
    Limits,
    PlanTooLarge,
    PretestSettings,
    RandomAcquisition,
    RandomExcitation,
)

__all__ = ["Plan", "PlannedStep", "RandomPlan", "SteppedSinePlan"]


# ------------------------------------------------------------------------ plans


@dataclass(frozen=True)
class PlannedStep:
    """One step of a stepped-sine plan.

    Attributes
    ----------
    plan_index : int
        Position in the plan (the file's ``plan_index``).
    level_index : int
    level_n : float
        Fundamental force amplitude [N].
    frequency_hz : float
        Planned fundamental frequency [Hz].
    sweep_direction : int
        +1 up, -1 down.
    first_of_sweep : bool
        The first step of a sweep (a large change from the previous drive).
    """

    plan_index: int
    level_index: int
    level_n: float
    frequency_hz: float
    sweep_direction: int
    first_of_sweep: bool


def _check_common(owner: str, name: str, setup: str, points: tuple[int, ...], sr: float) -> None:
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{owner}.name: expected a non-empty name, got {name!r}")
    if not isinstance(setup, str) or not setup.strip():
        raise ValueError(f"{owner}.setup: expected a setup name or file, got {setup!r}")
    if not points or any(isinstance(p, bool) or not isinstance(p, int) or p < 0 for p in points):
        raise ValueError(f"{owner}.points: expected point numbers >= 0, got {points!r}")
    if len(set(points)) != len(points):
        raise ValueError(f"{owner}.points: points repeat: {list(points)}")
    if not (math.isfinite(sr) and sr >= 0):
        raise ValueError(f"{owner}.sample_rate_hz: must be >= 0 (0: the setup's), got {sr}")


@dataclass(frozen=True)
class SteppedSinePlan:
    """A force-controlled stepped multi-sine test.

    Parameters
    ----------
    name, description : str
    setup : str
        Built-in setup name or setup file the plan expects.
    points : tuple of int
        Accelerometer points recorded (the drive force is always recorded).
    excitation : ExcitationSettings
    frequencies : FrequencyPlan
    acquisition : AcquisitionSettings
    control : ControlPolicy
    limits : Limits
    pretest : PretestSettings
    sample_rate_hz : float
        Sample rate [Hz]; 0 uses the setup's.
    """

    name: str
    description: str
    setup: str
    points: tuple[int, ...]
    excitation: ExcitationSettings
    frequencies: FrequencyPlan
    acquisition: AcquisitionSettings = field(default_factory=AcquisitionSettings)
    control: ControlPolicy = field(default_factory=ControlPolicy)
    limits: Limits = field(default_factory=Limits)
    pretest: PretestSettings = field(default_factory=PretestSettings)
    sample_rate_hz: float = 0.0

    kind: ClassVar[str] = "stepped-sine"

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", tuple(self.points))
        _check_common("SteppedSinePlan", self.name, self.setup, self.points, self.sample_rate_hz)
        n = self.step_count_bound()
        if n > MAX_PLAN_STEPS:
            raise PlanTooLarge(
                f"plan {self.name!r} has {n:,} steps, more than the maximum of "
                f"{MAX_PLAN_STEPS:,} (levels x sweeps x frequencies): check its step_hz"
            )
        s = self.control.settings
        if s.orders != self.excitation.orders or s.max_drive_v != self.limits.drive_peak_v:
            settings = dataclasses.replace(
                s, orders=self.excitation.orders, max_drive_v=self.limits.drive_peak_v
            )
            object.__setattr__(
                self, "control", dataclasses.replace(self.control, settings=settings)
            )

    @property
    def levels_n(self) -> tuple[float, ...]:
        return self.excitation.levels_n

    def step_count_bound(self) -> int:
        """Steps counted from the settings without listing them: levels x sweeps x each
        range's frequencies (a frequency two ranges share counted twice, so an upper bound of
        :attr:`n_steps`, exact for ranges that do not overlap)."""
        fr = self.frequencies
        sweeps = 2 if "-" in fr.direction else 1
        return len(self.excitation.levels_n) * sweeps * sum(r.count for r in fr.ranges)

    def steps(self) -> tuple[PlannedStep, ...]:
        """Every step in the order it is run: for each level, each sweep, each frequency."""
        out: list[PlannedStep] = []
        for li, level in enumerate(self.excitation.levels_n):
            for sign, freqs in self.frequencies.sweeps():
                for j, f in enumerate(freqs):
                    out.append(PlannedStep(len(out), li, level, float(f), sign, j == 0))
        return tuple(out)

    @property
    def n_steps(self) -> int:
        return len(self.steps())

    @property
    def extra_orders(self) -> tuple[Fraction, ...]:
        """Whole orders up to ``acquisition.force_orders_up_to`` that the drive does not
        contain: the force is recorded there too (the file's extra orders)."""
        drive = set(self.excitation.orders)
        top = self.acquisition.force_orders_up_to
        return tuple(Fraction(k) for k in range(1, top + 1) if Fraction(k) not in drive)

    def force_targets(self) -> np.ndarray:
        """Target force phasors per level, shape (L, H), complex, N (the file's layout)."""
        spec = self.excitation.spec
        return np.array([spec.force_targets(level) for level in self.excitation.levels_n])

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the file's ``config_json``); :func:`plan_from_dict` reads it back."""
        ex = self.excitation
        control = {
            k: v
            for k, v in dataclasses.asdict(self.control.settings).items()
            if k not in ("orders", "max_drive_v")
        }
        return {
            "name": self.name,
            "kind": self.kind,
            "description": self.description,
            "setup": self.setup,
            "points": list(self.points),
            "sample_rate_hz": self.sample_rate_hz,
            "excitation": {
                "orders": [str(o) for o in ex.orders],
                "relative_amplitudes": list(ex.relative_amplitudes),
                "phases_deg": list(ex.phases_deg),
                "levels_n": list(ex.levels_n),
            },
            "frequencies": {
                "direction": self.frequencies.direction,
                "ranges": [dataclasses.asdict(r) for r in self.frequencies.ranges],
            },
            "acquisition": dataclasses.asdict(self.acquisition),
            "control": {
                "uncertainty_factor": self.control.uncertainty_factor,
                "warm_start": self.control.warm_start,
                "on_divergence": self.control.on_divergence,
                "divergence_abort_error": self.control.divergence_abort_error,
                "restart_after": self.control.restart_after,
                **control,
            },
            "limits": _limits_dict(self.limits),
            "pretest": dataclasses.asdict(self.pretest),
        }


@dataclass(frozen=True)
class RandomPlan:
    """A low-level random test giving H1 FRFs and coherence of every channel.

    Parameters are those of :class:`SteppedSinePlan` where shared, with
    :class:`RandomExcitation` and :class:`RandomAcquisition`.
    """

    name: str
    description: str
    setup: str
    points: tuple[int, ...]
    excitation: RandomExcitation = field(default_factory=RandomExcitation)
    acquisition: RandomAcquisition = field(default_factory=RandomAcquisition)
    limits: Limits = field(default_factory=Limits)
    pretest: PretestSettings = field(default_factory=PretestSettings)
    sample_rate_hz: float = 0.0

    kind: ClassVar[str] = "random"

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", tuple(self.points))
        _check_common("RandomPlan", self.name, self.setup, self.points, self.sample_rate_hz)

    @property
    def n_steps(self) -> int:
        """Records acquired (calibration, settling and averaged)."""
        return 1 + self.acquisition.settle_records + self.acquisition.average_records

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the file's ``config_json``); :func:`plan_from_dict` reads it back."""
        return {
            "name": self.name,
            "kind": self.kind,
            "description": self.description,
            "setup": self.setup,
            "points": list(self.points),
            "sample_rate_hz": self.sample_rate_hz,
            "excitation": dataclasses.asdict(self.excitation),
            "acquisition": dataclasses.asdict(self.acquisition),
            "limits": _limits_dict(self.limits),
            "pretest": dataclasses.asdict(self.pretest),
        }


Plan = SteppedSinePlan | RandomPlan


def _limits_dict(limits: Limits) -> dict[str, Any]:
    response = []
    for r in limits.response:
        d = {k: v for k, v in dataclasses.asdict(r).items() if v is not None}
        if not d.get("channel"):
            d.pop("channel", None)
        if d.get("point", -1) < 0:
            d.pop("point", None)
        response.append(d)
    return {"drive_peak_v": limits.drive_peak_v, "response": response}
