"""Sensors and input converters of the simulated DAQ, and the faults tests can switch on.

Each input channel turns the physical signal (N, m/s^2, V) into what a DAQ card returns:
white sensor noise of the truth's amplitude spectral density, the sensor's output voltage
(``sensitivity``), clipping at the channel's input range (``range_v``), quantisation of the
ADC (``adc_bits`` over the range), and back to physical units. Noise is drawn per block of
samples from a generator seeded by ``(seed, channel, block)``, so it depends on the sample
index only, not on how the samples were read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["STANDARD_GRAVITY", "ChannelChain", "FaultSwitches", "volts_per_unit"]

STANDARD_GRAVITY = 9.80665  # m/s^2 per g
_NOISE_BLOCK = 8192


@dataclass(frozen=True)
class FaultSwitches:
    """Faults of the simulated chain, switched on by tests.

    Parameters
    ----------
    disconnected : tuple of str
        Channels whose sensor is unplugged: they read the noise floor only.
    clip_levels : dict of str to float
        Channels whose sensor saturates, with the level [channel units] beyond which its
        output is flat (a sensor range exceeded).
    read_timeout : bool
        Input samples stop arriving: ``read`` raises ``ReadTimeoutError``.
    amplifier_overload : bool
        Trip the amplifier's overload protection (latched in the amplifier model).
    """

    disconnected: tuple[str, ...] = ()
    clip_levels: Mapping[str, float] = field(default_factory=dict)
    read_timeout: bool = False
    amplifier_overload: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.disconnected, str):
            raise TypeError("FaultSwitches.disconnected: expected a tuple of channel names")
        object.__setattr__(self, "disconnected", tuple(self.disconnected))
        levels = dict(self.clip_levels)
        for name, level in levels.items():
            if not (isinstance(level, int | float) and math.isfinite(level) and level > 0):
                raise ValueError(
                    f"FaultSwitches.clip_levels[{name!r}]: must be a level > 0, got {level!r}"
                )
        object.__setattr__(self, "clip_levels", levels)
        for name in ("read_timeout", "amplifier_overload"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"FaultSwitches.{name}: expected a bool")

    def channels(self) -> set[str]:
        """Every channel named by a fault."""
        return set(self.disconnected) | set(self.clip_levels)


def volts_per_unit(quantity: str, sensitivity: float) -> float:
    """Sensor output per physical unit [V per N, V per m/s^2, V per V]."""
    if quantity == "force":
        return sensitivity / 1000.0
    if quantity == "acceleration":
        return sensitivity / 1000.0 / STANDARD_GRAVITY
    return sensitivity


class ChannelChain:
    """Noise, clipping and quantisation of every input channel.

    Parameters
    ----------
    quantities : sequence of str
        Quantity of each channel.
    sensitivities, ranges_v : sequence of float
        Sensor sensitivity (mV/N, mV/g, V/V) and ADC input range [V] of each channel.
    noise_asd : sequence of float
        Noise amplitude spectral density of each channel [unit/sqrt(Hz)].
    sample_rate_hz : float
    adc_bits : int
    seed : int
    noise, quantisation : bool
        Switch noise and ADC quantisation (clipping at the range always applies).
    """

    def __init__(
        self,
        quantities: Sequence[str],
        sensitivities: Sequence[float],
        ranges_v: Sequence[float],
        noise_asd: Sequence[float],
        sample_rate_hz: float,
        adc_bits: int,
        seed: int,
        *,
        noise: bool = True,
        quantisation: bool = True,
    ) -> None:
        self.scale = np.array(
            [volts_per_unit(q, s) for q, s in zip(quantities, sensitivities, strict=True)]
        )
        self.range_v = np.asarray(ranges_v, dtype=float)
        self.sigma = np.asarray(noise_asd, dtype=float) * math.sqrt(sample_rate_hz / 2.0)
        if not noise:
            self.sigma = np.zeros_like(self.sigma)
        self.lsb_v = 2.0 * self.range_v / 2.0**adc_bits if quantisation else None
        self.seed = int(seed)
        self._cache: dict[tuple[int, int], np.ndarray] = {}

    def noise_std(self) -> np.ndarray:
        """Per-sample noise standard deviation of each channel, shape (C,), channel units."""
        return self.sigma.copy()

    def _noise(self, channel: int, a: int, b: int) -> np.ndarray:
        out = np.empty(b - a)
        pos = a
        while pos < b:
            block = pos // _NOISE_BLOCK
            key = (channel, block)
            if key not in self._cache:
                if len(self._cache) > 4 * max(len(self.sigma), 1):
                    self._cache.clear()
                rng = np.random.default_rng([self.seed, channel, block])
                self._cache[key] = rng.standard_normal(_NOISE_BLOCK)
            lo = pos - block * _NOISE_BLOCK
            n = min(b - pos, _NOISE_BLOCK - lo)
            out[pos - a : pos - a + n] = self._cache[key][lo : lo + n]
            pos += n
        return out

    def acquire(
        self,
        signals: np.ndarray,
        first_index: int,
        disconnected: Sequence[int] = (),
        clip_levels: Mapping[int, float] | None = None,
    ) -> np.ndarray:
        """Samples as the DAQ returns them.

        Parameters
        ----------
        signals : ndarray, shape (n, C), channel units
            Physical signals at the sensors.
        first_index : int
            Sample index of ``signals[0]`` (keys the noise).
        disconnected : sequence of int
            Channel columns that see no signal.
        clip_levels : dict of int to float, optional
            Channel columns whose sensor saturates at the given level.

        Returns
        -------
        ndarray, shape (n, C), float64
        """
        x = np.array(signals, dtype=float)
        n = x.shape[0]
        for c in disconnected:
            x[:, c] = 0.0
        for c, level in (clip_levels or {}).items():
            np.clip(x[:, c], -level, level, out=x[:, c])
        for c, sigma in enumerate(self.sigma):
            if sigma > 0:
                x[:, c] += sigma * self._noise(c, first_index, first_index + n)
        volts = np.clip(x * self.scale, -self.range_v, self.range_v)
        if self.lsb_v is not None:
            volts = np.round(volts / self.lsb_v) * self.lsb_v
        return volts / self.scale
