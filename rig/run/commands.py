"""The commands a procedure yields to the engine, and what the engine sends back.

A procedure (:mod:`rig.procedures.stepped_sine`, :mod:`rig.procedures.random_test`,
:mod:`rig.procedures.pretest`) is a generator:
it yields a command, the engine executes it against the backend and sends the result back in::

    applied = yield SetDrive(25.0, drive_v, orders)      # -> DriveApplied
    m = yield Acquire(settle_periods=20, blocks=16)       # -> Measurement
    yield WriteStep(record, control)                      # -> None

Procedures never touch hardware, so a test drives them with a stand-in that records the
commands and answers from a model plant.

=================  ===================  ====================================================
command            result               what the engine does
=================  ===================  ====================================================
SetDrive           DriveApplied         synthesise a multi-sine period, cross-fade to it
SetWaveform        WaveformApplied      cross-fade to an arbitrary periodic record
Acquire            Measurement          settle, read phase-synchronous blocks, settling test,
                                        average; checks limits on every block read
AcquireRecords     Records              read whole records of the current waveform
BeginStep          None                 pause/abort checkpoint, ``StepStarted`` event
WriteStep          None                 append the step to the file (flushed), event
WriteRandom        None                 write the random test's FRFs
Notify             None                 publish an event
Warn               None                 log and publish a warning
=================  ===================  ====================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np

from rig.estimation.harmonics import HarmonicEstimate
from rig.signals.multisine import PeriodPlan

__all__ = [
    "Acquire",
    "AcquireRecords",
    "BeginStep",
    "DriveApplied",
    "Measurement",
    "Notify",
    "Records",
    "RunContext",
    "SetDrive",
    "SetWaveform",
    "Warn",
    "WaveformApplied",
    "WriteRandom",
    "WriteStep",
]


@dataclass(frozen=True)
class RunContext:
    """What a procedure knows about the run it is part of.

    Attributes
    ----------
    sample_rate_hz : float
        Realised sample rate of the backend [Hz].
    channels : tuple of rig.config.setup.ChannelSetup
        Acquired channels, in column order of every phasor and sample array.
    drive_force_index : int
        Column of the drive-force channel.
    drive_limit_v : float
        The setup's hard output limit [V].
    """

    sample_rate_hz: float
    channels: tuple[Any, ...]
    drive_force_index: int
    drive_limit_v: float

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)


# ------------------------------------------------------------------------ drive


@dataclass(frozen=True, eq=False)
class SetDrive:
    """Apply a multi-sine drive (regenerated until the next drive command).

    Attributes
    ----------
    frequency_hz : float
        Requested fundamental [Hz]; the realised one comes back in :class:`DriveApplied`.
    drive_v : ndarray, shape (H,), complex, V
        Output phasor of each order.
    orders : tuple of Fraction
    ramp_s : float
        Cross-fade from the present output [s].
    """

    frequency_hz: float
    drive_v: np.ndarray
    orders: tuple[Fraction, ...]
    ramp_s: float = 0.05


@dataclass(frozen=True, eq=False)
class DriveApplied:
    """Result of :class:`SetDrive`.

    Attributes
    ----------
    period : PeriodPlan
        Samples per base period and the realised frequencies.
    steady_index : int
        Sample index from which the new waveform is in force, on a period boundary.
    drive_v : ndarray, shape (H,), complex, V
    """

    period: PeriodPlan
    steady_index: int
    drive_v: np.ndarray

    @property
    def frequency_hz(self) -> float:
        """Realised fundamental frequency [Hz]."""
        return self.period.fundamental_hz


@dataclass(frozen=True, eq=False)
class SetWaveform:
    """Apply an arbitrary periodic waveform (e.g. a random record).

    Attributes
    ----------
    period_v : ndarray, shape (n,), V
        One period, regenerated.
    ramp_s : float
        Cross-fade from the present output [s].
    band_hz : (float, float)
        Excited band [Hz] (for the displacement limits).
    label : str
    """

    period_v: np.ndarray
    ramp_s: float
    band_hz: tuple[float, float]
    label: str = ""


@dataclass(frozen=True)
class WaveformApplied:
    """Result of :class:`SetWaveform`: period length and the index it is in force from."""

    samples_per_period: int
    steady_index: int
    peak_v: float


# ------------------------------------------------------------------------ acquisition


@dataclass(frozen=True)
class Acquire:
    """Settle, then average phase-synchronous blocks of the multi-sine in force.

    Attributes
    ----------
    settle_periods : int
        Base periods to wait after the drive came into force (0: continue right after the
        previous acquisition, e.g. to extend an average).
    blocks : int
        Blocks averaged (>= 2 for standard errors, >= 4 for the settling test).
    block_periods : int
        Base periods per block.
    max_settle_periods : int, optional
        With a settling test: the longest wait; None: no settling test.
    settling_tolerance : float
        Allowed relative change of the fundamental between consecutive blocks.
    drift_tolerance : float
        Allowed relative difference between the means of the window's two halves.
    keep_samples : bool
        Return the averaged samples (for ``/raw``).
    check_signals : bool
        Check for silent and saturated sensors (off for a noise-floor record at 0 V).
    purpose : str
        ``"noise"``, ``"loop-check"``, ``"control"`` or ``"record"`` (for logs and events).
    extra_orders : tuple of Fraction
        Orders the drive does not contain to estimate as well (:attr:`Measurement.extra`).
    """

    settle_periods: int
    blocks: int
    block_periods: int = 1
    max_settle_periods: int | None = None
    settling_tolerance: float = 0.01
    drift_tolerance: float = 0.005
    keep_samples: bool = False
    check_signals: bool = True
    purpose: str = "control"
    extra_orders: tuple = ()


@dataclass(frozen=True, eq=False)
class Measurement:
    """Result of :class:`Acquire`.

    Attributes
    ----------
    estimate : HarmonicEstimate
        Phasors, standard errors and block phasors of every channel (C, H).
    frequency_hz : float
        Realised fundamental [Hz].
    first_index : int
        Sample index of the first averaged block (the phase origin).
    settled : bool
        The settling test passed (True when none was asked for).
    settle_periods : int
        Base periods between the drive coming into force and the first averaged block.
    settling_message : str
    rms : ndarray, shape (C,)
        Standard deviation of the averaged samples of each channel (channel units).
    samples : ndarray, shape (n, C), optional
        The averaged samples (``keep_samples``).
    extra : HarmonicEstimate, optional
        The same blocks at :attr:`Acquire.extra_orders` (None when none were asked for).
    """

    estimate: HarmonicEstimate
    frequency_hz: float
    first_index: int
    settled: bool
    settle_periods: int
    settling_message: str
    rms: np.ndarray
    samples: np.ndarray | None = None
    extra: HarmonicEstimate | None = None

    @property
    def phasors(self) -> np.ndarray:
        """Averaged phasors, shape (C, H), complex, channel units."""
        return self.estimate.phasors

    @property
    def std(self) -> np.ndarray:
        """Standard errors, shape (C, H), channel units (NaN with a single block)."""
        return self.estimate.std

    @property
    def n_blocks(self) -> int:
        return int(self.estimate.block_phasors.shape[0])


@dataclass(frozen=True)
class AcquireRecords:
    """Read whole periods (records) of the waveform in force.

    Attributes
    ----------
    records : int
        Records returned.
    settle_records : int
        Records read and discarded first (beyond the cross-fade).
    purpose : str
        ``"noise"``, ``"calibration"`` or ``"average"`` (events and logs).
    """

    records: int
    settle_records: int = 0
    purpose: str = "average"


@dataclass(frozen=True, eq=False)
class Records:
    """Result of :class:`AcquireRecords`.

    Attributes
    ----------
    samples : ndarray, shape (records * n, C), channel units
    first_index : int
        Sample index of the first returned sample (a period start of the waveform).
    samples_per_record : int
    sample_rate_hz : float
    """

    samples: np.ndarray
    first_index: int
    samples_per_record: int
    sample_rate_hz: float


# ------------------------------------------------------------------------ bookkeeping


@dataclass(frozen=True)
class BeginStep:
    """A stepped-sine step begins (a pause/abort checkpoint).

    Attributes
    ----------
    step : rig.config.plans.PlannedStep
    n_steps : int
    """

    step: Any
    n_steps: int


@dataclass(frozen=True, eq=False)
class WriteStep:
    """Append a completed step to the measurement file.

    Attributes
    ----------
    record : analysis.measurement_file.StepRecord
    control : rig.procedures.force_control.StepControlRecord, optional
    samples : ndarray, shape (n, C), optional
        Raw time data of the averaged blocks (stored when the file has ``/raw``).
    t0_s : float
        Time of the first raw sample after the drive started [s].
    settled : bool
    """

    record: Any
    control: Any = None
    samples: np.ndarray | None = None
    t0_s: float = 0.0
    settled: bool = True


@dataclass(frozen=True, eq=False)
class WriteRandom:
    """Write the random test's H1 estimate (:class:`analysis.measurement_file.RandomFRF`)."""

    frf: Any


@dataclass(frozen=True)
class Notify:
    """Publish an event (:mod:`rig.run.events`)."""

    event: Any


@dataclass(frozen=True)
class Warn:
    """Log and publish a warning; ``kind`` is a short tag."""

    kind: str
    message: str
    channel: str = ""
