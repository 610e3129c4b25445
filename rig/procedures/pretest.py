"""Checks before a test: noise floor, low-level loop check, channel sanity.

The pretest is procedure code (it yields :mod:`rig.run.commands`), run by the engine at the start
of a plan:

1. **noise floor**: the drive at 0 V, every channel recorded; its standard deviation is the
   channel's noise floor (a channel with every sample equal is *flat*: dead sensor or input);
2. **loop check** (stepped sine): every order driven at a low voltage; the force phasors give the
   drive-to-force gain that starts the force controller
   (:func:`rig.procedures.force_control.loop_check_gain`),
   and every channel must respond above its noise (``min_snr`` standard errors), otherwise it is
   reported by name as not responding (disconnected sensor, IEPE open circuit);
3. for a random test, the calibration record plays the loop check's part
   (:func:`check_random_response`).

A channel that is flat or does not respond makes the run stop before the test with a
``pretest`` fault naming the channel.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from rig.config.plans import PretestSettings, SteppedSinePlan
from rig.procedures.force_control import loop_check_gain
from rig.run.commands import Acquire, Measurement, Notify, RunContext, SetDrive
from rig.run.events import PretestFinished

__all__ = [
    "ChannelCheck",
    "PretestReport",
    "band_rms",
    "check_random_response",
    "pretest_procedure",
    "stepped_pretest",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ChannelCheck:
    """Verdict on one channel.

    Attributes
    ----------
    name : str
    point : int
    status : {"ok", "flat", "silent", "weak"}
        ``flat`` and ``silent`` stop the test; ``weak`` (a random test's channel with no
        response above its noise) is a warning.
    noise_rms : float
        Standard deviation at 0 V (channel units).
    response : float
        Amplitude of the response to the loop check (channel units; NaN if not measured).
    snr : float
        ``response`` over the noise standard error of a phasor of the same record length.
    message : str
        Empty when ``ok``.
    """

    name: str
    point: int
    status: str
    noise_rms: float
    response: float
    snr: float
    message: str = ""


@dataclass(frozen=True, eq=False)
class PretestReport:
    """Result of the pretest.

    Attributes
    ----------
    frequency_hz : float
        Realised fundamental of the loop check [Hz] (NaN for a random test).
    channels : tuple of ChannelCheck
    drive_v : ndarray, shape (H,), complex, V
        Loop-check drive (empty for a random test).
    force_n : ndarray, shape (H,), complex, N
        Force measured in the loop check.
    gain_n_per_v : ndarray, shape (H,), complex, N/V, or None
        Drive-to-force gain per order (None when no force was measured).
    """

    frequency_hz: float
    channels: tuple[ChannelCheck, ...]
    drive_v: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    gain_n_per_v: np.ndarray | None = None

    @property
    def problems(self) -> tuple[ChannelCheck, ...]:
        """Channels that stop the test (flat or silent)."""
        return tuple(c for c in self.channels if c.status in ("flat", "silent"))

    @property
    def doubtful(self) -> tuple[ChannelCheck, ...]:
        """Channels worth a look that do not stop the test (``weak``)."""
        return tuple(c for c in self.channels if c.status == "weak")

    @property
    def ok(self) -> bool:
        return not self.problems

    def problem_message(self) -> str:
        """One sentence per problem channel."""
        return "pretest: " + "; ".join(c.message for c in self.problems)

    def summary(self) -> list[str]:
        """Lines for a console: noise floor and response of every channel, the gain."""
        lines = []
        for c in self.channels:
            resp = (
                "" if math.isnan(c.response) else f", response {c.response:.3g} (SNR {c.snr:.0f})"
            )
            lines.append(f"  {c.name:8s} noise {c.noise_rms:.3g}{resp}: {c.status}")
        if self.gain_n_per_v is not None:
            g = ", ".join(f"{abs(v):.3g} N/V" for v in self.gain_n_per_v)
            lines.append(f"  loop gain at {self.frequency_hz:.4g} Hz: {g}")
        return lines


def _describe(ch) -> str:
    return f"channel {ch.name!r} (point {ch.point} {ch.direction})"


def stepped_pretest(
    settings: PretestSettings,
    ctx: RunContext,
    orders: Sequence[Fraction],
    frequency_hz: float,
    ramp_s: float = 0.05,
) -> Generator[object, Any, PretestReport]:
    """Noise floor and loop check for a stepped-sine test (``yield from`` it in a procedure).

    Parameters
    ----------
    settings : PretestSettings
    ctx : RunContext
    orders : sequence of Fraction
        The excitation's orders.
    frequency_hz : float
        Fundamental of the loop check [Hz].
    ramp_s : float
        Drive cross-fade [s].

    Returns
    -------
    PretestReport
    """
    orders = tuple(orders)
    h = len(orders)
    periods = max(8, math.ceil(settings.noise_s * frequency_hz / _denominator(orders)))
    yield SetDrive(frequency_hz, np.zeros(h, complex), orders, ramp_s)
    noise = yield Acquire(settle_periods=2, blocks=periods, check_signals=False, purpose="noise")
    drive = np.full(h, settings.loop_check_drive_v, dtype=complex)
    applied = yield SetDrive(frequency_hz, drive, orders, ramp_s)
    loop = yield Acquire(
        settle_periods=20,
        blocks=periods,
        max_settle_periods=400,
        check_signals=False,
        purpose="loop-check",
    )
    i1 = orders.index(Fraction(1))
    checks = _channel_checks(ctx, noise, loop, i1, settings.min_snr, applied.frequency_hz)
    force = loop.phasors[ctx.drive_force_index]
    gain = None
    if checks[ctx.drive_force_index].status == "ok" and np.all(np.abs(force) > 0):
        gain = loop_check_gain(drive, force)
    report = PretestReport(applied.frequency_hz, tuple(checks), drive, force.copy(), gain)
    for line in report.summary():
        logger.info("pretest:%s", line)
    return report


def _denominator(orders: Sequence[Fraction]) -> int:
    return math.lcm(*(Fraction(o).denominator for o in orders))


def _channel_checks(
    ctx: RunContext,
    noise: Measurement,
    loop: Measurement,
    i1: int,
    min_snr: float,
    frequency_hz: float,
) -> list[ChannelCheck]:
    n_total = loop.estimate.block_phasors.shape[0] * loop.estimate.samples_per_block
    out = []
    for c, ch in enumerate(ctx.channels):
        floor = float(noise.rms[c])
        response = float(abs(loop.phasors[c, i1]))
        sigma = 2.0 * floor / math.sqrt(n_total)
        snr = response / sigma if sigma > 0 else math.inf
        if floor == 0.0 or float(loop.rms[c]) == 0.0:
            status = "flat"
            message = (
                f"{_describe(ch)} is flat (every sample equal): dead sensor or input; check the "
                "sensor, its cable and the IEPE supply"
            )
        elif ch.quantity != "voltage" and snr < min_snr:
            status = "silent"
            what = "no force at the drive point: " if ch.role == "drive-force" else ""
            cause = (
                "the amplifier is off, muted or tripped, or the shaker is not connected"
                if ch.role == "drive-force"
                else "the sensor or its cable is disconnected (IEPE open circuit?)"
            )
            message = (
                f"{what}{_describe(ch)} does not respond to the loop check: "
                f"{response:.3g} {ch.unit} at {frequency_hz:.4g} Hz against a noise level of "
                f"{sigma:.2g} {ch.unit} (SNR {snr:.1f} < {min_snr:g}); {cause}"
            )
        else:
            status, message = "ok", ""
        out.append(ChannelCheck(ch.name, ch.point, status, floor, response, snr, message))
    return out


def check_random_response(
    ctx: RunContext,
    noise: np.ndarray,
    response: np.ndarray,
    samples_per_record: int,
    band_hz: tuple[float, float],
    min_snr: float,
) -> PretestReport:
    """Channel sanity of a random test from a 0 V record and two periods of the calibration drive.

    The calibration drive is periodic (one record is one period), so what a live sensor sees
    repeats from one record to the next and its noise does not. Over the DFT bins of the band,
    ``R = sum |X1 + X2|^2 / sum |X1 - X2|^2`` is 1 (to ``sqrt(2 / n_bins)``) for a channel that
    sees only noise and grows with its response; ``snr = (R - 1) / sqrt(2 / n_bins)``.

    Parameters
    ----------
    ctx : RunContext
    noise : ndarray, shape (n, C)
        Record at 0 V (channel units).
    response : ndarray, shape (2 * samples_per_record, C)
        Two consecutive periods of the calibration drive's response.
    samples_per_record : int
    band_hz : (float, float)
        Excited band [Hz].
    min_snr : float
        A channel below it is reported ``weak`` (a warning: a low-level broadband test cannot
        tell a disconnected sensor from one on a point that barely moves); a flat channel
        (every sample equal) is a problem.

    Returns
    -------
    PretestReport
    """
    n = samples_per_record
    x1, x2 = response[:n], response[n : 2 * n]
    f = np.fft.rfftfreq(n, 1.0 / ctx.sample_rate_hz)
    keep = (f >= band_hz[0]) & (f <= band_hz[1]) & (f > 0)
    s1, s2 = np.fft.rfft(x1, axis=0)[keep], np.fft.rfft(x2, axis=0)[keep]
    common = np.sum(np.abs(s1 + s2) ** 2, axis=0)
    differ = np.sum(np.abs(s1 - s2) ** 2, axis=0)
    scale = math.sqrt(2.0 / max(int(keep.sum()), 1))
    checks = []
    for c, ch in enumerate(ctx.channels):
        floor = float(np.std(noise[:, c]))
        ratio = float(common[c] / differ[c]) if differ[c] > 0 else math.inf
        snr = (ratio - 1.0) / scale
        rms = float(band_rms(x1[:, [c]], ctx.sample_rate_hz, band_hz)[0])
        if floor == 0.0 or float(np.ptp(response[:, c])) == 0.0:
            status = "flat"
            message = f"{_describe(ch)} is flat (every sample equal): dead sensor or input"
        elif ch.quantity != "voltage" and snr < min_snr:
            status = "weak"
            message = (
                f"{_describe(ch)} shows no response above its noise to the calibration drive "
                f"(periodic-to-noise statistic {snr:.1f} < {min_snr:g}); check the sensor if "
                "its point should move"
            )
        else:
            status, message = "ok", ""
        checks.append(ChannelCheck(ch.name, ch.point, status, floor, rms, snr, message))
    return PretestReport(math.nan, tuple(checks))


def band_rms(x: np.ndarray, fs: float, band_hz: tuple[float, float]) -> np.ndarray:
    """RMS of each column within a frequency band.

    Parameters
    ----------
    x : ndarray, shape (n, C)
    fs : float
        Sample rate [Hz].
    band_hz : (float, float)

    Returns
    -------
    ndarray, shape (C,)
        ``sqrt(2 sum |X_k|^2) / n`` over the DFT bins in the band (Parseval).
    """
    n = x.shape[0]
    spectrum = np.fft.rfft(x - x.mean(axis=0), axis=0)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    keep = (f >= band_hz[0]) & (f <= band_hz[1])
    return np.sqrt(2.0 * np.sum(np.abs(spectrum[keep]) ** 2, axis=0)) / n


def pretest_procedure(plan: SteppedSinePlan):
    """The pretest of a stepped-sine plan alone: noise floor, loop check, channel checks, at the
    frequency the plan's run would use (:func:`rig.procedures.pretest.stepped_pretest`)."""

    def procedure(ctx):
        f0 = plan.pretest.loop_check_frequency_hz or plan.steps()[0].frequency_hz
        report = yield from stepped_pretest(
            plan.pretest, ctx, plan.excitation.orders, f0, plan.acquisition.ramp_s
        )
        yield Notify(PretestFinished(report))

    return procedure
