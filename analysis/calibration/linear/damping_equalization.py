"""Damping equalization: test and model FRFs with one modal damping for every mode.

The identified modal model of the test (:class:`~analysis.calibration.linear.modal_id.ModalFit`)
is re-synthesised with every mode at the damping ``zeta0`` (natural frequencies, modal
constants and residual terms kept), and the FE model is given the same ``zeta0`` for all its
modes, i.e. the viscous damping ``V = M X diag(m_n)^-1 diag(2 zeta0 m_n omega_n) diag(m_n)^-1
X^T M``. Only mass and stiffness remain to be calibrated, and the comparison of the two no longer
hinges on the sharp, damping-controlled resonance peaks. The comparison frequencies lie at equal
log increments within the half-power band ``omega_r (1 - zeta0) .. omega_r (1 + zeta0)`` of each
test mode, where the FRFs carry most information on the modes.

References
----------
T. J. S. Abrahamsson, D. C. Kammer, "Finite element model calibration using frequency
responses with damping equalization", Mechanical Systems and Signal Processing 62-63 (2015)
218-234; also "FEM calibration with FRF damping equalization", IMAC XXXII (2014).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.calibration.linear.modal_id import ModalFit

__all__ = ["EqualizedTest", "equalize", "metric_frequencies"]


def metric_frequencies(
    natural_frequency_hz: np.ndarray, zeta0: float, n_per_band: int = 9
) -> np.ndarray:
    """Frequencies at equal log increments within each mode's half-power band.

    Parameters
    ----------
    natural_frequency_hz : ndarray, shape (m,), Hz
    zeta0 : float
        Equalized damping ratio; the band of mode ``r`` is ``f_r (1 - zeta0) .. f_r (1 + zeta0)``
        (the half-power points to first order in ``zeta0``).
    n_per_band : int
        Points per band, ends included (>= 2).

    Returns
    -------
    ndarray, shape (m * n_per_band,), Hz
        Band by band, ascending.
    """
    if not 0 < zeta0 < 0.5:
        raise ValueError(f"zeta0 must be in (0, 0.5), got {zeta0!r}")
    if n_per_band < 2:
        raise ValueError(f"n_per_band must be >= 2, got {n_per_band!r}")
    f = np.sort(np.asarray(natural_frequency_hz, dtype=float))
    u = np.linspace(np.log1p(-zeta0), np.log1p(zeta0), n_per_band)
    return (f[:, None] * np.exp(u)[None, :]).ravel()


@dataclass(frozen=True)
class EqualizedTest:
    """The damping-equalized test FRFs at the metric frequencies.

    Attributes
    ----------
    frequency_hz : ndarray, shape (nk,), Hz
        Metric frequencies (:func:`metric_frequencies`).
    H : ndarray, shape (nk, C), complex, m/N
        Test receptances re-synthesised with every mode at ``zeta0``.
    zeta0 : float
    fit : ModalFit
        The identified test modes.
    """

    frequency_hz: np.ndarray
    H: np.ndarray
    zeta0: float
    fit: ModalFit


def equalize(fit: ModalFit, zeta0: float, n_per_band: int = 9) -> EqualizedTest:
    """Damping-equalized test FRFs at the metric frequencies of ``fit``'s modes."""
    if fit.n_modes == 0:
        raise ValueError("no identified mode to equalize")
    f = metric_frequencies(fit.frequency_hz, zeta0, n_per_band)
    return EqualizedTest(frequency_hz=f, H=fit.synthesize(f, zeta0), zeta0=zeta0, fit=fit)
