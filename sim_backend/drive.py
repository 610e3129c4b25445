"""The DAQ output as a program of the sample index: a regenerated waveform and its cross-fades.

The semantics are those of the NI driver's output buffer (``rig.backends.ni``): a periodic
waveform repeats with its first sample at ``anchor``; a new waveform replaces it with a
raised-cosine cross-fade that starts at a period boundary of the old waveform and lasts a
whole number of periods of the new one, so the returned index (fade end) is the first sample
of a whole period of the new waveform.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["DriveProgram", "analyse_period"]


@dataclass(frozen=True)
class DriveProgram:
    """Drive voltage [V] as a function of the sample index counted from start.

    ``wave`` (one period) repeats with ``wave[0]`` at ``anchor``; before
    ``fade_start + fade_len`` it is cross-faded from ``before`` (None: 0 V) with the weight
    ``0.5 - 0.5 cos(pi (j + 1) / fade_len)`` of ``wave`` at ``fade_start + j``, which reaches
    exactly 1 at the last sample of the fade.
    """

    wave: np.ndarray
    anchor: int
    fade_start: int
    fade_len: int
    before: DriveProgram | None = None

    @classmethod
    def zero(cls) -> DriveProgram:
        """0 V for ever."""
        return cls(np.zeros(1), 0, 0, 0, None)

    @property
    def period(self) -> int:
        return int(self.wave.size)

    @property
    def steady_from(self) -> int:
        """First index at which ``wave`` is in force at full weight."""
        return self.fade_start + self.fade_len

    def samples(self, index: np.ndarray) -> np.ndarray:
        """Drive at the given indices, shape of ``index``, V."""
        index = np.asarray(index, dtype=np.int64)
        out = self.wave[(index - self.anchor) % self.period]
        early = index < self.steady_from
        if early.any():
            k = index[early]
            old = self.before.samples(k) if self.before is not None else np.zeros(k.size)
            if self.fade_len:
                x = np.clip((k - self.fade_start + 1) / self.fade_len, 0.0, 1.0)
                weight = 0.5 - 0.5 * np.cos(np.pi * x)
            else:
                weight = np.zeros(k.size)
            out[early] = old + weight * (out[early] - old)
        return out

    def steady_samples(self, index: np.ndarray) -> np.ndarray:
        """The target waveform alone (no fade) at the given indices, V."""
        index = np.asarray(index, dtype=np.int64)
        return self.wave[(index - self.anchor) % self.period]

    def next_boundary(self, index: int) -> int:
        """First index at or after ``index`` where a period of ``wave`` starts."""
        return self.anchor - ((self.anchor - index) // self.period) * self.period

    def from_index(self, index: int) -> DriveProgram:
        """An equivalent program for indices at or after ``index`` (finished fades dropped)."""
        if index >= self.steady_from:
            return DriveProgram(self.wave, self.anchor, self.steady_from, 0, None)
        before = self.before.from_index(index) if self.before is not None else None
        return replace(self, before=before)

    def replaced(self, wave: np.ndarray, start: int, ramp_samples: float) -> DriveProgram:
        """Cross-fade to ``wave`` from ``start``, over ``ramp_samples`` rounded up to periods."""
        n = wave.size
        fade = math.ceil(ramp_samples / n - 1e-9) * n if ramp_samples > 0 else 0
        return DriveProgram(wave, start, start, fade, self.from_index(start))


@dataclass(frozen=True)
class PeriodContent:
    """Harmonic content of one period of a drive waveform.

    Attributes
    ----------
    base_bin : int
        Greatest common divisor of the non-zero DFT bins: the waveform repeats every
        ``n / base_bin`` samples in the harmonic sense; 0 for a zero waveform.
    phasors : ndarray, shape (K,), complex, V
        Phasors of harmonics ``1..K`` of the base (``x = Re sum X_k exp(i k w_b t)``, sample
        0 at ``t = 0``).
    mean_v : float
        DC component [V].
    """

    base_bin: int
    phasors: np.ndarray
    mean_v: float


def analyse_period(wave: np.ndarray, relative_floor: float = 1e-9) -> PeriodContent:
    """DFT of one period and the base harmonic it is built on.

    Bins below ``relative_floor`` times the largest are treated as empty.

    Parameters
    ----------
    wave : ndarray, shape (n,), V
    relative_floor : float

    Returns
    -------
    PeriodContent
    """
    n = wave.size
    spectrum = np.fft.rfft(wave) / n
    amps = np.abs(spectrum[1:])
    peak = amps.max(initial=0.0)
    if peak == 0.0:
        return PeriodContent(0, np.zeros(0, dtype=complex), float(spectrum[0].real))
    bins = np.flatnonzero(amps > relative_floor * peak) + 1
    base = int(np.gcd.reduce(bins))
    K = int(bins.max() // base)
    k = np.arange(1, K + 1) * base
    scale = np.where(2 * k == n, 1.0, 2.0)  # the Nyquist bin is not doubled
    phasors = spectrum[k] * scale
    keep = np.zeros(K, dtype=bool)
    keep[bins // base - 1] = True
    return PeriodContent(base, np.where(keep, phasors, 0.0), float(spectrum[0].real))
