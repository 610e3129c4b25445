"""The plan classes: :class:`SteppedSinePlan`, :class:`RandomPlan`, :class:`PlannedStep`.

Their parts are in :mod:`rig.config.plan_settings`, reading and writing plan files in
:mod:`rig.config.plan_files`; :mod:`rig.config.plans` is where users import all of them from (its
docstring
has the file layout).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from fractions import Fraction
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import Field

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
from rig.config.settings import Integer, Number, SettingError, Text, dump, settings

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


Name = Annotated[Text, Field(min_length=1, pattern=r"\S", description="Name of the plan.")]
Description = Annotated[Text, Field(description="What the plan is for.")]
SetupName = Annotated[
    Text,
    Field(min_length=1, pattern=r"\S", description="Built-in setup name or setup file expected."),
]
Points = Annotated[
    tuple[Annotated[Integer, Field(ge=0)], ...],
    Field(
        min_length=1,
        description="Accelerometer points recorded (the drive force is always recorded).",
    ),
]
SampleRate = Annotated[Number, Field(ge=0, description="Sample rate [Hz]; 0 uses the setup's.")]


@settings(kw_only=True)
class _PlanBase:
    """What every kind of plan has."""

    name: Name
    points: Points
    description: Description = ""
    setup: SetupName = "reference"
    limits: Limits = Field(default_factory=Limits)
    pretest: PretestSettings = Field(default_factory=PretestSettings)
    sample_rate_hz: SampleRate = 0.0

    kind: ClassVar[str]

    def __post_init__(self) -> None:
        if len(set(self.points)) != len(self.points):
            raise SettingError(("points",), f"points repeat: {list(self.points)}")

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the file's ``config_json``); :func:`plan_from_dict` reads it back."""
        data = dump(self)
        return {"name": data.pop("name"), "kind": self.kind, **data}


@settings(kw_only=True)
class SteppedSinePlan(_PlanBase):
    """A force-controlled stepped multi-sine test (the file layout is in
    :mod:`rig.config.plans`)."""

    excitation: ExcitationSettings
    frequencies: FrequencyPlan
    acquisition: AcquisitionSettings = Field(default_factory=AcquisitionSettings)
    control: ControlPolicy = Field(default_factory=ControlPolicy)

    kind: ClassVar[str] = "stepped-sine"

    def __post_init__(self) -> None:
        super().__post_init__()
        n = self.step_count_bound()
        if n > MAX_PLAN_STEPS:
            raise PlanTooLarge(
                (),
                f"plan {self.name!r} has {n:,} steps, more than the maximum of "
                f"{MAX_PLAN_STEPS:,} (levels x sweeps x frequencies): check its step_hz",
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


@settings(kw_only=True)
class RandomPlan(_PlanBase):
    """A low-level random test giving H1 FRFs and coherence of every channel."""

    excitation: RandomExcitation = Field(default_factory=RandomExcitation)
    acquisition: RandomAcquisition = Field(default_factory=RandomAcquisition)

    kind: ClassVar[str] = "random"

    @property
    def n_steps(self) -> int:
        """Records acquired (calibration, settling and averaged)."""
        return 1 + self.acquisition.settle_records + self.acquisition.average_records


Plan = SteppedSinePlan | RandomPlan
