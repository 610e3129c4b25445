"""Pairing identified test modes with model modes (MAC and frequency).

A test mode's shape over the measured channels is its row of modal constants
``a_rc = phi_r(c) phi_r(drive)``, proportional to the mode shape at the channels. It is paired
with a model mode by the modal assurance criterion and the frequency distance; the pairing is
one-to-one (Hungarian assignment on ``(1 - MAC) + |ln(f_model / f_test)|``).

References
----------
R. J. Allemang, "The modal assurance criterion - twenty years of use and abuse", Sound and
Vibration 37(8) (2003) 14-23.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from analysis.linear.modal import modal_analysis

__all__ = ["ModePair", "mac_matrix", "match_modes", "renumber_modes"]


@dataclass(frozen=True)
class ModePair:
    """An identified test mode and its model partner.

    Attributes
    ----------
    test_index : int
        0-based index among the identified modes.
    frequency_hz, zeta : float
        Identified natural frequency and damping ratio.
    model_mode : int or None
        1-based model mode number (ascending frequency), None when no partner reaches the MAC
        threshold.
    model_frequency_hz : float or None
    mac : float
    """

    test_index: int
    frequency_hz: float
    zeta: float
    model_mode: int | None
    model_frequency_hz: float | None
    mac: float

    def to_json(self) -> dict:
        return dict(self.__dict__)


def mac_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC between the columns of ``a`` (n, p) and ``b`` (n, q), shape (p, q)."""
    num = np.abs(a.conj().T @ b) ** 2
    den = np.outer(np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0))
    return num / np.maximum(den, 1e-300)


def match_modes(
    test_frequency_hz: np.ndarray,
    test_zeta: np.ndarray,
    test_shapes: np.ndarray,
    model_frequency_hz: np.ndarray,
    model_shapes: np.ndarray,
    mac_min: float = 0.5,
) -> list[ModePair]:
    """Pair test modes with model modes.

    Parameters
    ----------
    test_frequency_hz, test_zeta : ndarray, shape (p,)
    test_shapes : ndarray, shape (C, p)
        Test shapes at the channels (modal constants).
    model_frequency_hz : ndarray, shape (q,)
        Natural frequencies of model modes 1..q.
    model_shapes : ndarray, shape (C, q)
        Model shapes at the same channels.
    mac_min : float
        Pairs below are reported without a model mode.

    Returns
    -------
    list of ModePair, one per test mode
    """
    mac = mac_matrix(np.asarray(test_shapes, float), np.asarray(model_shapes, float))
    ratio = np.abs(
        np.log(np.asarray(model_frequency_hz)[None, :] / np.asarray(test_frequency_hz)[:, None])
    )
    cost = (1.0 - mac) + ratio
    ti, mi = linear_sum_assignment(cost)
    partner = dict(zip(ti.tolist(), mi.tolist(), strict=True))
    out = []
    for r in range(len(test_frequency_hz)):
        j = partner.get(r)
        ok = j is not None and mac[r, j] >= mac_min
        out.append(
            ModePair(
                test_index=r,
                frequency_hz=float(test_frequency_hz[r]),
                zeta=float(test_zeta[r]),
                model_mode=j + 1 if ok else None,
                model_frequency_hz=float(model_frequency_hz[j]) if ok else None,
                mac=float(mac[r, j]) if j is not None else 0.0,
            )
        )
    return out


def renumber_modes(M_from, K_from, M_to, K_to, numbers: list[int]) -> list[int]:
    """Mode numbers of one model's modes in a slightly different model (e.g. without sensors).

    Each mode ``n`` (1-based) of ``(M_from, K_from)`` is paired with the mode of
    ``(M_to, K_to)`` of largest mass-weighted MAC; same-size DOF sets are required.
    """
    a = modal_analysis(np.asarray(M_from), np.asarray(K_from)).phi
    b = modal_analysis(np.asarray(M_to), np.asarray(K_to)).phi
    q = max(numbers) + 5 if numbers else 0
    cross = np.abs(a[:, [n - 1 for n in numbers]].T @ np.asarray(M_to) @ b[:, :q]) ** 2
    return [int(np.argmax(row)) + 1 for row in cross]
