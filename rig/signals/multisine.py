"""Multi-sine drive synthesis on the DAQ sample clock.

A stepped multi-sine step drives the shaker with

    v(t) = Re{ sum_k V_k exp(i 2 pi k f t) },

where the orders ``k`` are positive rationals (1, 2, 3 for the reference test; sub-harmonics
such as 1/2 are allowed) and ``|V_k|`` is the amplitude of order ``k`` in volts. The *base
period* is the period of the lowest common frequency ``f / m``, with ``m`` the least common
multiple of the orders' denominators; one base period holds a whole number of cycles of every
order.

:func:`plan_period` picks an integer number of samples per base period, so every order has a
whole number of cycles per period *on the DAQ clock* and harmonic estimation over whole periods
has no leakage. The realised fundamental frequency differs slightly from the requested one and
is what the measurement file records. :func:`synthesize` returns one base period of samples
and refuses (rather than clips) a waveform whose peak exceeds the output limit.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

__all__ = [
    "MultisineSpec",
    "PeriodPlan",
    "as_orders",
    "base_denominator",
    "cosine_ramp",
    "crossfade",
    "plan_period",
    "synthesize",
    "waveform_peak_v",
]

logger = logging.getLogger(__name__)

DEFAULT_SIDE_AMPLITUDE = 0.02
_MAX_ORDER_DENOMINATOR = 64


def _as_order(value: object, where: str) -> Fraction:
    if isinstance(value, bool):
        raise ValueError(f"{where}: an order must be a positive rational, got {value!r}")
    if isinstance(value, float):
        order = Fraction(value).limit_denominator(_MAX_ORDER_DENOMINATOR)
        if abs(float(order) - value) > 1e-9:
            raise ValueError(
                f"{where}: order {value!r} is not a simple rational; give it as a Fraction "
                f"or a string like '1/3'"
            )
    else:
        try:
            order = Fraction(value)  # int, Fraction, numpy integer, or "p/q"
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: cannot read {value!r} as a rational order") from exc
    if order <= 0:
        raise ValueError(f"{where}: orders must be > 0 (order 0 is not measured), got {order}")
    return order


def as_orders(orders: Iterable[object], where: str = "orders") -> tuple[Fraction, ...]:
    """Validate harmonic orders and return them as fractions.

    Parameters
    ----------
    orders : iterable of int, Fraction, str or float
        Positive rational orders, e.g. ``(1, 2, 3)`` or ``("1/2", 1, 2)``. Floats are accepted
        when they are a simple rational (``0.5``).
    where : str
        Name used in error messages.

    Returns
    -------
    tuple of Fraction
        The orders in the given sequence (their order is the column order of every phasor
        array).

    Raises
    ------
    ValueError
        If the sequence is empty, an order is not a positive rational, or orders repeat.
    """
    result = tuple(_as_order(o, where) for o in orders)
    if not result:
        raise ValueError(f"{where}: at least one order is needed")
    if len(set(result)) != len(result):
        raise ValueError(f"{where}: orders repeat: {[str(o) for o in result]}")
    return result


def base_denominator(orders: Iterable[Fraction]) -> int:
    """Least common multiple ``m`` of the orders' denominators (base frequency = f / m)."""
    return math.lcm(*(Fraction(o).denominator for o in orders))


@dataclass(frozen=True)
class MultisineSpec:
    """Shape of the multi-sine force: orders, relative amplitudes and phases.

    Parameters
    ----------
    orders : tuple of Fraction
        Harmonic orders of the fundamental; order 1 must be present.
    relative_amplitudes : tuple of float, optional
        Amplitude of each order relative to the fundamental (the fundamental's must be 1: a test
        level is the fundamental force amplitude). Default: 1 for order 1, 0.02 for the others.
    phases_rad : tuple of float, optional
        Phase of each order [rad] relative to ``k`` times the fundamental's phase (the
        measurement-file convention). Default: all 0.
    """

    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    relative_amplitudes: tuple[float, ...] | None = None
    phases_rad: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        orders = as_orders(self.orders, "MultisineSpec.orders")
        if Fraction(1) not in orders:
            raise ValueError("MultisineSpec.orders: order 1 (the fundamental) must be present")
        n = len(orders)
        amps = self.relative_amplitudes
        if amps is None:
            amps = tuple(1.0 if o == 1 else DEFAULT_SIDE_AMPLITUDE for o in orders)
        amps = tuple(float(a) for a in amps)
        phases = tuple(float(p) for p in (self.phases_rad or (0.0,) * n))
        for name, values in (("relative_amplitudes", amps), ("phases_rad", phases)):
            if len(values) != n:
                raise ValueError(
                    f"MultisineSpec.{name}: expected {n} values (one per order), got {len(values)}"
                )
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"MultisineSpec.{name}: values must be finite, got {values}")
        if any(a < 0 for a in amps):
            raise ValueError(f"MultisineSpec.relative_amplitudes: must be >= 0, got {amps}")
        if amps[orders.index(Fraction(1))] != 1.0:
            raise ValueError(
                "MultisineSpec.relative_amplitudes: the fundamental's must be 1, got "
                f"{amps[orders.index(Fraction(1))]}"
            )
        object.__setattr__(self, "orders", orders)
        object.__setattr__(self, "relative_amplitudes", amps)
        object.__setattr__(self, "phases_rad", phases)

    @property
    def fundamental_index(self) -> int:
        """Column of order 1 in every phasor array."""
        return self.orders.index(Fraction(1))

    def force_targets(self, level_n: float, fundamental_phase_rad: float = 0.0) -> np.ndarray:
        """Target force phasors for one test level.

        Parameters
        ----------
        level_n : float
            Fundamental force amplitude [N].
        fundamental_phase_rad : float
            Phase of the fundamental [rad] at the step's time origin.

        Returns
        -------
        ndarray, shape (H,), complex, N
            ``level * a_k * exp(i (phi_k + k * phi_1))``, phases referenced to the time origin.
            With ``fundamental_phase_rad = 0`` this is also the measurement file's
            ``/force_targets`` row (phases relative to ``k`` times the fundamental's).
        """
        if not (math.isfinite(level_n) and level_n > 0):
            raise ValueError(f"force_targets: level_n must be finite and > 0, got {level_n}")
        k = np.array([float(o) for o in self.orders])
        amps = np.asarray(self.relative_amplitudes)
        phases = np.asarray(self.phases_rad) + k * fundamental_phase_rad
        return level_n * amps * np.exp(1j * phases)


@dataclass(frozen=True)
class PeriodPlan:
    """Timing of one step's periodic drive on the DAQ clock.

    Attributes
    ----------
    orders : tuple of Fraction
        Harmonic orders (column order of the phasor arrays).
    sample_rate_hz : float
        Sample rate of the DAQ clock [Hz].
    fundamental_target_hz : float
        Requested fundamental frequency [Hz].
    samples_per_period : int
        Samples per base period ``N``.
    base_denominator : int
        ``m``: the base frequency is ``fundamental_hz / m``.
    """

    orders: tuple[Fraction, ...]
    sample_rate_hz: float
    fundamental_target_hz: float
    samples_per_period: int
    base_denominator: int

    @property
    def base_frequency_hz(self) -> float:
        """Realised base frequency ``fs / N`` [Hz]."""
        return self.sample_rate_hz / self.samples_per_period

    @property
    def fundamental_hz(self) -> float:
        """Realised fundamental frequency ``m fs / N`` [Hz] (record this one)."""
        return self.base_denominator * self.base_frequency_hz

    @property
    def frequency_error_hz(self) -> float:
        """Realised minus requested fundamental frequency [Hz]."""
        return self.fundamental_hz - self.fundamental_target_hz

    @property
    def cycles_per_period(self) -> tuple[int, ...]:
        """Whole cycles of each order in one base period (``k m``)."""
        return tuple(int(o * self.base_denominator) for o in self.orders)

    @property
    def frequencies_hz(self) -> np.ndarray:
        """Realised frequency of each order, shape (H,) [Hz]."""
        return np.array(self.cycles_per_period, dtype=float) * self.base_frequency_hz

    @property
    def period_s(self) -> float:
        """Duration of one base period [s]."""
        return self.samples_per_period / self.sample_rate_hz


def plan_period(
    fundamental_hz: float,
    sample_rate_hz: float,
    orders: Iterable[object],
    min_samples_per_cycle: float = 8.0,
    max_relative_frequency_error: float | None = None,
) -> PeriodPlan:
    """Choose a whole number of samples per base period for a fundamental frequency.

    Parameters
    ----------
    fundamental_hz : float
        Requested fundamental frequency [Hz].
    sample_rate_hz : float
        Realised DAQ sample rate [Hz] (as reported by the backend).
    orders : iterable of rationals
        Harmonic orders; see :func:`as_orders`.
    min_samples_per_cycle : float
        Fewest samples per cycle of the highest order (waveform fidelity); must be > 2.
    max_relative_frequency_error : float, optional
        If given, raise when ``|f_realised - f| / f`` exceeds it (raise the sample rate).

    Returns
    -------
    PeriodPlan
        ``samples_per_period = round(m fs / f)``; the realised fundamental is ``m fs / N``.

    Raises
    ------
    ValueError
        On non-positive inputs, too few samples per cycle, or a frequency error beyond the limit.
    """
    orders_f = as_orders(orders)
    if not (math.isfinite(fundamental_hz) and fundamental_hz > 0):
        raise ValueError(f"plan_period: fundamental_hz must be > 0, got {fundamental_hz}")
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise ValueError(f"plan_period: sample_rate_hz must be > 0, got {sample_rate_hz}")
    if not min_samples_per_cycle > 2:
        raise ValueError(
            f"plan_period: min_samples_per_cycle must be > 2 (Nyquist), got {min_samples_per_cycle}"
        )
    m = base_denominator(orders_f)
    n = max(1, round(m * sample_rate_hz / fundamental_hz))
    plan = PeriodPlan(orders_f, float(sample_rate_hz), float(fundamental_hz), n, m)
    top = max(plan.cycles_per_period)
    if n < min_samples_per_cycle * top:
        raise ValueError(
            f"plan_period: order {max(orders_f)} at {fundamental_hz:g} Hz gets "
            f"{n / top:.2f} samples per cycle at {sample_rate_hz:g} Hz, fewer than "
            f"min_samples_per_cycle = {min_samples_per_cycle:g}; raise the sample rate"
        )
    rel = abs(plan.frequency_error_hz) / fundamental_hz
    if max_relative_frequency_error is not None and rel > max_relative_frequency_error:
        raise ValueError(
            f"plan_period: realised fundamental {plan.fundamental_hz:.6g} Hz is {rel:.2e} "
            f"from {fundamental_hz:g} Hz, more than max_relative_frequency_error = "
            f"{max_relative_frequency_error:g}; raise the sample rate"
        )
    if rel > 1e-3:
        logger.warning(
            "fundamental %.6g Hz realised as %.6g Hz (%.2e relative) at %g Hz sampling",
            fundamental_hz,
            plan.fundamental_hz,
            rel,
            sample_rate_hz,
        )
    return plan


def _check_phasors(drive_phasors_v: np.ndarray, n_orders: int, where: str) -> np.ndarray:
    phasors = np.asarray(drive_phasors_v, dtype=complex)
    if phasors.shape != (n_orders,):
        raise ValueError(
            f"{where}: expected {n_orders} phasors (one per order), got shape {phasors.shape}"
        )
    if not np.all(np.isfinite(phasors)):
        raise ValueError(f"{where}: phasors must be finite, got {phasors}")
    return phasors


def _waveform(phasors: np.ndarray, cycles: np.ndarray, n_samples: int) -> np.ndarray:
    phase = 2.0 * np.pi * np.outer(np.arange(n_samples) / n_samples, cycles)
    return np.real(np.exp(1j * phase) @ phasors)


def synthesize(
    drive_phasors_v: np.ndarray, plan: PeriodPlan, *, limit_v: float, n_periods: int = 1
) -> np.ndarray:
    """One (or more) base periods of the drive waveform.

    Parameters
    ----------
    drive_phasors_v : ndarray, shape (H,), complex, V
        Output-voltage phasor of each order of ``plan.orders``.
    plan : PeriodPlan
        Timing from :func:`plan_period`.
    limit_v : float
        Hard output-voltage limit [V]: a waveform whose peak exceeds it is refused.
    n_periods : int
        Number of base periods returned.

    Returns
    -------
    ndarray, shape (n_periods * N,), float, V
        Samples ``v[n] = Re{sum_k V_k exp(i 2 pi c_k n / N)}``; sample 0 is the phase origin.

    Raises
    ------
    ValueError
        If the peak exceeds ``limit_v`` (the message names both), or on malformed input.
    """
    if not limit_v > 0:
        raise ValueError(f"synthesize: limit_v must be > 0, got {limit_v}")
    if n_periods < 1:
        raise ValueError(f"synthesize: n_periods must be >= 1, got {n_periods}")
    phasors = _check_phasors(drive_phasors_v, len(plan.orders), "synthesize: drive_phasors_v")
    cycles = np.array(plan.cycles_per_period, dtype=float)
    period = _waveform(phasors, cycles, plan.samples_per_period)
    peak = float(np.max(np.abs(period), initial=0.0))
    if peak > limit_v:
        raise ValueError(
            f"synthesize: waveform peak {peak:.4g} V exceeds the output limit "
            f"limit_v = {limit_v:.4g} V; lower the drive phasors"
        )
    return np.tile(period, n_periods)


def waveform_peak_v(
    drive_phasors_v: np.ndarray, orders: Iterable[object], samples_per_cycle: int = 64
) -> float:
    """Upper bound of the peak of the continuous multi-sine, independent of the sample rate.

    Parameters
    ----------
    drive_phasors_v : ndarray, shape (H,), complex, V
        Phasor of each order.
    orders : iterable of rationals
        Harmonic orders.
    samples_per_cycle : int
        Grid density for the highest order.

    Returns
    -------
    float
        Maximum of ``|v(t)|`` over one base period on the grid plus the largest amount a peak
        between grid points can exceed it, ``sum_k |V_k| (pi c_k / (c_max n_c))^2 / 2``
        (second-order bound, ``n_c = samples_per_cycle``) [V]. No sampled version of the
        waveform exceeds it; it overestimates by at most about ``1.2e-3 sum_k |V_k|``.
    """
    orders_f = as_orders(orders)
    phasors = _check_phasors(drive_phasors_v, len(orders_f), "waveform_peak_v: drive_phasors_v")
    if samples_per_cycle < 4:
        raise ValueError(
            f"waveform_peak_v: samples_per_cycle must be >= 4, got {samples_per_cycle}"
        )
    m = base_denominator(orders_f)
    cycles = np.array([int(o * m) for o in orders_f], dtype=float)
    n = int(samples_per_cycle * cycles.max())
    grid_peak = float(np.max(np.abs(_waveform(phasors, cycles, n))))
    between = 0.5 * np.sum(
        np.abs(phasors) * (np.pi * cycles / (cycles.max() * samples_per_cycle)) ** 2
    )
    return grid_peak + float(between)


def cosine_ramp(n_samples: int) -> np.ndarray:
    """Rising raised-cosine window from 0 to 1.

    Parameters
    ----------
    n_samples : int
        Ramp length (>= 0).

    Returns
    -------
    ndarray, shape (n_samples,), float
        ``w[i] = (1 - cos(pi (i + 1/2) / n)) / 2``; ``w + w[::-1] == 1``, so a cross-fade
        ``(1 - w) old + w new`` keeps a constant sum. Reverse it for a ramp-down.
    """
    if n_samples < 0:
        raise ValueError(f"cosine_ramp: n_samples must be >= 0, got {n_samples}")
    i = np.arange(n_samples, dtype=float)
    return 0.5 * (1.0 - np.cos(np.pi * (i + 0.5) / max(n_samples, 1)))


def crossfade(old_period_v: np.ndarray, new_period_v: np.ndarray, n_samples: int) -> np.ndarray:
    """Raised-cosine cross-fade between two periodic waveforms.

    Parameters
    ----------
    old_period_v : ndarray, shape (n_old,), V
        One period of the outgoing waveform, continued periodically from its sample 0.
    new_period_v : ndarray, shape (n_new,), V
        One period of the incoming waveform, continued periodically from its sample 0.
    n_samples : int
        Cross-fade length.

    Returns
    -------
    ndarray, shape (n_samples,), V
        ``(1 - w) old + w new`` with ``w = cosine_ramp(n_samples)``. After it, ``new`` continues
        at its sample ``n_samples mod n_new``. Use a zero waveform for a start or a stop ramp.
    """
    old = np.asarray(old_period_v, dtype=float)
    new = np.asarray(new_period_v, dtype=float)
    if old.ndim != 1 or new.ndim != 1 or old.size == 0 or new.size == 0:
        raise ValueError("crossfade: waveforms must be non-empty 1-D arrays")
    w = cosine_ramp(n_samples)
    idx = np.arange(n_samples)
    return (1.0 - w) * old[idx % old.size] + w * new[idx % new.size]
