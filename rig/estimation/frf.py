"""Frequency response functions from a random test: H1, and the periodic estimate.

``H1(f) = S_fy(f) / S_ff(f)`` with Welch-averaged one-sided spectra, and the ordinary coherence
``gamma^2 = |S_fy|^2 / (S_ff S_yy)``. H1 is unbiased by noise on the responses (not on the
force); with uncorrelated output noise ``gamma^2 = S_yy,signal / (S_yy,signal + S_nn)``.

Noise on the force biases H1 low by ``1 / (1 + S_nn / S_ff)``, worst where the force drops: at
the structure's resonances, where the shaker can hardly push. For a periodic excitation
(:func:`periodic_frf`) the spectra are averaged over the periods first and then divided; the
noise averages out of both before the division and the estimate is consistent.

References
----------
R. Pintelon, J. Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
Wiley 2012, ch. 2 (FRF measurement with periodic excitations, errors-in-variables).
J. S. Bendat, A. G. Piersol, *Random Data: Analysis and Measurement Procedures*, 4th ed.,
Wiley 2010, ch. 6 and 9 (single-input/output relationships, statistical errors).
"""

from __future__ import annotations

import logging
import math
from typing import NamedTuple

import numpy as np
from scipy import signal

__all__ = ["H1Estimate", "h1_frf", "periodic_frf", "welch_average_count"]

logger = logging.getLogger(__name__)


class H1Estimate(NamedTuple):
    """Result of :func:`h1_frf` (unpacks as a 4-tuple).

    Attributes
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    h1 : ndarray, shape (nf, C), complex, response unit per force unit
        NaN where the force PSD is zero.
    coherence : ndarray, shape (nf, C), float in [0, 1]
        NaN where the force or response PSD is zero.
    force_psd : ndarray, shape (nf,), force unit^2/Hz, one-sided
    """

    frequency_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    force_psd: np.ndarray


def _noverlap(nperseg: int, overlap: float) -> int:
    return int(round(overlap * nperseg))


def welch_average_count(n_samples: int, nperseg: int, overlap: float = 0.5) -> int:
    """Number of segments Welch averages (``n_averages`` of the measurement file)."""
    step = nperseg - _noverlap(nperseg, overlap)
    return max(0, (n_samples - nperseg) // step + 1)


def _check_inputs(force, responses, nperseg: int, overlap: float):
    f = np.asarray(force, dtype=float)
    y = np.asarray(responses, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if f.ndim != 1 or y.ndim != 2 or y.shape[0] != f.size:
        raise ValueError(
            "h1_frf: force must be (n,) and responses (n, C); got "
            f"{f.shape} and {np.shape(responses)}"
        )
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(y))):
        raise ValueError("h1_frf: force or responses contain NaN or inf")
    if not 2 <= nperseg <= f.size:
        raise ValueError(f"h1_frf: nperseg must be in [2, {f.size}], got {nperseg}")
    if not (math.isfinite(overlap) and 0 <= overlap < 1):
        raise ValueError(f"h1_frf: overlap must be in [0, 1), got {overlap}")
    return f, y


def h1_frf(
    force: np.ndarray,
    responses: np.ndarray,
    sample_rate_hz: float,
    nperseg: int,
    window: str = "hann",
    overlap: float = 0.5,
    band_hz: tuple[float, float] | None = None,
) -> H1Estimate:
    """H1 estimate, coherence and force PSD by Welch averaging.

    Parameters
    ----------
    force : ndarray, shape (n,), N
        Drive force.
    responses : ndarray, shape (n, C) or (n,), channel units
        Responses (the force channel itself may be among them; its H1 is 1).
    sample_rate_hz : float
        Sample rate [Hz].
    nperseg : int
        Segment length; the frequency spacing is ``fs / nperseg``.
    window : str
        Window name for :func:`scipy.signal.get_window`.
    overlap : float
        Segment overlap as a fraction in [0, 1).
    band_hz : (float, float), optional
        Keep only the bins inside this band (the excited band).

    Returns
    -------
    H1Estimate
        ``(frequency_hz, h1, coherence, force_psd)``.
    """
    f, y = _check_inputs(force, responses, nperseg, overlap)
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise ValueError(f"h1_frf: sample_rate_hz must be > 0, got {sample_rate_hz}")
    opts = dict(
        fs=sample_rate_hz,
        window=window,
        nperseg=nperseg,
        noverlap=_noverlap(nperseg, overlap),
        axis=0,
    )
    freq, s_ff = signal.welch(f, **opts)
    _, s_yy = signal.welch(y, **opts)
    _, s_fy = signal.csd(f[:, None], y, **opts)
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = np.where(s_ff[:, None] > 0, s_fy / s_ff[:, None], np.nan)
        denom = s_ff[:, None] * s_yy
        coherence = np.where(denom > 0, np.abs(s_fy) ** 2 / denom, np.nan)
    if band_hz is not None:
        keep = (freq >= band_hz[0]) & (freq <= band_hz[1])
        freq, h1, coherence, s_ff = freq[keep], h1[keep], coherence[keep], s_ff[keep]
    logger.debug(
        "H1 from %d averages, df = %.4g Hz",
        welch_average_count(f.size, nperseg, overlap),
        sample_rate_hz / nperseg,
    )
    return H1Estimate(freq, h1, np.clip(coherence, 0.0, 1.0), s_ff)


def periodic_frf(
    force: np.ndarray,
    responses: np.ndarray,
    sample_rate_hz: float,
    period: int,
    band_hz: tuple[float, float] | None = None,
) -> H1Estimate:
    """FRF of a periodic excitation: the ratio of the period-averaged spectra.

    ``H = mean_p Y_p / mean_p F_p`` over the ``P`` whole periods of the record; the coherence
    and the force PSD are those of :func:`h1_frf` with one period per segment (rectangular
    window, no overlap), so their statistics stay comparable.

    Parameters
    ----------
    force : ndarray, shape (n,), N
        Drive force, starting on a period boundary of the excitation.
    responses : ndarray, shape (n, C) or (n,), channel units
    sample_rate_hz : float
    period : int
        Samples per period of the excitation (the samples beyond whole periods are unused).
    band_hz : (float, float), optional
        Keep only the bins inside this band.

    Returns
    -------
    H1Estimate
        ``(frequency_hz, h, coherence, force_psd)``; NaN where the averaged force is zero.
    """
    f, y = _check_inputs(force, responses, period, 0.0)
    if f.size < 2 * period:
        raise ValueError(f"periodic_frf: at least two periods of {period} samples needed")
    est = h1_frf(f, y, sample_rate_hz, period, window="boxcar", overlap=0.0)
    p = f.size // period
    spec_f = np.fft.rfft(f[: p * period].reshape(p, period), axis=1).mean(axis=0)
    spec_y = np.fft.rfft(y[: p * period].reshape(p, period, y.shape[1]), axis=1).mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(np.abs(spec_f)[:, None] > 0, spec_y / spec_f[:, None], np.nan)
    freq = est.frequency_hz
    if band_hz is not None:
        keep = (freq >= band_hz[0]) & (freq <= band_hz[1])
        return H1Estimate(freq[keep], h[keep], est.coherence[keep], est.force_psd[keep])
    return H1Estimate(freq, h, est.coherence, est.force_psd)
