"""The settings a test plan is made of: frequencies, excitation, acquisition, control, limits.

Frozen dataclasses with units in their names, validated on construction (a ``ValueError``
names the class and the field). :mod:`rig.config.plans` assembles them into plans and
:mod:`rig.config.plan_files` reads them from TOML.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import ClassVar

import numpy as np

from rig.signals.multisine import MultisineSpec, as_orders
from rig.signals.random import RANDOM_KINDS

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

DIRECTIONS = ("up", "down", "up-down", "down-up")
_FREQ_DECIMALS = 6  # frequencies closer than 1e-6 Hz are the same step
#: The most steps a stepped-sine plan may hold. A step takes a second or more (settling and
#: averaging), so this is over a day of shaking; a plan beyond it is a mistyped ``step_hz``,
#: refused before its frequencies are listed (a 1e-9 Hz step over 21-40 Hz would need 142 GiB).
MAX_PLAN_STEPS = 100_000


class PlanTooLarge(ValueError):
    """A plan (or one frequency range of it) with more than :data:`MAX_PLAN_STEPS` steps."""


def _positive(owner: str, name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}.{name}: expected a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{owner}.{name}: must be > 0, got {value!r}")


def _at_least(owner: str, name: str, value: int, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{owner}.{name}: expected an integer >= {minimum}, got {value!r}")


# ------------------------------------------------------------------------ frequencies


_CONTROL_POSITIVE = (
    "max_drive_v",
    "fundamental_amplitude_tolerance",
    "fundamental_phase_tolerance_deg",
    "harmonic_tolerance",
    "max_step_ratio",
    "gain_uncertainty",
    "coupling_uncertainty",
)


@dataclass(frozen=True)
class ControlSettings:
    """Tolerances, estimator prior and safety limits of the force controller.

    Parameters
    ----------
    orders : tuple of Fraction
        Harmonic orders (H); order 1 must be present.
    max_drive_v : float
        Largest allowed peak of the drive waveform [V] (keep it below the output limit).
    fundamental_amplitude_tolerance : float
        Relative amplitude tolerance of the fundamental force.
    fundamental_phase_tolerance_deg : float
        Phase tolerance of the fundamental force [deg].
    harmonic_tolerance : float
        Tolerance of order k relative to its own target: ``|F_k - T_k| <= tol |T_k|``.
    harmonic_floor_ratio : float
        Absolute floor of that tolerance relative to ``|T_1|`` (needed for zero targets).
    max_iterations : int
        Most measurements per step.
    max_step_ratio : float
        Largest drive change per iteration relative to ``|V|`` (2-norm over orders).
    gain_uncertainty : float
        Prior relative standard deviation of the initial diagonal gains.
    coupling_uncertainty : float
        Prior standard deviation of a cross-order gain relative to ``sqrt(|J_ii J_jj|)``.
    gain_drift : float
        Fraction of the prior covariance added before each update (0 keeps every secant,
        right only for a linear plant).
    divergence_patience : int
        Diverged if the error grew over this many consecutive iterations.
    max_gain_ratio : float
        Diverged if a diagonal gain changes magnitude by more than this factor (either way).
    max_gain_phase_change_deg : float
        Diverged if a diagonal gain rotates by more than this [deg].
    max_condition : float
        Diverged if the gain matrix's condition number exceeds this (singular estimate).
    """

    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    max_drive_v: float = 1.0
    fundamental_amplitude_tolerance: float = 0.01
    fundamental_phase_tolerance_deg: float = 1.0
    harmonic_tolerance: float = 0.10
    harmonic_floor_ratio: float = 0.002
    max_iterations: int = 8
    max_step_ratio: float = 0.5
    gain_uncertainty: float = 0.3
    coupling_uncertainty: float = 0.03
    gain_drift: float = 0.3
    divergence_patience: int = 2
    max_gain_ratio: float = 10.0
    max_gain_phase_change_deg: float = 90.0
    max_condition: float = 1e6

    def __post_init__(self) -> None:
        orders = as_orders(self.orders, "ControlSettings.orders")
        if Fraction(1) not in orders:
            raise ValueError("ControlSettings.orders: order 1 (the fundamental) must be present")
        object.__setattr__(self, "orders", orders)
        for name in _CONTROL_POSITIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ControlSettings.{name}: must be finite and > 0, got {value}")
        for name in ("harmonic_floor_ratio", "gain_drift"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"ControlSettings.{name}: must be finite and >= 0, got {value}")
        for name in ("max_iterations", "divergence_patience"):
            if getattr(self, name) < 1:
                raise ValueError(f"ControlSettings.{name}: must be >= 1, got {getattr(self, name)}")
        for name in ("max_gain_ratio", "max_condition"):
            if not getattr(self, name) > 1:
                raise ValueError(f"ControlSettings.{name}: must be > 1, got {getattr(self, name)}")
        if not 0 < self.max_gain_phase_change_deg <= 180:
            raise ValueError(
                "ControlSettings.max_gain_phase_change_deg: must be in (0, 180], got "
                f"{self.max_gain_phase_change_deg}"
            )

    @property
    def fundamental_index(self) -> int:
        """Column of order 1."""
        return self.orders.index(Fraction(1))


@dataclass(frozen=True)
class FrequencyRange:
    """Equally spaced fundamental frequencies ``start_hz, start_hz + step_hz, ..., stop_hz``.

    Parameters
    ----------
    start_hz, stop_hz : float
        First and last frequency [Hz]; ``stop_hz`` must be reached in whole steps.
    step_hz : float
        Spacing [Hz].
    """

    start_hz: float
    stop_hz: float
    step_hz: float

    def __post_init__(self) -> None:
        for name in ("start_hz", "stop_hz", "step_hz"):
            _positive("FrequencyRange", name, getattr(self, name))
        if self.stop_hz < self.start_hz:
            raise ValueError(
                f"FrequencyRange: stop_hz {self.stop_hz} is below start_hz {self.start_hz}"
            )
        n = (self.stop_hz - self.start_hz) / self.step_hz
        if n + 1 > MAX_PLAN_STEPS:
            raise PlanTooLarge(
                f"FrequencyRange: {self.start_hz} to {self.stop_hz} Hz in {self.step_hz} Hz "
                f"steps is {round(n) + 1:,} frequencies, more than a plan may hold "
                f"({MAX_PLAN_STEPS:,} steps): check step_hz"
            )
        if abs(n - round(n)) > 1e-6 * max(1.0, n):
            raise ValueError(
                f"FrequencyRange: {self.start_hz} to {self.stop_hz} Hz is not a whole number of "
                f"{self.step_hz} Hz steps"
            )

    @property
    def count(self) -> int:
        """Number of frequencies (without listing them)."""
        return round((self.stop_hz - self.start_hz) / self.step_hz) + 1

    def frequencies_hz(self) -> np.ndarray:
        """The frequencies, ascending, shape (n,) [Hz]."""
        n = round((self.stop_hz - self.start_hz) / self.step_hz)
        return np.round(self.start_hz + self.step_hz * np.arange(n + 1), _FREQ_DECIMALS)


@dataclass(frozen=True)
class FrequencyPlan:
    """The fundamental frequencies of a sweep and its direction.

    Parameters
    ----------
    ranges : tuple of FrequencyRange
        Their union is swept; frequencies shared by two ranges (within 1e-6 Hz) are measured
        once (the paper: 21-40 Hz in 1 Hz plus 24-28 Hz in 0.1 Hz is 56 frequencies).
    direction : {"up", "down", "up-down", "down-up"}
        Sweep direction at each level; the two-way kinds measure every frequency twice.
    """

    ranges: tuple[FrequencyRange, ...]
    direction: str = "up"

    def __post_init__(self) -> None:
        ranges = tuple(self.ranges)
        if not ranges or not all(isinstance(r, FrequencyRange) for r in ranges):
            raise ValueError("FrequencyPlan.ranges: at least one FrequencyRange is needed")
        if self.direction not in DIRECTIONS:
            raise ValueError(
                f"FrequencyPlan.direction: expected one of {DIRECTIONS}, got {self.direction!r}"
            )
        object.__setattr__(self, "ranges", ranges)

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


@dataclass(frozen=True)
class ExcitationSettings:
    """The multi-sine force and its levels.

    Parameters
    ----------
    orders : tuple of Fraction
        Harmonic orders of the force (order 1 required).
    relative_amplitudes : tuple of float
        Amplitude of each order relative to the fundamental (fundamental 1).
    phases_deg : tuple of float
        Phase of each order relative to its order times the fundamental's phase [deg].
    levels_n : tuple of float
        Fundamental force amplitudes [N], in the order they are run.
    """

    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    relative_amplitudes: tuple[float, ...] = (1.0, 0.02, 0.02)
    phases_deg: tuple[float, ...] | None = None
    levels_n: tuple[float, ...] = (2.0,)

    def __post_init__(self) -> None:
        orders = as_orders(self.orders, "ExcitationSettings.orders")
        phases = self.phases_deg
        if phases is None:
            phases = (0.0,) * len(orders)
        object.__setattr__(self, "orders", orders)
        object.__setattr__(self, "relative_amplitudes", tuple(map(float, self.relative_amplitudes)))
        object.__setattr__(self, "phases_deg", tuple(map(float, phases)))
        levels = tuple(float(v) for v in self.levels_n)
        if not levels:
            raise ValueError("ExcitationSettings.levels_n: at least one level is needed")
        for i, v in enumerate(levels):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"ExcitationSettings.levels_n[{i}]: must be > 0 N, got {v}")
        object.__setattr__(self, "levels_n", levels)
        _ = self.spec  # validates amplitudes and phases against the orders

    @property
    def spec(self) -> MultisineSpec:
        """The force shape for :mod:`rig.signals.multisine`."""
        try:
            return MultisineSpec(
                self.orders,
                self.relative_amplitudes,
                tuple(math.radians(p) for p in self.phases_deg),
            )
        except ValueError as exc:
            raise ValueError(str(exc).replace("MultisineSpec", "ExcitationSettings")) from None


@dataclass(frozen=True)
class AcquisitionSettings:
    """Settling, averaging and ramps of a stepped-sine step.

    Parameters
    ----------
    block_periods : int
        Base periods per block (the unit of averaging and of the settling test).
    average_blocks : int
        Blocks averaged for each force-control measurement (>= 4, the settling test needs them).
    record_blocks : int
        Blocks averaged for the recorded step (>= ``average_blocks``): after the controller
        accepts a drive, acquisition continues at that drive to this many blocks.
    settle_periods : int
        Base periods waited after a frequency or level change before blocks count.
    correction_settle_periods : int
        Base periods waited after a force-control correction (a small drive change).
    max_settle_periods : int
        Longest wait for the settling test to pass; the step then goes on and a warning says so.
    settling_tolerance : float
        Allowed change of the fundamental phasors between consecutive blocks, relative.
    drift_tolerance : float
        Allowed difference between the means of the two halves of the averaged blocks,
        relative (a slow drift that the block-to-block test misses).
    ramp_s : float
        Cross-fade between drive waveforms [s].
    store_raw : bool
        Keep the averaged time blocks of each recorded step in the file (``/raw``).
    force_orders_up_to : int
        Also record the drive force at every whole order up to this one that the drive does
        not contain (the file's extra orders). Where the structure responds nonlinearly the
        shaker pushes back at the harmonics of the response, and a model driven by the
        measured force needs those forces too; 0: the drive's orders only.
    """

    block_periods: int = 1
    average_blocks: int = 16
    record_blocks: int = 48
    settle_periods: int = 20
    correction_settle_periods: int = 10
    max_settle_periods: int = 400
    settling_tolerance: float = 0.01
    drift_tolerance: float = 0.005
    ramp_s: float = 0.05
    store_raw: bool = False
    force_orders_up_to: int = 0

    def __post_init__(self) -> None:
        owner = "AcquisitionSettings"
        _at_least(owner, "force_orders_up_to", self.force_orders_up_to, 0)
        _at_least(owner, "block_periods", self.block_periods, 1)
        _at_least(owner, "average_blocks", self.average_blocks, 4)
        _at_least(owner, "record_blocks", self.record_blocks, self.average_blocks)
        _at_least(owner, "settle_periods", self.settle_periods, 0)
        _at_least(owner, "correction_settle_periods", self.correction_settle_periods, 0)
        _at_least(owner, "max_settle_periods", self.max_settle_periods, self.settle_periods)
        for name in ("settling_tolerance", "drift_tolerance", "ramp_s"):
            _positive(owner, name, getattr(self, name))


@dataclass(frozen=True)
class ControlPolicy:
    """Force control of each step.

    Parameters
    ----------
    settings : ControlSettings
        Tolerances and limits of :class:`rig.procedures.force_control.ForceController` (its
        ``max_drive_v`` is
        the plan's drive limit, its orders the excitation's).
    uncertainty_factor : float
        A measured force phasor also counts as on target when its deviation from the target is
        within this many standard errors of the measurement (a deviation the averaging cannot
        resolve is not chased); 0 switches this off.
    warm_start : bool
        Start each step from the previous step's gain estimate (otherwise from the loop check).
    on_divergence : {"abort", "record"}
        When the iteration diverges: stop the run (the loop is not behaving physically), or
        record the best measurement flagged as not converged and go on.
    restart_after : int
        Start the iteration again, from the force per volt of the latest measurement, when
        after this many iterations the latest error is above 10 % and twice the best so far
        (0: never). Near the fold of a nonlinear resonance the response can jump to another
        branch; the gain learnt before the jump then misleads the controller. The total number
        of measurements per step stays within ``max_iterations``.
    divergence_abort_error : float
        With ``"abort"``: a diverged step whose best error (``max_k |F_k - T_k| / |T_1|``) is
        below this is recorded flagged as not converged and the run goes on (near a jump of a
        nonlinear response the iteration can wander without anything being wrong); above it
        the run stops.
    """

    settings: ControlSettings = field(default_factory=ControlSettings)
    uncertainty_factor: float = 2.0
    warm_start: bool = True
    on_divergence: str = "abort"
    divergence_abort_error: float = 0.5
    restart_after: int = 4

    def __post_init__(self) -> None:
        if not isinstance(self.settings, ControlSettings):
            raise ValueError("ControlPolicy.settings: expected ControlSettings")
        f = self.uncertainty_factor
        if isinstance(f, bool) or not (math.isfinite(f) and f >= 0):
            raise ValueError(f"ControlPolicy.uncertainty_factor: must be >= 0, got {f!r}")
        r = self.restart_after
        if isinstance(r, bool) or not isinstance(r, int) or r < 0:
            raise ValueError(f"ControlPolicy.restart_after: expected an integer >= 0, got {r!r}")
        e = self.divergence_abort_error
        if isinstance(e, bool) or not (math.isfinite(e) and e > 0):
            raise ValueError(f"ControlPolicy.divergence_abort_error: must be > 0, got {e!r}")
        if self.on_divergence not in ("abort", "record"):
            raise ValueError(
                f"ControlPolicy.on_divergence: expected 'abort' or 'record', "
                f"got {self.on_divergence!r}"
            )


# ------------------------------------------------------------------------ limits and pretest


@dataclass(frozen=True)
class ResponseLimit:
    """Alarm and abort limits of one channel (separate from the drive limit).

    The channel is named directly or by its point (the acceleration channel at that point).
    An alarm warns once per step; an abort stops the run with the output ramped to 0 V. Peaks
    are checked on every block read; displacement is the acceleration integrated twice over the
    excited band.

    Parameters
    ----------
    channel : str
        Channel name ("" when ``point`` is given).
    point : int
        Measurement point (-1 when ``channel`` is given).
    acceleration_alarm_m_s2, acceleration_abort_m_s2 : float, optional
        Peak acceleration limits [m/s^2].
    displacement_alarm_m, displacement_abort_m : float, optional
        Peak displacement limits [m].
    force_alarm_n, force_abort_n : float, optional
        Peak force limits [N] (force channels).
    """

    channel: str = ""
    point: int = -1
    acceleration_alarm_m_s2: float | None = None
    acceleration_abort_m_s2: float | None = None
    displacement_alarm_m: float | None = None
    displacement_abort_m: float | None = None
    force_alarm_n: float | None = None
    force_abort_n: float | None = None

    _PAIRS: ClassVar[tuple[tuple[str, str], ...]] = (
        ("acceleration_alarm_m_s2", "acceleration_abort_m_s2"),
        ("displacement_alarm_m", "displacement_abort_m"),
        ("force_alarm_n", "force_abort_n"),
    )

    def __post_init__(self) -> None:
        owner = f"ResponseLimit {self.target}"
        if bool(self.channel) == (self.point >= 0):
            raise ValueError("ResponseLimit: give either channel or point (not both, not neither)")
        given = False
        for alarm, abort in self._PAIRS:
            for name in (alarm, abort):
                value = getattr(self, name)
                if value is not None:
                    _positive(owner, name, value)
                    given = True
            a, b = getattr(self, alarm), getattr(self, abort)
            if a is not None and b is not None and a >= b:
                raise ValueError(f"{owner}: {alarm} ({a}) must be below {abort} ({b})")
        if not given:
            raise ValueError(f"{owner}: no limit given")

    @property
    def target(self) -> str:
        """``"channel NAME"`` or ``"point N"``."""
        return f"channel {self.channel!r}" if self.channel else f"point {self.point}"


@dataclass(frozen=True)
class Limits:
    """Safety limits of a run.

    Parameters
    ----------
    drive_peak_v : float
        Largest drive-waveform peak the run may apply [V] (below the setup's AO limit).
    response : tuple of ResponseLimit
        Per-channel alarm and abort limits.
    """

    drive_peak_v: float = 1.0
    response: tuple[ResponseLimit, ...] = ()

    def __post_init__(self) -> None:
        _positive("Limits", "drive_peak_v", self.drive_peak_v)
        object.__setattr__(self, "response", tuple(self.response))


@dataclass(frozen=True)
class PretestSettings:
    """Checks before the test: noise floor, loop check, channel sanity.

    Parameters
    ----------
    enabled : bool
        Run the pretest (without it the first step starts from ``loop_check``-free defaults).
    noise_s : float
        Length of the noise-floor record at 0 V [s].
    loop_check_drive_v : float
        Drive amplitude of every order in the low-level loop check [V] (stepped sine).
    loop_check_frequency_hz : float
        Fundamental of the loop check [Hz]; 0: the plan's first frequency.
    min_snr : float
        A channel whose response to the loop check is below this many noise standard errors
        is reported as not responding.
    """

    enabled: bool = True
    noise_s: float = 1.0
    loop_check_drive_v: float = 0.02
    loop_check_frequency_hz: float = 0.0
    min_snr: float = 5.0

    def __post_init__(self) -> None:
        for name in ("noise_s", "loop_check_drive_v", "min_snr"):
            _positive("PretestSettings", name, getattr(self, name))
        f = self.loop_check_frequency_hz
        if not (math.isfinite(f) and f >= 0):
            raise ValueError(f"PretestSettings.loop_check_frequency_hz: must be >= 0, got {f}")


@dataclass(frozen=True)
class RandomExcitation:
    """Band-limited random force of the linear test.

    Parameters
    ----------
    f_lo_hz, f_hi_hz : float
        Excited band [Hz].
    force_rms_n : float
        RMS drive force aimed at [N] (low, so that the gap never closes).
    signal : {"periodic", "gaussian"}
        Periodic random (flat spectrum, random phases; leakage-free with a rectangular window)
        or Gaussian random.
    record_s : float
        Length of one record (one period of the drive) [s]; the frequency resolution of a
        periodic-random test is ``1 / record_s``.
    seed : int
        Random state of the drive.
    calibration_drive_rms_v : float
        RMS drive of the short record that measures the force per volt [V].
    """

    f_lo_hz: float = 10.0
    f_hi_hz: float = 200.0
    force_rms_n: float = 0.3
    signal: str = "periodic"
    record_s: float = 8.0
    seed: int = 1
    calibration_drive_rms_v: float = 0.003

    def __post_init__(self) -> None:
        owner = "RandomExcitation"
        for name in ("f_lo_hz", "f_hi_hz", "force_rms_n", "record_s", "calibration_drive_rms_v"):
            _positive(owner, name, getattr(self, name))
        if self.f_hi_hz <= self.f_lo_hz:
            raise ValueError(f"{owner}: f_hi_hz ({self.f_hi_hz}) must exceed f_lo_hz")
        if self.signal not in RANDOM_KINDS:
            raise ValueError(f"{owner}.signal: expected one of {RANDOM_KINDS}, got {self.signal!r}")
        _at_least(owner, "seed", self.seed, 0)


@dataclass(frozen=True)
class RandomAcquisition:
    """Records and spectral averaging of the random test.

    Parameters
    ----------
    settle_records : int
        Records discarded after the drive starts (the transient).
    average_records : int
        Records acquired for the H1 estimate.
    window : str
        Window of the Welch average (``"boxcar"`` for periodic random).
    overlap : float
        Segment overlap, fraction in [0, 1).
    segments_per_record : int
        Welch segments per record (1: one segment is one record).
    ramp_s : float
        Fade in and out of the drive [s].
    """

    settle_records: int = 1
    average_records: int = 8
    window: str = "boxcar"
    overlap: float = 0.0
    segments_per_record: int = 1
    ramp_s: float = 0.2

    def __post_init__(self) -> None:
        owner = "RandomAcquisition"
        _at_least(owner, "settle_records", self.settle_records, 0)
        _at_least(owner, "average_records", self.average_records, 1)
        _at_least(owner, "segments_per_record", self.segments_per_record, 1)
        if not (math.isfinite(self.overlap) and 0 <= self.overlap < 1):
            raise ValueError(f"{owner}.overlap: must be in [0, 1), got {self.overlap}")
        if not isinstance(self.window, str) or not self.window:
            raise ValueError(f"{owner}.window: expected a window name, got {self.window!r}")
        _positive(owner, "ramp_s", self.ramp_s)
