"""Starting poles for the modal identification: least-squares complex frequency (LSCF).

A common-denominator rational model in the z-domain, ``H_o = N_o(z) / D(z)`` with real
polynomial coefficients and ``z = exp(-i omega T)``, is fitted to all channels at once in the
linearised sense; the numerators are eliminated from the normal equations, so only the small
reduced matrix of the denominator is solved. The poles are computed for a range of model
orders and those that persist (a stabilisation diagram read automatically) are returned.

References
----------
P. Guillaume, P. Verboven, S. Vanlanduit, H. Van der Auweraer, B. Peeters, "A poly-reference
implementation of the least-squares complex frequency-domain estimator", IMAC XXI (2003).
B. Peeters, H. Van der Auweraer, P. Guillaume, J. Leuridan, "The PolyMAX frequency-domain
method: a new standard for modal parameter estimation?", Shock and Vibration 11 (2004) 395-409.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

__all__ = ["StablePole", "lscf_poles", "stable_poles", "starting_poles"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StablePole:
    """A pole that persists over model orders.

    Attributes
    ----------
    frequency_hz : float
        Undamped natural frequency ``|lambda| / 2 pi``.
    zeta : float
        Damping ratio ``-Re(lambda) / |lambda|``.
    n_orders : int
        Number of model orders at which the pole was found stable.
    """

    frequency_hz: float
    zeta: float
    n_orders: int

    @property
    def pole(self) -> complex:
        """``lambda = -zeta omega + i omega sqrt(1 - zeta^2)`` [rad/s]."""
        w = 2 * np.pi * self.frequency_hz
        return complex(-self.zeta * w, w * np.sqrt(1 - self.zeta**2))


def _reduced_r(
    omega: np.ndarray, H: np.ndarray, order: int, T: float, weights: np.ndarray | None = None
) -> np.ndarray:
    """Triangular factor of the denominator's reduced problem, shape (order + 1, order + 1).

    Channel by channel the numerator is projected out of the equation error (QR of the
    numerator basis, not the normal equations: for a good fit the reduced normal matrix is a
    small difference of large terms); the projected denominator columns of all channels are
    stacked and reduced to one triangular factor ``R``. The order-``n`` denominator solves
    ``R[:n, :n] a = -R[:n, n]`` (leading columns of a QR factor are the QR factor of the
    leading columns).

    Each channel is scaled to unit RMS magnitude; ``weights`` ``W`` (nf, C), if given, then
    scale the equation error of channel ``o`` at each frequency by ``W[:, o]`` (e.g. the
    coherence, so noisy lines and channels count less). Without them every line counts alike.
    """
    X = np.exp(-1j * np.outer(omega, np.arange(order + 1)) * T)  # (nf, n+1)
    blocks = []
    for o in range(H.shape[1]):
        h = H[:, o]
        w = np.full(h.size, 1.0 / max(float(np.sqrt(np.mean(np.abs(h) ** 2))), 1e-300))
        if weights is not None:
            w = w * np.asarray(weights[:, o], dtype=float)
        A = w[:, None] * X
        B = -(w * h)[:, None] * X
        Ar = np.concatenate([A.real, A.imag])
        Br = np.concatenate([B.real, B.imag])
        Q, _ = np.linalg.qr(Ar)
        Bp = Br - Q @ (Q.T @ Br)
        blocks.append(np.linalg.qr(Bp, mode="r"))
    return np.linalg.qr(np.concatenate(blocks), mode="r")


def lscf_poles(
    frequency_hz: np.ndarray,
    H: np.ndarray,
    orders: list[int],
    f_max_hz: float,
    weights: np.ndarray | None = None,
) -> dict[int, np.ndarray]:
    """Poles of LSCF models of the given orders.

    Parameters
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    H : ndarray, shape (nf, C), complex
        FRFs of one input (any consistent unit per channel).
    orders : list of int
        Denominator orders (number of poles including conjugates).
    f_max_hz : float
        Sets the sampling interval of the z-domain, ``T = 1 / (2 f_max)``; above the band.
    weights : ndarray, shape (nf, C), optional
        Equation-error weights on top of the channel scaling (e.g. the coherence).

    Returns
    -------
    dict order -> ndarray of complex, rad/s
        All roots of each order's denominator as s-domain poles.
    """
    omega = 2 * np.pi * np.asarray(frequency_hz, dtype=float)
    T = 1.0 / (2.0 * f_max_hz)
    n_max = max(orders)
    R = _reduced_r(omega, np.asarray(H), n_max, T, weights)
    out = {}
    for n in orders:
        a = np.linalg.lstsq(R[:n, :n], -R[:n, n], rcond=None)[0]
        coeffs = np.append(a, 1.0)  # ascending powers of z
        roots = np.roots(coeffs[::-1])
        roots = roots[np.isfinite(roots) & (np.abs(roots) > 0)]
        out[n] = -np.log(roots.astype(complex)) / T
    return out


def _physical(poles: np.ndarray, band: tuple[float, float], zeta_max: float) -> np.ndarray:
    """(frequency_hz, zeta) rows of upper-half-plane poles in the band with 0 < zeta < max."""
    p = poles[poles.imag > 0]
    f = np.abs(p) / (2 * np.pi)
    z = -p.real / np.abs(p)
    keep = (f >= band[0]) & (f <= band[1]) & (z > 0) & (z < zeta_max)
    rows = np.column_stack([f[keep], z[keep]])
    return rows[np.argsort(rows[:, 0])]


def stable_poles(
    frequency_hz: np.ndarray,
    H: np.ndarray,
    band_hz: tuple[float, float],
    *,
    max_order: int = 48,
    zeta_max: float = 0.2,
    tol_frequency: float = 0.02,
    tol_zeta: float = 0.5,
    tol_group: float = 0.005,
    min_fraction: float = 0.3,
    weights: np.ndarray | None = None,
) -> list[StablePole]:
    """Poles stable over LSCF model orders 4, 6, ..., ``max_order``.

    A pole at order ``n`` is stable when order ``n - 2`` has one within ``tol_frequency``
    (relative) in frequency and ``tol_zeta`` (relative) in damping (loose: the starting poles
    are refined by the pole-residue fit). Stable poles are grouped by frequency (a relative gap
    above ``tol_group`` starts a new group); a group found at no fewer than
    ``min_fraction`` of the orders (and at least 3) gives one pole, the median of the group.

    Parameters
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    H : ndarray, shape (nf, C), complex
    band_hz : (float, float)
        Only poles with natural frequency inside are returned (stability is judged over all
        fitted frequencies, so a pole on the band's edge is not lost).
    weights : ndarray, shape (nf, C), optional
        See :func:`lscf_poles`.

    Returns
    -------
    list of StablePole, ascending frequency
    """
    orders = list(range(4, max_order + 1, 2))
    f_max = float(np.max(frequency_hz)) * 1.05
    poles = lscf_poles(frequency_hz, H, orders, f_max, weights)
    stable: list[tuple[float, float]] = []
    prev = np.zeros((0, 2))
    fitted = (float(np.min(frequency_hz)), float(np.max(frequency_hz)))
    for n in orders:
        rows = _physical(poles[n], fitted, zeta_max)
        for f, z in rows:
            if prev.size:
                df = np.abs(prev[:, 0] - f) / f
                dz = np.abs(prev[:, 1] - z) / z
                if np.any((df < tol_frequency) & (dz < tol_zeta)):
                    stable.append((f, z))
        prev = rows
    if not stable:
        return []
    arr = np.array(sorted(stable))
    groups = np.split(arr, np.flatnonzero(np.diff(arr[:, 0]) / arr[1:, 0] > tol_group) + 1)
    need = max(3, int(np.ceil(min_fraction * len(orders))))
    out = [
        StablePole(float(np.median(g[:, 0])), float(np.median(g[:, 1])), len(g))
        for g in groups
        if len(g) >= need and band_hz[0] <= np.median(g[:, 0]) <= band_hz[1]
    ]
    log.debug("LSCF: %d stable poles from orders %d..%d", len(out), orders[0], orders[-1])
    return out


def starting_poles(
    frequency_hz: np.ndarray,
    H: np.ndarray,
    band_hz: tuple[float, float],
    *,
    max_order: int = 32,
    zeta_max: float = 0.2,
    margin: float = 0.02,
    weights: np.ndarray | None = None,
) -> list[StablePole]:
    """Stable poles over a wide band, found sub-band by sub-band.

    One z-domain model over a band of several decades resolves its low modes poorly (they
    crowd near ``z = 1``). The band is cut at ``f_lo * 2^k``; sub-band ``k`` spans
    ``[e_(k-1), e_(k+2)]`` (three octaves) and contributes the stable poles of its middle
    octave ``[e_k, e_(k+1)]`` widened by ``margin`` (relative); of two poles from neighbouring
    sub-bands within 0.5 % of each other the one stable over more orders is kept.

    Parameters
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
    H : ndarray, shape (nf, C), complex
    band_hz : (float, float)
    weights : ndarray, shape (nf, C), optional
        See :func:`lscf_poles`.

    Returns
    -------
    list of StablePole, ascending frequency
    """
    f = np.asarray(frequency_hz, dtype=float)
    lo, hi = band_hz
    n_oct = max(1, int(np.ceil(np.log2(hi / lo))))
    edges = lo * 2.0 ** np.arange(n_oct + 1)
    edges[-1] = hi
    found: list[tuple[float, int, StablePole]] = []
    for k in range(n_oct):
        a, b = edges[max(k - 1, 0)], edges[min(k + 2, n_oct)]
        m = (f >= a) & (f <= b)
        if np.count_nonzero(m) < 8:
            continue
        core = (edges[k] / (1 + margin), edges[k + 1] * (1 + margin))
        W = None if weights is None else np.asarray(weights)[m]
        poles = stable_poles(f[m], H[m], core, max_order=max_order, zeta_max=zeta_max, weights=W)
        found += [(p.frequency_hz, k, p) for p in poles]
    # a pole near an octave edge may come from both neighbours: keep the better supported
    out: list[tuple[float, int, StablePole]] = []
    for item in sorted(found, key=lambda t: t[0]):
        f_r, k, p = item
        if out and out[-1][1] != k and f_r - out[-1][0] < 0.005 * f_r:
            if p.n_orders > out[-1][2].n_orders:
                out[-1] = item
        else:
            out.append(item)
    return [p for f_r, _, p in out if lo <= f_r <= hi]
