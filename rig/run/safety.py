"""Checks on every block read, and keeping Ctrl-C from interrupting a ramp-down.

:class:`SignalChecks` is what the engine runs on the data as they arrive:

- input range: a sample at a channel's ADC range means the channel clipped (fault ``clipping``);
- response limits (:class:`rig.config.plans.ResponseLimit`): peak acceleration or force of every
block,
  and peak displacement (acceleration integrated twice over the excited band); an alarm warns
  once per step, an abort ends the run (fault ``response-limit``);
- after each averaged measurement: a flat channel (every sample equal) or one whose fundamental
  is at its noise level (below ``SILENT_SNR`` standard errors) in ``SILENT_STRIKES`` measurements
  in a row while the drive is on, its response per newton having fallen to a fifth of what it
  was (``SILENT_DROP``) (fault ``sensor``; on the drive-force channel, one measurement at the
  noise level: ``no-force``); a live sensor that responds weakly (an antiresonance, a low
  level) stays where it was from step to step, a dead one drops to its noise;
- the shaker's coil current, estimated after each measurement from the drive point's force and
  acceleration (:class:`analysis.planning.drive_current.ShakerDrive`, when the setup gives the
  armature mass, the force constant and the amplifier's current limit): a warning once per step
  near the limit, and a force lost after a measurement near it is named as the amplifier's
  overload trip;
  and a waveform flat-topped at both peaks, the mark of a saturated sensor (``clipping``):
  near the signal chain's full scale (the sensor's output swing or the input range) a slight
  plateau is enough; far below it a sensor saturates only when it is faulty, and a structure's
  own waveform can flatten its peaks (harmonics in phase), so the plateau must be flatter than
  smooth harmonics make a peak (:func:`peak_exponent`; ``docs/acquisition.md``, "Saturated
  sensors").

Process-level safety: :func:`deferred_interrupts` holds Ctrl-C while the output ramps down or a
step is written; :func:`interrupt_handlers` turns Ctrl-C and SIGTERM into a clean abort of a
running engine (a second Ctrl-C interrupts at once).
"""

from __future__ import annotations

import logging
import math
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from analysis.planning.drive_current import ShakerDrive
from rig.config.plans import Limits
from rig.run.faults import RunFault

__all__ = [
    "ResolvedLimit",
    "SignalChecks",
    "deferred_interrupts",
    "displacement_peak",
    "flat_tops",
    "interrupt_handlers",
    "peak_exponent",
    "resolve_limits",
]

logger = logging.getLogger(__name__)

SILENT_SNR = 3.0  # a fundamental below this many noise standard errors is "no response"
SILENT_STRIKES = 2  # consecutive silent measurements before a channel counts as dead
SILENT_DROP = 0.2  # ... and only if its response per newton fell below this share of before
#: a force lost after a measurement whose estimated coil current was at least this share of the
#: amplifier's limit is named as the overload trip (the controller's first drive at the next
#: frequency overshoots, and the current rises steeply toward a resonance of the drive point)
TRIP_LIKELY = 0.5
#: A waveform whose peaks are flatter than this (:func:`peak_exponent`) at a level of at least
#: ``PLATEAU_NEAR_FULL_SCALE`` of the channel's full scale: a sensor at the end of its swing
#: (a sine cut at about 92 % of its amplitude).
PLATEAU_EXPONENT = 4.0
PLATEAU_NEAR_FULL_SCALE = 0.1
#: ... flatter than this at any level: saturated whatever the level. Smooth peaks from orders 1
#: to 5 stay at 5 or below however they combine; a plateau needs a constant net force on the
#: point over part of every cycle, which no contact or friction law makes of an acceleration. A
#: sine cut at 80 % of its amplitude (order 1 then 10 % low) reaches it without noise.
PLATEAU_EXPONENT_ANY_LEVEL = 6.0
_PLATEAU_HARMONICS = 20  # harmonics of the base kept to denoise the period average
_PEAK_DEPTHS = 10.0  # the two depths below a peak whose times give its exponent


def _describe(channel) -> str:
    extra = f", serial {channel.serial}" if getattr(channel, "serial", "") else ""
    if channel.quantity == "voltage":
        return f"channel {channel.name!r}{extra}"
    return f"channel {channel.name!r} (point {channel.point} {channel.direction}{extra})"


@dataclass(frozen=True)
class ResolvedLimit:
    """One limit on one acquired channel.

    Attributes
    ----------
    column : int
        Channel column.
    quantity : {"peak", "displacement"}
        ``peak``: the channel's own peak (acceleration or force); ``displacement``: the
        twice-integrated acceleration.
    alarm, abort : float or None
        Limits in channel units (peak) or m (displacement).
    unit : str
    """

    column: int
    quantity: str
    alarm: float | None
    abort: float | None
    unit: str


def resolve_limits(limits: Limits, channels: Sequence) -> list[ResolvedLimit]:
    """Attach the plan's response limits to the acquired channels.

    Raises
    ------
    ValueError
        If a limit names a channel or point that is not acquired, or a limit that does not fit
        the channel's quantity (displacement of a force channel).
    """
    names = [c.name for c in channels]
    out = []
    for i, lim in enumerate(limits.response):
        where = f"limits.response[{i}] ({lim.target})"
        if lim.channel:
            if lim.channel not in names:
                raise ValueError(f"{where}: channel not acquired by this plan (channels {names})")
            col = names.index(lim.channel)
        else:
            cols = [
                j
                for j, c in enumerate(channels)
                if c.point == lim.point and c.quantity == "acceleration"
            ]
            if not cols:
                raise ValueError(f"{where}: no acceleration channel at that point in {names}")
            col = cols[0]
        ch = channels[col]
        accel = (lim.acceleration_alarm_m_s2, lim.acceleration_abort_m_s2)
        disp = (lim.displacement_alarm_m, lim.displacement_abort_m)
        force = (lim.force_alarm_n, lim.force_abort_n)
        if ch.quantity != "acceleration" and any(v is not None for v in accel + disp):
            raise ValueError(f"{where}: acceleration limits on the {ch.quantity} channel {ch.name}")
        if ch.quantity != "force" and any(v is not None for v in force):
            raise ValueError(f"{where}: force limits on the {ch.quantity} channel {ch.name}")
        for pair, quantity, unit in ((accel, "peak", "m/s^2"), (force, "peak", "N")):
            if any(v is not None for v in pair):
                out.append(ResolvedLimit(col, quantity, pair[0], pair[1], unit))
        if any(v is not None for v in disp):
            out.append(ResolvedLimit(col, "displacement", disp[0], disp[1], "m"))
    return out


def displacement_peak(
    acceleration: np.ndarray, sample_rate_hz: float, band_hz, periodic: bool = True
) -> np.ndarray:
    """Peak displacement from acceleration, integrated twice over a band.

    Parameters
    ----------
    acceleration : ndarray, shape (n,) or (n, C), m/s^2
    sample_rate_hz : float
    band_hz : (float, float)
        Frequencies kept [Hz]; outside it (drift, noise) is dropped.
    periodic : bool
        The record holds whole periods of the excitation. If not, it is tapered (Tukey window,
        25 %) so that the jump between its ends does not leak into the band; the peak is then
        an estimate.

    Returns
    -------
    ndarray, shape () or (C,), m
        ``max |d(t)|`` with ``D(f) = -A(f) / (2 pi f)^2`` on the record's DFT grid (exact for a
        record of whole periods of a periodic signal in the band).
    """
    a = np.asarray(acceleration, dtype=float)
    n = a.shape[0]
    if not periodic:
        a = a - a.mean(axis=0)
        taper = _tukey(n, 0.25)
        a = a * (taper[:, None] if a.ndim == 2 else taper)
    spectrum = np.fft.rfft(a, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    keep = (f >= band_hz[0]) & (f <= band_hz[1]) & (f > 0)
    d = np.zeros_like(spectrum)
    w2 = (2.0 * np.pi * f[keep]) ** 2
    d[keep] = -spectrum[keep] / (w2[:, None] if a.ndim == 2 else w2)
    return np.max(np.abs(np.fft.irfft(d, n, axis=0)), axis=0)


def _tukey(n: int, alpha: float) -> np.ndarray:
    w = np.ones(n)
    edge = int(alpha * n / 2)
    if edge > 0:
        ramp = 0.5 * (1 - np.cos(np.pi * np.arange(edge) / edge))
        w[:edge] = ramp
        w[n - edge :] = ramp[::-1]
    return w


def peak_exponent(period_waveform: np.ndarray, noise_rms: float) -> float:
    """How flat a waveform is at both its peaks: the exponent n of ``time ~ depth^(1/n)``.

    The time a waveform spends within a depth ``d`` of its maximum grows like ``d^(1/n)``,
    where ``n`` is the order of the first derivative that does not vanish at the peak: 2 for a
    sine's rounded peak, 4 for the flattest peak orders 1 and 3 can make together (a third
    harmonic of 1/9 in phase), 6 with order 5 as well, and without bound on a plateau (a sine
    clipped at 80 % of its amplitude gives about 6, at 60 % about 10). The exponent is read
    from the times within ``b`` and ``min(10 b, amplitude / 2)`` of each peak, ``b = max(2 %
    of the amplitude, 3 noise_rms)``, scaled so that a sine reads 2 at any depths, and the
    smaller of the two peaks' is returned. Unlike the time at the peak
    alone it does not mistake a smooth flat peak for a plateau.

    Parameters
    ----------
    period_waveform : ndarray, shape (N,)
        One base period, averaged over periods and denoised.
    noise_rms : float
        Noise left in it (channel units).

    Returns
    -------
    float
        The exponent; 0 when the peaks are not symmetric (a saturated sensor clips both ways at
        about the same level; the flat top of a nonlinear response is one-sided); NaN when the
        noise band exceeds 10 % of the amplitude (too noisy to tell).
    """
    w = np.asarray(period_waveform, dtype=float)
    hi, lo = float(np.max(w)), float(np.min(w))
    amp = 0.5 * (hi - lo)
    if amp <= 0:
        return math.nan
    band = max(0.02 * amp, 3.0 * noise_rms)
    if band > 0.1 * amp:
        return math.nan
    if abs(hi + lo) > max(0.05 * amp, band):
        return 0.0
    deep = min(_PEAK_DEPTHS * band, 0.5 * amp)

    def near_peaks(depth: float) -> float:
        return float(min(np.mean(w >= hi - depth), np.mean(w <= lo + depth)))

    inner, outer = near_peaks(band), near_peaks(deep)
    if outer <= inner:
        return math.inf
    # a sine's times at the same depths, so that a sine reads 2 at any depth
    sine = math.acos(1.0 - deep / amp) / math.acos(1.0 - band / amp)
    return 2.0 * math.log(sine) / math.log(outer / inner)


class SignalChecks:
    """Limit, clipping and sensor checks of one run.

    Parameters
    ----------
    channels : sequence of rig.config.setup.ChannelSetup
        Acquired channels in column order.
    limits : Limits
    sample_rate_hz : float
    warn : callable(kind, message, channel)
        Called for alarms (once per channel and limit per step).
    drive : ShakerDrive, optional
        The shaker and amplifier, for the coil current (None: not estimated).
    """

    def __init__(
        self,
        channels: Sequence,
        limits: Limits,
        sample_rate_hz: float,
        warn: Callable[[str, str, str], None],
        drive: ShakerDrive | None = None,
    ) -> None:
        self.channels = tuple(channels)
        self.limits = resolve_limits(limits, self.channels)
        self.sample_rate_hz = float(sample_rate_hz)
        self._range = np.array([c.range_units for c in self.channels]) * (1.0 - 1e-6)
        self._warn = warn
        self._alarmed: set[tuple[int, str]] = set()
        self._silent = np.zeros(len(self.channels), dtype=int)
        self._reference = np.full(len(self.channels), np.nan)  # last |X_1 / F_1| when live
        self.context = ""  # "at 25.3 Hz, 4 N": appended to messages
        roles = [c.role for c in self.channels]
        has_acc = "drive-acceleration" in roles and "drive-force" in roles
        self.drive = drive if has_acc else None
        # the latest measurement with force: its estimated coil current [A] and where it was
        self._last_current: tuple[float, str] | None = None

    def new_step(self, context: str) -> None:
        """Forget the alarms given (they warn again in the new step)."""
        self._alarmed.clear()
        self.context = context

    def _where(self) -> str:
        return f" {self.context}" if self.context else ""

    # -- every block ------------------------------------------------------------------------
    def check_block(
        self, data: np.ndarray, band_hz: tuple[float, float] | None, periodic: bool = True
    ) -> None:
        """Check samples as they are read.

        Parameters
        ----------
        data : ndarray, shape (n, C), channel units
        band_hz : (float, float), optional
            Excited band for the displacement limits (None: skip them, e.g. at 0 V).
        periodic : bool
            ``data`` holds whole periods of the drive (see :func:`displacement_peak`).

        Raises
        ------
        RunFault
            ``clipping`` when a channel reaches its input range; ``response-limit`` when an
            abort limit is exceeded.
        """
        if data.size == 0:
            return
        peaks = np.max(np.abs(data), axis=0)
        over = np.flatnonzero(peaks >= self._range)
        if over.size:
            ch = self.channels[int(over[0])]
            raise RunFault(
                "clipping",
                f"{_describe(ch)} reached its input range (+-{ch.range_v:g} V = "
                f"+-{ch.range_units:.4g} {ch.unit}){self._where()}: the signal is clipped; "
                f"raise the channel's range_v in the setup or lower the level",
                ch.name,
            )
        for lim in self.limits:
            if lim.quantity == "peak":
                value = float(peaks[lim.column])
            elif band_hz is None or data.shape[0] < 8:
                continue
            else:
                acc = data[:, lim.column]
                value = float(displacement_peak(acc, self.sample_rate_hz, band_hz, periodic))
            self._compare(lim, value)

    def _compare(self, lim: ResolvedLimit, value: float) -> None:
        ch = self.channels[lim.column]
        what = "displacement" if lim.quantity == "displacement" else f"peak {ch.quantity}"
        if lim.abort is not None and value > lim.abort:
            raise RunFault(
                "response-limit",
                f"{_describe(ch)}: {what} {value:.4g} {lim.unit} exceeded the abort limit "
                f"{lim.abort:.4g} {lim.unit}{self._where()}",
                ch.name,
            )
        key = (lim.column, lim.quantity)
        if lim.alarm is not None and value > lim.alarm and key not in self._alarmed:
            self._alarmed.add(key)
            self._warn(
                "response-alarm",
                f"{_describe(ch)}: {what} {value:.4g} {lim.unit} above the alarm limit "
                f"{lim.alarm:.4g} {lim.unit}{self._where()}",
                ch.name,
            )

    # -- every averaged measurement ---------------------------------------------------------
    def check_measurement(
        self,
        estimate,
        window: np.ndarray,
        samples_per_period: int,
        fundamental_index: int,
        drive_v: float,
    ) -> None:
        """Check an averaged multi-sine measurement for flat, silent and saturated channels.

        Parameters
        ----------
        estimate : HarmonicEstimate
        window : ndarray, shape (n, C)
            The averaged samples (whole base periods).
        samples_per_period : int
        fundamental_index : int
            Column of order 1.
        drive_v : float
            Fundamental drive amplitude [V] (for the message).

        Raises
        ------
        RunFault
            ``sensor``, ``no-force`` or ``clipping``.
        """
        n_total = window.shape[0]
        spread = np.ptp(window, axis=0)
        forces = [c for c, ch in enumerate(self.channels) if ch.role == "drive-force"]
        force = abs(estimate.phasors[forces[0], fundamental_index]) if forces else math.nan
        freq = estimate.frequencies_hz[fundamental_index]
        for c, ch in enumerate(self.channels):
            if ch.quantity == "voltage":
                continue
            if spread[c] == 0:
                raise RunFault(
                    "sensor",
                    f"{_describe(ch)} is flat (every sample {window[0, c]:.4g} {ch.unit})"
                    f"{self._where()}: the sensor or its input is dead; check the sensor, its "
                    "cable and the IEPE supply",
                    ch.name,
                )
            amp = abs(estimate.phasors[c, fundamental_index])
            noise = 2.0 * estimate.nonperiodic_rms[c] / math.sqrt(n_total)
            silent = bool(np.isfinite(noise) and amp < SILENT_SNR * noise)
            ratio = amp / force if force > 0 else math.nan
            if silent and ch.role != "drive-force" and ratio >= SILENT_DROP * self._reference[c]:
                silent = False  # weak but where it was before: an antiresonance, not a dead sensor
            if not silent and np.isfinite(ratio):
                self._reference[c] = ratio
            self._silent[c] = self._silent[c] + 1 if silent else 0
            # the force gauge has no antiresonance to dip into: one silent measurement is enough
            strikes = 1 if ch.role == "drive-force" else SILENT_STRIKES
            if self._silent[c] >= strikes:
                self._silent[c] = 0
                if ch.role == "drive-force":
                    raise RunFault(
                        "no-force",
                        f"no force at the drive point: {_describe(ch)} reads {amp:.3g} N at "
                        f"{freq:.4g} Hz with {drive_v:.3g} V drive, the level of its noise "
                        f"({noise:.2g} N){self._where()}; {self._no_force_cause()}",
                        ch.name,
                    )
                raise RunFault(
                    "sensor",
                    f"{_describe(ch)} stopped responding: its fundamental is {amp:.3g} {ch.unit} "
                    f"at {freq:.4g} Hz, the level of its noise ({noise:.2g} {ch.unit})"
                    f"{self._where()}; the sensor or its cable is disconnected (IEPE open "
                    "circuit?)",
                    ch.name,
                )
        self._check_current(estimate, force, freq)  # the force is live: the current is real
        self._check_saturation(window, samples_per_period, estimate)

    def _check_current(self, estimate, force: float, freq: float) -> None:
        """Estimate the coil current of a measurement with force; warn near the limit."""
        drive = self.drive
        if drive is None or not force > 0:
            return
        roles = [c.role for c in self.channels]
        f = estimate.phasors[roles.index("drive-force")]
        a = estimate.phasors[roles.index("drive-acceleration")]
        current = float(np.abs(f + drive.armature_mass_kg * a).sum() / drive.force_constant_n_per_a)
        if not np.isfinite(current):
            return
        self._last_current = (
            current,
            (
                f"at the last measurement with force ({freq:.4g} Hz, {force:.3g} N) the shaker "
                f"drew about {current:.2g} A (estimated as (F + m a) / Bl from the drive "
                f"point's force and acceleration) of the amplifier's {drive.current_limit_a:g} A "
                "limit"
            ),
        )
        if current > drive.usable_current_a and (-1, "current") not in self._alarmed:
            self._alarmed.add((-1, "current"))
            self._warn(
                "amplifier-current",
                f"the shaker draws about {current:.2g} A at {freq:.4g} Hz, {force:.3g} N "
                f"(estimated from the drive point's force and acceleration){self._where()}, "
                f"near the amplifier's {drive.current_limit_a:g} A overload limit: the drive "
                "point is near a resonance, where the armature's inertia needs the current; "
                "lower the level in this band if the amplifier trips",
                "",
            )

    def _no_force_cause(self) -> str:
        generic = (
            "the amplifier is off, muted or has tripped (overload), or the shaker is not connected"
        )
        drive, last = self.drive, self._last_current
        # far below the limit an overload is unlikely: then the generic causes stand first
        if drive is None or last is None or last[0] < TRIP_LIKELY * drive.current_limit_a:
            return generic
        return (
            f"{last[1]}: most likely its overload protection tripped at a resonance "
            "of the drive point, where the armature's inertia needs the current; run this band "
            "at a lower level (otherwise: " + generic + ")"
        )

    def _check_saturation(self, window: np.ndarray, n: int, estimate) -> None:
        levels, exponents = flat_tops(window, n, estimate.nonperiodic_rms)
        for c, ch in enumerate(self.channels):
            if ch.quantity == "voltage" or np.isnan(exponents[c]):
                continue
            near = levels[c] >= PLATEAU_NEAR_FULL_SCALE * ch.full_scale_units
            if exponents[c] <= (PLATEAU_EXPONENT if near else PLATEAU_EXPONENT_ANY_LEVEL):
                continue
            what = "force gauge" if ch.quantity == "force" else "sensor"
            if near:
                why = (
                    f"the {what} saturates (its measuring range is exceeded); use a less "
                    "sensitive one or lower the level"
                )
            else:
                why = (
                    f"that is {levels[c] / ch.full_scale_units:.1%} of its full scale "
                    f"(+-{ch.full_scale_units:.4g} {ch.unit}), so the {what} saturates below "
                    "its range: it is faulty (a damaged element, too little IEPE current for "
                    "its cable, a bias drifted toward the rail) or loosely mounted; check or "
                    "replace it"
                )
            raise RunFault(
                "clipping",
                f"{_describe(ch)} is flat-topped at about +-{levels[c]:.3g} {ch.unit} "
                f"(peaks of order {exponents[c]:.3g}; a sine's are of order 2)"
                f"{self._where()}: {why}",
                ch.name,
            )


def flat_tops(
    window: np.ndarray, samples_per_period: int, nonperiodic_rms: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Half the peak-to-peak level and the :func:`peak_exponent` of every channel.

    Parameters
    ----------
    window : ndarray, shape (n, C)
        Samples of whole base periods.
    samples_per_period : int
    nonperiodic_rms : ndarray, shape (C,)
        RMS of what is not periodic in the base period (noise), per channel.

    Returns
    -------
    levels, exponents : ndarray, shape (C,)
        The period average, its harmonics above ``_PLATEAU_HARMONICS`` removed with Lanczos'
        sigma factors: a plain cut rings (Gibbs) on a plateau's corners and hides a sensor
        clipped hard at low noise. NaN where there is not one period.
    """
    n = samples_per_period
    periods = window.shape[0] // n
    n_channels = window.shape[1]
    if periods < 1:
        return np.full(n_channels, np.nan), np.full(n_channels, np.nan)
    mean_period = window[: periods * n].reshape(periods, n, -1).mean(axis=0)
    spectrum = np.fft.rfft(mean_period, axis=0)
    keep = min(_PLATEAU_HARMONICS, spectrum.shape[0] - 1)
    k = np.arange(spectrum.shape[0])
    sigma = np.where(k <= keep, np.sinc(k / (keep + 1)), 0.0)
    spectrum *= sigma[:, None]
    spectrum[0] = 0.0
    smooth = np.fft.irfft(spectrum, n, axis=0)
    residual = np.asarray(nonperiodic_rms) * math.sqrt(2.0 * keep / n) / math.sqrt(periods)
    levels = 0.5 * np.ptp(smooth, axis=0)
    exponents = np.array(
        [peak_exponent(smooth[:, c], float(np.nan_to_num(residual[c]))) for c in range(n_channels)]
    )
    return levels, exponents


# ------------------------------------------------------------------------ signals


@contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) while the body runs; deliver it afterwards.

    Used around the ramp-down and file writes so that an impatient second Ctrl-C cannot cut
    them short. Outside the main thread (where Python delivers signals) it does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def hold(signum, frame) -> None:
        received.append(signum)
        logger.warning("Ctrl-C held until the output is safe")

    try:
        previous = signal.signal(signal.SIGINT, hold)
    except ValueError:  # not the main interpreter
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received and callable(previous):
            previous(signal.SIGINT, None)


@contextmanager
def interrupt_handlers(abort: Callable[[str], None]) -> Iterator[None]:
    """Turn Ctrl-C and SIGTERM into ``abort(reason)`` for the duration of a run.

    The first Ctrl-C asks for a clean abort (the engine ramps the output down and records the
    run as aborted); a second one raises ``KeyboardInterrupt`` at once (the engine's cleanup
    still ramps down). SIGTERM asks for a clean abort. Only in the main thread.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    count = [0]

    def on_int(signum, frame) -> None:
        count[0] += 1
        if count[0] > 1:
            raise KeyboardInterrupt
        abort("interrupted by the user (Ctrl-C)")

    def on_term(signum, frame) -> None:
        abort("terminated by a signal (SIGTERM)")

    old_int = signal.signal(signal.SIGINT, on_int)
    old_term = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_int)
        signal.signal(signal.SIGTERM, old_term)
