"""What a pretest plan chooses from, and the noise it assumes: validated, frozen settings.

A *configuration* is one actuator, ``n_sensors`` sensors, ``n_levels`` force levels and one
frequency range (with its step plan). :func:`paper_candidates` gives the candidate sets of the
reference paper (Table 3): 35 sensor triples x 3 actuators x 20 level triples x 7 ranges =
14 700 configurations, excitation orders 1-3 with the 2nd and 3rd harmonics at 2 % of the
fundamental.

References
----------
Y. Chen, A. Linderholt, T. Abrahamsson, Y. Xia, M. I. Friswell, "Validation of a model
calibration method through vibrational testing of a mechanical system with local clearance",
ISMA 2016, sec. 2.1 and Tables 3-4.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Literal

import numpy as np

__all__ = [
    "Candidates",
    "Configuration",
    "FrequencyRange",
    "NoiseModel",
    "paper_candidates",
    "quick_candidates",
]


def _positive(owner: str, name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}.{name}: must be a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{owner}.{name}: must be > 0, got {value!r}")
    return float(value)


def _points(owner: str, name: str, values) -> tuple[int, ...]:
    pts = tuple(values)
    if not pts:
        raise ValueError(f"{owner}.{name}: give at least one measurement point")
    for p in pts:
        if isinstance(p, bool) or not isinstance(p, int | np.integer):
            raise ValueError(f"{owner}.{name}: measurement points are integers, got {p!r}")
    if len(set(pts)) != len(pts):
        raise ValueError(f"{owner}.{name}: duplicate points in {list(pts)}")
    return tuple(int(p) for p in pts)


@dataclass(frozen=True)
class FrequencyRange:
    """A range of fundamental frequencies stepped upwards, optionally refined in a band.

    Parameters
    ----------
    start_hz, stop_hz : float
        First and last step [Hz] (both included when ``stop - start`` is a whole number of
        steps).
    step_hz : float
        Step [Hz].
    fine_band_hz : (float, float), optional
        A band [Hz] stepped with ``fine_step_hz`` in addition to the coarse steps (the paper's
        0.1 Hz in 24-28 Hz around the first resonance).
    fine_step_hz : float
        Step inside ``fine_band_hz`` [Hz].
    """

    start_hz: float
    stop_hz: float
    step_hz: float = 1.0
    fine_band_hz: tuple[float, float] | None = None
    fine_step_hz: float = 0.1

    def __post_init__(self) -> None:
        for name in ("start_hz", "stop_hz", "step_hz", "fine_step_hz"):
            object.__setattr__(self, name, _positive("FrequencyRange", name, getattr(self, name)))
        if self.stop_hz < self.start_hz:
            raise ValueError(
                f"FrequencyRange.stop_hz: {self.stop_hz} is below start_hz {self.start_hz}"
            )
        if self.fine_band_hz is not None:
            lo, hi = (_positive("FrequencyRange", "fine_band_hz", v) for v in self.fine_band_hz)
            if hi < lo:
                raise ValueError(f"FrequencyRange.fine_band_hz: ({lo}, {hi}) is reversed")
            object.__setattr__(self, "fine_band_hz", (lo, hi))

    @staticmethod
    def _grid(start: float, stop: float, step: float) -> np.ndarray:
        n = math.floor((stop - start) / step + 1e-9)
        return start + step * np.arange(n + 1)

    def frequencies_hz(self) -> np.ndarray:
        """Fundamental frequencies in stepping order (ascending), shape (n_steps,), Hz.

        Coarse and fine steps are merged; steps closer than 1e-6 Hz count as one.
        """
        f = self._grid(self.start_hz, self.stop_hz, self.step_hz)
        if self.fine_band_hz is not None:
            lo = max(self.fine_band_hz[0], self.start_hz)
            hi = min(self.fine_band_hz[1], self.stop_hz)
            if hi >= lo:
                f = np.concatenate([f, self._grid(lo, hi, self.fine_step_hz)])
        return np.unique(np.round(f, 6))

    def overlaps(self, band_hz: tuple[float, float]) -> bool:
        """Whether the band [Hz] intersects the range."""
        return band_hz[0] <= self.stop_hz and band_hz[1] >= self.start_hz

    def refined(self, band_hz: tuple[float, float], step_hz: float) -> FrequencyRange:
        """The same range with ``step_hz`` steps added inside ``band_hz``."""
        return FrequencyRange(
            self.start_hz, self.stop_hz, self.step_hz, (band_hz[0], band_hz[1]), step_hz
        )

    @property
    def label(self) -> str:
        """``"[21-40]"``, with the refinement appended (``"[21-40] + 0.1 Hz in 24-28"``)."""
        text = f"[{self.start_hz:g}-{self.stop_hz:g}]"
        if self.fine_band_hz is not None:
            lo, hi = self.fine_band_hz
            text += f" + {self.fine_step_hz:g} Hz in {lo:g}-{hi:g}"
        return text


#: The paper's seven 20 Hz ranges in 1 Hz steps: [21-40], [41-60], ..., [141-160] Hz.
PAPER_RANGES = tuple(FrequencyRange(21.0 + 20 * i, 40.0 + 20 * i, 1.0) for i in range(7))


@dataclass(frozen=True)
class Candidates:
    """Candidate sets of a pretest plan and the excitation and parameters it plans for.

    Parameters
    ----------
    sensors : tuple of int
        Candidate sensor points (measurement points of the model, each in its direction).
    n_sensors : int
        Sensors in a configuration (chosen from ``sensors``).
    actuators : tuple of int
        Candidate actuator points (one per configuration).
    levels_n : tuple of float
        Candidate fundamental force amplitudes [N].
    n_levels : int
        Levels in a configuration (chosen from ``levels_n``).
    ranges : tuple of FrequencyRange
        Candidate frequency ranges with their step plans (one per configuration).
    orders : tuple of int or Fraction
        Excitation orders; the first is the fundamental.
    side_harmonic_ratio : float
        Amplitude of every other order relative to the fundamental (0.02: the paper's 2 %).
    parameters : tuple of str
        Model parameters the plan is for (element parameters such as ``k_c``, ``gap``,
        ``v_c`` or structural ones).
    """

    sensors: tuple[int, ...] = (1, 2, 3, 4, 5, 6, 7)
    n_sensors: int = 3
    actuators: tuple[int, ...] = (1, 2, 3)
    levels_n: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    n_levels: int = 3
    ranges: tuple[FrequencyRange, ...] = PAPER_RANGES
    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    side_harmonic_ratio: float = 0.02
    parameters: tuple[str, ...] = ("k_c", "gap", "v_c")

    def __post_init__(self) -> None:
        own = "Candidates"
        object.__setattr__(self, "sensors", _points(own, "sensors", self.sensors))
        object.__setattr__(self, "actuators", _points(own, "actuators", self.actuators))
        levels = tuple(_positive(own, "levels_n", v) for v in self.levels_n)
        if not levels or len(set(levels)) != len(levels):
            raise ValueError(f"{own}.levels_n: give distinct levels, got {list(levels)}")
        object.__setattr__(self, "levels_n", levels)
        for name, pool in (("n_sensors", self.sensors), ("n_levels", levels)):
            k = getattr(self, name)
            if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= len(pool):
                raise ValueError(f"{own}.{name}: must be an integer in 1..{len(pool)}, got {k!r}")
        ranges = tuple(self.ranges)
        if not ranges or not all(isinstance(r, FrequencyRange) for r in ranges):
            raise ValueError(f"{own}.ranges: give one or more FrequencyRange")
        object.__setattr__(self, "ranges", ranges)
        try:
            orders = tuple(Fraction(o) for o in self.orders)
        except (TypeError, ValueError):
            raise ValueError(f"{own}.orders: expected numbers, got {self.orders!r}") from None
        if not orders or min(orders) <= 0 or len(set(orders)) != len(orders):
            raise ValueError(f"{own}.orders: give distinct positive orders, got {self.orders!r}")
        object.__setattr__(self, "orders", orders)
        r = self.side_harmonic_ratio
        if isinstance(r, bool) or not isinstance(r, int | float) or not 0 <= r < math.inf:
            raise ValueError(f"{own}.side_harmonic_ratio: must be >= 0, got {r!r}")
        params = tuple(self.parameters)
        if not params or len(set(params)) != len(params):
            raise ValueError(f"{own}.parameters: give distinct parameter names, got {params!r}")
        object.__setattr__(self, "parameters", params)

    def force(self, level_n: float) -> np.ndarray:
        """Force phasors per order for a fundamental of ``level_n``, shape (n_orders,), N."""
        f = np.full(len(self.orders), self.side_harmonic_ratio * level_n, dtype=complex)
        f[0] = level_n
        return f

    @property
    def n_configurations(self) -> int:
        """Number of configurations: C(sensors, n) x actuators x C(levels, m) x ranges."""
        return (
            math.comb(len(self.sensors), self.n_sensors)
            * len(self.actuators)
            * math.comb(len(self.levels_n), self.n_levels)
            * len(self.ranges)
        )


@dataclass(frozen=True)
class Configuration:
    """One test design: actuator point, sensor points, force levels [N], frequency range."""

    actuator: int
    sensors: tuple[int, ...]
    levels_n: tuple[float, ...]
    frequency_range: FrequencyRange

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensors", _points("Configuration", "sensors", self.sensors))
        levels = tuple(_positive("Configuration", "levels_n", v) for v in self.levels_n)
        if not levels or len(set(levels)) != len(levels):
            raise ValueError(f"Configuration.levels_n: give distinct levels, got {list(levels)}")
        object.__setattr__(self, "levels_n", levels)

    def describe(self) -> str:
        """One line: actuator, levels, range and sensors (the columns of the paper's Table 4)."""
        levels = ", ".join(f"{v:g}" for v in self.levels_n)
        return (
            f"actuator {self.actuator}, levels [{levels}] N, range {self.frequency_range.label} "
            f"Hz, sensors {list(self.sensors)}"
        )


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise of the response phasors, in the measured quantity.

    Each of the real and imaginary parts of a response phasor at order ``nu`` (one sensor,
    one step) has standard deviation::

        sigma = sqrt((relative * |Y|)**2 + floor_s**2)

    with ``Y`` the phasor of the measured quantity (acceleration ``-(nu Omega)^2 Q`` in m/s^2
    by default, or the receptance FRF ``Q / F`` in m/N) and ``floor_s`` the sensor's absolute
    floor. The noise is evaluated at the planning point (the FIM ignores its dependence on the
    parameters); force phasors are taken as known. Because ``sigma`` scales with the data,
    the Fisher information of an FRF, of a response phasor and of an acceleration phasor is the
    same: the choice of quantity only says in which units ``floor`` is given.

    The default is the rig's: accelerometers, so the floor is in m/s^2. ``relative = 0.02``
    is the paper's bound on the measured noise (below 2 %). ``floor = 0.01`` m/s^2 stands for
    everything not synchronous with the excitation after harmonic estimation (ambient
    vibration, shaker and amplifier noise, sensor and ADC noise), a white floor of about
    0.007 m/s^2/sqrt(Hz) averaged over a 1 s record. It keeps small super-harmonic and
    off-resonance responses from counting as exact data; set it from the phasor scatter the
    harmonic estimation reports on the actual rig. ``NoiseModel.uniform_frf()`` is the paper's
    assumption (identical sigma for every FRF entry): the FIM is then in units of sigma^-2.

    Parameters
    ----------
    relative : float
        Noise relative to the phasor's magnitude (>= 0).
    floor : float
        Absolute floor per real component, in the quantity's unit (m/s^2 or m/N); > 0.
    sensor_floors : mapping of int to float
        Floors of particular sensors (points), overriding ``floor``.
    quantity : {"acceleration", "receptance"}
    """

    relative: float = 0.02
    floor: float = 0.01
    sensor_floors: Mapping[int, float] = field(default_factory=dict)
    quantity: Literal["acceleration", "receptance"] = "acceleration"

    def __post_init__(self) -> None:
        r = self.relative
        if isinstance(r, bool) or not isinstance(r, int | float) or not 0 <= r < math.inf:
            raise ValueError(f"NoiseModel.relative: must be a finite number >= 0, got {r!r}")
        object.__setattr__(self, "relative", float(r))
        # a floor of 0 would count vanishing responses (nodes, unforced orders) as exact data
        object.__setattr__(self, "floor", _positive("NoiseModel", "floor", self.floor))
        floors = {}
        for p, v in dict(self.sensor_floors).items():
            floors[int(p)] = _positive("NoiseModel", f"sensor_floors[{p}]", v)
        object.__setattr__(self, "sensor_floors", floors)
        if self.quantity not in ("acceleration", "receptance"):
            raise ValueError(
                f"NoiseModel.quantity: 'acceleration' or 'receptance', got {self.quantity!r}"
            )

    @classmethod
    def uniform_frf(cls, sigma: float = 1.0) -> NoiseModel:
        """The paper's assumption: every FRF entry has the same ``sigma`` [m/N]."""
        return cls(relative=0.0, floor=sigma, quantity="receptance")

    def floor_at(self, sensor: int) -> float:
        """Absolute floor of a sensor point, in the quantity's unit."""
        return self.sensor_floors.get(sensor, self.floor)

    @property
    def unit(self) -> str:
        """Unit of the floor: ``"m/s^2"`` or ``"m/N"``."""
        return "m/s^2" if self.quantity == "acceleration" else "m/N"


def paper_candidates(parameters: tuple[str, ...] = ("k_c", "gap", "v_c")) -> Candidates:
    """The paper's Table 3: sensors 1-7 choose 3, actuators 1-3, levels 1-6 N choose 3, the
    seven 20 Hz ranges from 21 to 160 Hz in 1 Hz steps; orders 1-3 with 2 % side harmonics."""
    return Candidates(parameters=tuple(parameters))


def quick_candidates(parameters: tuple[str, ...] = ("k_c", "gap", "v_c")) -> Candidates:
    """A reduced set for smoke runs: all sensors and actuators, levels 2/4/6 N choose 2,
    the first and last range (630 configurations, 18 sweeps)."""
    return Candidates(
        levels_n=(2.0, 4.0, 6.0),
        n_levels=2,
        ranges=(PAPER_RANGES[0], PAPER_RANGES[-1]),
        parameters=tuple(parameters),
    )
