"""The settings a test plan is made of: frequencies, excitation, acquisition, control, limits.

Declared once (:mod:`rig.config.settings`): each field with its type, unit (in the name),
default, bounds and doc; frozen dataclasses validated on construction. :mod:`rig.config.plans`
assembles them into plans and :mod:`rig.config.plan_files` reads them from TOML.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any, ClassVar, Literal, get_args

import numpy as np
from pydantic import model_serializer, model_validator

from rig.config.settings import (
    Flag,
    Integer,
    NonNegative,
    Number,
    Orders,
    Positive,
    SettingError,
    Text,
    settings,
)
from rig.config.settings import declare as _doc
from rig.signals.multisine import MultisineSpec
from rig.signals.random import RandomKind

__all__ = [
    "MAX_PLAN_STEPS",
    "ControlSettings",
    "PlanTooLarge",
    "DIRECTIONS",
    "AcquisitionSettings",
    "ControlPolicy",
    "ExcitationSettings",
    "FrequencyPlan",
    "FrequencyRange",
    "Limits",
    "PretestSettings",
    "RandomAcquisition",
    "RandomExcitation",
    "ResponseLimit",
]

Direction = Literal["up", "down", "up-down", "down-up"]
DIRECTIONS: tuple[str, ...] = get_args(Direction)
_FREQ_DECIMALS = 6  # frequencies closer than 1e-6 Hz are the same step
#: The most steps a stepped-sine plan may hold. A step takes a second or more (settling and
#: averaging), so this is over a day of shaking; a plan beyond it is a mistyped ``step_hz``,
#: refused before its frequencies are listed (a 1e-9 Hz step over 21-40 Hz would need 142 GiB).
MAX_PLAN_STEPS = 100_000


class PlanTooLarge(SettingError):
    """A plan (or one frequency range of it) with more than :data:`MAX_PLAN_STEPS` steps."""


# ------------------------------------------------------------------------ frequencies


@settings()
class ControlSettings:
    """Tolerances, estimator prior and safety limits of the force controller."""

    orders: Orders = _doc("Harmonic orders (H); order 1 must be present.", (1, 2, 3))
    max_drive_v: Positive = _doc(
        "Largest allowed peak of the drive waveform [V] (keep it below the output limit).", 1.0
    )
    fundamental_amplitude_tolerance: Positive = _doc(
        "Relative amplitude tolerance of the fundamental force.", 0.01
    )
    fundamental_phase_tolerance_deg: Positive = _doc(
        "Phase tolerance of the fundamental force [deg].", 1.0
    )
    harmonic_tolerance: Positive = _doc(
        "Tolerance of order k relative to its own target: |F_k - T_k| <= tol |T_k|.", 0.10
    )
    harmonic_floor_ratio: NonNegative = _doc(
        "Absolute floor of that tolerance relative to |T_1| (needed for zero targets).", 0.002
    )
    max_iterations: Integer = _doc("Most measurements per step.", 8, ge=1)
    max_step_ratio: Positive = _doc(
        "Largest drive change per iteration relative to |V| (2-norm over orders).", 0.5
    )
    gain_uncertainty: Positive = _doc(
        "Prior relative standard deviation of the initial diagonal gains.", 0.3
    )
    coupling_uncertainty: Positive = _doc(
        "Prior standard deviation of a cross-order gain relative to sqrt(|J_ii J_jj|).", 0.03
    )
    gain_drift: NonNegative = _doc(
        "Fraction of the prior covariance added before each update (0 keeps every secant, "
        "right only for a linear plant).",
        0.3,
    )
    divergence_patience: Integer = _doc(
        "Diverged if the error grew over this many consecutive iterations.", 2, ge=1
    )
    max_gain_ratio: Number = _doc(
        "Diverged if a diagonal gain changes magnitude by more than this factor (either way).",
        10.0,
        gt=1,
    )
    max_gain_phase_change_deg: Number = _doc(
        "Diverged if a diagonal gain rotates by more than this [deg].", 90.0, gt=0, le=180
    )
    max_condition: Number = _doc(
        "Diverged if the gain matrix's condition number exceeds this (singular estimate).",
        1e6,
        gt=1,
    )

    def __post_init__(self) -> None:
        if Fraction(1) not in self.orders:
            raise SettingError(("orders",), "order 1 (the fundamental) must be present")

    @property
    def fundamental_index(self) -> int:
        """Column of order 1."""
        return self.orders.index(Fraction(1))


@settings()
class FrequencyRange:
    """Equally spaced fundamental frequencies ``start_hz, start_hz + step_hz, ..., stop_hz``."""

    start_hz: Positive = _doc("First frequency [Hz].")
    stop_hz: Positive = _doc("Last frequency [Hz]; reached from start_hz in whole steps.")
    step_hz: Positive = _doc("Spacing [Hz].")

    def __post_init__(self) -> None:
        if self.stop_hz < self.start_hz:
            raise SettingError(
                ("stop_hz",), f"is below start_hz ({self.start_hz}), got {self.stop_hz}"
            )
        n = (self.stop_hz - self.start_hz) / self.step_hz
        if n + 1 > MAX_PLAN_STEPS:
            raise PlanTooLarge(
                ("step_hz",),
                f"{self.start_hz} to {self.stop_hz} Hz in {self.step_hz} Hz steps is "
                f"{round(n) + 1:,} frequencies, more than a plan may hold "
                f"({MAX_PLAN_STEPS:,} steps): check step_hz",
            )
        if abs(n - round(n)) > 1e-6 * max(1.0, n):
            raise SettingError(
                ("stop_hz",),
                f"{self.start_hz} to {self.stop_hz} Hz is not a whole number of "
                f"{self.step_hz} Hz steps",
            )

    @property
    def count(self) -> int:
        """Number of frequencies (without listing them)."""
        return round((self.stop_hz - self.start_hz) / self.step_hz) + 1

    def frequencies_hz(self) -> np.ndarray:
        """The frequencies, ascending, shape (n,) [Hz]."""
        n = round((self.stop_hz - self.start_hz) / self.step_hz)
        return np.round(self.start_hz + self.step_hz * np.arange(n + 1), _FREQ_DECIMALS)


@settings()
class FrequencyPlan:
    """The fundamental frequencies of a sweep and its direction."""

    ranges: tuple[FrequencyRange, ...] = _doc(
        "Their union is swept; frequencies shared by two ranges (within 1e-6 Hz) are measured "
        "once (the paper: 21-40 Hz in 1 Hz plus 24-28 Hz in 0.1 Hz is 56 frequencies).",
        min_length=1,
    )
    direction: Direction = _doc(
        "Sweep direction at each level; the two-way kinds measure every frequency twice.", "up"
    )

    def frequencies_hz(self) -> np.ndarray:
        """Every planned frequency once, ascending, shape (n,) [Hz]."""
        return np.unique(np.concatenate([r.frequencies_hz() for r in self.ranges]))

    def sweeps(self) -> list[tuple[int, np.ndarray]]:
        """``(sweep_direction, frequencies)`` of each sweep at one level (+1 up, -1 down)."""
        f = self.frequencies_hz()
        up, down = (1, f), (-1, f[::-1].copy())
        return {"up": [up], "down": [down], "up-down": [up, down], "down-up": [down, up]}[
            self.direction
        ]


# ------------------------------------------------------------------------ stepped-sine settings


@settings()
class ExcitationSettings:
    """The multi-sine force and its levels."""

    orders: Orders = _doc("Harmonic orders of the force (order 1 required).", (1, 2, 3))
    relative_amplitudes: tuple[Number, ...] | None = _doc(
        "Amplitude of each order relative to the fundamental (default: 1 for the fundamental, "
        "0.02 for the others).",
        None,
    )
    phases_deg: tuple[Number, ...] | None = _doc(
        "Phase of each order relative to its order times the fundamental's phase [deg] "
        "(default: 0).",
        None,
    )
    levels_n: tuple[Positive, ...] = _doc(
        "Fundamental force amplitudes [N], in the order they are run.", (2.0,), min_length=1
    )

    def __post_init__(self) -> None:
        if self.relative_amplitudes is None:
            amplitudes = tuple(1.0 if o == 1 else 0.02 for o in self.orders)
            object.__setattr__(self, "relative_amplitudes", amplitudes)
        if self.phases_deg is None:
            object.__setattr__(self, "phases_deg", (0.0,) * len(self.orders))
        _ = self.spec  # validates amplitudes and phases against the orders

    @property
    def spec(self) -> MultisineSpec:
        """The force shape for :mod:`rig.signals.multisine`."""
        assert self.relative_amplitudes is not None and self.phases_deg is not None
        try:
            return MultisineSpec(
                self.orders,
                self.relative_amplitudes,
                tuple(np.radians(p) for p in self.phases_deg),
            )
        except ValueError as exc:
            raise ValueError(str(exc).replace("MultisineSpec", "ExcitationSettings")) from None


@settings()
class AcquisitionSettings:
    """Settling, averaging and ramps of a stepped-sine step."""

    block_periods: Integer = _doc(
        "Base periods per block (the unit of averaging and of the settling test).", 1, ge=1
    )
    average_blocks: Integer = _doc(
        "Blocks averaged for each force-control measurement (>= 4, the settling test needs them).",
        16,
        ge=4,
    )
    record_blocks: Integer = _doc(
        "Blocks averaged for the recorded step (>= average_blocks): after the controller "
        "accepts a drive, acquisition continues at that drive to this many blocks.",
        48,
    )
    settle_periods: Integer = _doc(
        "Base periods waited after a frequency or level change before blocks count.", 20, ge=0
    )
    correction_settle_periods: Integer = _doc(
        "Base periods waited after a force-control correction (a small drive change).",
        10,
        ge=0,
    )
    max_settle_periods: Integer = _doc(
        "Longest wait for the settling test to pass (>= settle_periods); the step then goes on "
        "and a warning says so.",
        400,
    )
    settling_tolerance: Positive = _doc(
        "Allowed change of the fundamental phasors between consecutive blocks, relative.", 0.01
    )
    drift_tolerance: Positive = _doc(
        "Allowed difference between the means of the two halves of the averaged blocks, "
        "relative (a slow drift that the block-to-block test misses).",
        0.005,
    )
    ramp_s: Positive = _doc("Cross-fade between drive waveforms [s].", 0.05)
    store_raw: Flag = _doc(
        "Keep the averaged time blocks of each recorded step in the file (/raw).", False
    )
    force_orders_up_to: Integer = _doc(
        "Also record the drive force at every whole order up to this one that the drive does "
        "not contain (the file's extra orders): where the structure responds nonlinearly the "
        "shaker pushes back at the harmonics of the response, and a model driven by the "
        "measured force needs those forces too; 0: the drive's orders only.",
        0,
        ge=0,
    )

    def __post_init__(self) -> None:
        for name, least in (
            ("record_blocks", "average_blocks"),
            ("max_settle_periods", "settle_periods"),
        ):
            if getattr(self, name) < getattr(self, least):
                raise SettingError(
                    (name,),
                    f"must be >= {least} ({getattr(self, least)}), got {getattr(self, name)}",
                )


@settings()
class ControlPolicy:
    """Force control of each step.

    In a plan file the ``[control]`` table holds these fields and those of
    :class:`ControlSettings` side by side, except ``orders`` and ``max_drive_v`` (the
    excitation's orders and the plan's drive limit).
    """

    settings: ControlSettings = _doc(
        "Tolerances and limits of the force controller (its max_drive_v is the plan's drive "
        "limit, its orders the excitation's).",
        default_factory=ControlSettings,
    )
    uncertainty_factor: NonNegative = _doc(
        "A measured force phasor also counts as on target when its deviation from the target "
        "is within this many standard errors of the measurement (a deviation the averaging "
        "cannot resolve is not chased); 0 switches this off.",
        2.0,
    )
    warm_start: Flag = _doc(
        "Start each step from the previous step's gain estimate (otherwise from the loop check).",
        True,
    )
    on_divergence: Literal["abort", "record"] = _doc(
        "When the iteration diverges: stop the run (the loop is not behaving physically), or "
        "record the best measurement flagged as not converged and go on.",
        "abort",
    )
    divergence_abort_error: Positive = _doc(
        "With 'abort': a diverged step whose best error (max_k |F_k - T_k| / |T_1|) is below "
        "this is recorded flagged as not converged and the run goes on (near a jump of a "
        "nonlinear response the iteration can wander without anything being wrong); above it "
        "the run stops.",
        0.5,
    )
    restart_after: Integer = _doc(
        "Start the iteration again, from the force per volt of the latest measurement, when "
        "after this many iterations the latest error is above 10 % and twice the best so far "
        "(0: never): near the fold of a nonlinear resonance the response can jump to another "
        "branch and the gain learnt before the jump misleads the controller. The total number "
        "of measurements per step stays within max_iterations.",
        4,
        ge=0,
    )

    #: The fields of ``settings`` sit in the file's ``[control]`` table itself ...
    __flattened__: ClassVar[dict[str, type]] = {"settings": ControlSettings}
    #: ... except these, which the plan sets from elsewhere.
    __set_elsewhere__: ClassVar[dict[str, str]] = {
        "orders": "excitation.orders",
        "max_drive_v": "limits.drive_peak_v",
    }

    @model_validator(mode="before")
    @classmethod
    def _nest(cls, data: object) -> object:
        """The flat ``[control]`` table of a file as the nested fields."""
        if not isinstance(data, dict) or "settings" in data:
            return data
        for name, where in cls.__set_elsewhere__.items():
            if name in data:
                raise SettingError((name,), f"set by {where}, not here")
        inner = set(ControlSettings.__pydantic_fields__)  # type: ignore[attr-defined]
        nested = {k: v for k, v in data.items() if k in inner}
        return {**{k: v for k, v in data.items() if k not in inner}, "settings": nested}

    @model_serializer(mode="wrap")
    def _flatten(self, handler):  # type: ignore[no-untyped-def]
        data = handler(self)
        settings = data.pop("settings")
        return {**data, **{k: v for k, v in settings.items() if k not in self.__set_elsewhere__}}


# ------------------------------------------------------------------------ limits and pretest


def _limit(doc: str) -> Any:
    return _doc(doc, None, gt=0)


@settings()
class ResponseLimit:
    """Alarm and abort limits of one channel (separate from the drive limit).

    The channel is named directly or by its point (the acceleration channel at that point).
    An alarm warns once per step; an abort stops the run with the output ramped to 0 V. Peaks
    are checked on every block read; displacement is the acceleration integrated twice over the
    excited band.
    """

    channel: Text = _doc('Channel name ("" when point is given).', "")
    point: Integer = _doc("Measurement point (-1 when channel is given).", -1)
    acceleration_alarm_m_s2: Number | None = _limit("Peak acceleration that warns [m/s^2].")
    acceleration_abort_m_s2: Number | None = _limit("Peak acceleration that stops [m/s^2].")
    displacement_alarm_m: Number | None = _limit("Peak displacement that warns [m].")
    displacement_abort_m: Number | None = _limit("Peak displacement that stops [m].")
    force_alarm_n: Number | None = _limit("Peak force that warns [N] (force channels).")
    force_abort_n: Number | None = _limit("Peak force that stops [N] (force channels).")

    _PAIRS: ClassVar[tuple[tuple[str, str], ...]] = (
        ("acceleration_alarm_m_s2", "acceleration_abort_m_s2"),
        ("displacement_alarm_m", "displacement_abort_m"),
        ("force_alarm_n", "force_abort_n"),
    )

    def __post_init__(self) -> None:
        if bool(self.channel) == (self.point >= 0):
            raise SettingError((), "give either channel or point (not both, not neither)")
        given = False
        for alarm, abort in self._PAIRS:
            a, b = getattr(self, alarm), getattr(self, abort)
            given = given or a is not None or b is not None
            if a is not None and b is not None and a >= b:
                raise SettingError((alarm,), f"must be below {abort} ({b}), got {a}")
        if not given:
            raise SettingError((), f"{self.target}: no limit given")

    @model_serializer(mode="wrap")
    def _only_the_target(self, handler):  # type: ignore[no-untyped-def]
        """The file names the channel or the point, not the placeholder of the other."""
        data = handler(self)
        unset = ("point", -1) if self.channel else ("channel", "")
        if data.get(unset[0]) == unset[1]:
            del data[unset[0]]
        return data

    @property
    def target(self) -> str:
        """``"channel NAME"`` or ``"point N"``."""
        return f"channel {self.channel!r}" if self.channel else f"point {self.point}"


@settings()
class Limits:
    """Safety limits of a run."""

    drive_peak_v: Positive = _doc(
        "Largest drive-waveform peak the run may apply [V] (below the setup's AO limit).", 1.0
    )
    response: tuple[ResponseLimit, ...] = _doc("Per-channel alarm and abort limits.", ())


@settings()
class PretestSettings:
    """Checks before the test: noise floor, loop check, channel sanity."""

    enabled: Flag = _doc(
        "Run the pretest (without it the first step starts from loop-check-free defaults).",
        True,
    )
    noise_s: Positive = _doc("Length of the noise-floor record at 0 V [s].", 1.0)
    loop_check_drive_v: Positive = _doc(
        "Drive amplitude of every order in the low-level loop check [V] (stepped sine).", 0.02
    )
    loop_check_frequency_hz: NonNegative = _doc(
        "Fundamental of the loop check [Hz]; 0: the plan's first frequency.", 0.0
    )
    min_snr: Positive = _doc(
        "A channel whose response to the loop check is below this many noise standard errors "
        "is reported as not responding.",
        5.0,
    )


@settings()
class RandomExcitation:
    """Band-limited random force of the linear test."""

    f_lo_hz: Positive = _doc("Lower edge of the excited band [Hz].", 10.0)
    f_hi_hz: Positive = _doc("Upper edge of the excited band [Hz].", 200.0)
    force_rms_n: Positive = _doc(
        "RMS drive force aimed at [N] (low, so that the gap never closes).", 0.3
    )
    signal: RandomKind = _doc(
        "Periodic random (flat spectrum, random phases; leakage-free with a rectangular "
        "window) or Gaussian random.",
        "periodic",
    )
    record_s: Positive = _doc(
        "Length of one record (one period of the drive) [s]; the frequency resolution of a "
        "periodic-random test is 1 / record_s.",
        8.0,
    )
    seed: Integer = _doc("Random state of the drive.", 1, ge=0)
    calibration_drive_rms_v: Positive = _doc(
        "RMS drive of the short record that measures the force per volt [V].", 0.003
    )

    def __post_init__(self) -> None:
        if self.f_hi_hz <= self.f_lo_hz:
            raise SettingError(
                ("f_hi_hz",), f"must exceed f_lo_hz ({self.f_lo_hz}), got {self.f_hi_hz}"
            )


@settings()
class RandomAcquisition:
    """Records and spectral averaging of the random test."""

    settle_records: Integer = _doc(
        "Records discarded after the drive starts (the transient).", 1, ge=0
    )
    average_records: Integer = _doc("Records acquired for the H1 estimate.", 8, ge=1)
    window: Text = _doc(
        'Window of the Welch average ("boxcar" for periodic random).', "boxcar", min_length=1
    )
    overlap: Number = _doc("Segment overlap, fraction in [0, 1).", 0.0, ge=0, lt=1)
    segments_per_record: Integer = _doc(
        "Welch segments per record (1: one segment is one record).", 1, ge=1
    )
    ramp_s: Positive = _doc("Fade in and out of the drive [s].", 0.2)
