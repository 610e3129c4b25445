"""Fisher information of sweep data: noise, whitened Jacobians, per-sensor blocks, MAC.

With data ``z`` the stacked real and imaginary parts of the multi-harmonic FRFs and
independent Gaussian noise of standard deviation ``sigma_n`` on each entry,

    FIM = sum_n sigma_n^-2 (dz_n/dP) (dz_n/dP)^T.

Since the force phasors are known, ``dz/dP`` and ``sigma`` of an FRF ``Q / F`` are those of the
response phasor ``Q`` divided by ``|F|``, so the information is computed from the response
phasors directly. The sum runs over steps, orders and sensors; its part for one sensor of one
sweep is a ``p x p`` block, and the FIM of a configuration is the sum of its blocks.

Parameters are scaled, ``theta_i = P_i / s_i``, so that the blocks are well conditioned:
``FIM_theta = S FIM_P S`` with ``S = diag(s)``.

References
----------
Y. Chen et al., ISMA 2016 (the reference paper), sec. 2.1.2, eq. (3). D. C. Kammer,
"Sensor placement for on-orbit modal identification and correlation of large space
structures", J. Guidance 14 (1991) (the Fisher information in test planning).
"""

from __future__ import annotations

import numpy as np

from analysis.planning.candidates import NoiseModel
from analysis.planning.sweeps import SweepSensitivities

__all__ = [
    "correlation_indices",
    "information_blocks",
    "jacobian_mac",
    "phasor_sigma",
    "whitened_jacobian",
    "whitened_sensitivities",
]


def phasor_sigma(
    sweep: SweepSensitivities, sensors: tuple[int, ...], noise: NoiseModel
) -> np.ndarray:
    """Noise standard deviation of each real component of the displacement phasors.

    Parameters
    ----------
    sweep : SweepSensitivities
    sensors : tuple of int
        The sweep's output points, in its order.
    noise : NoiseModel

    Returns
    -------
    ndarray, shape (n_steps, n_orders, n_sensors), m
        ``inf`` at orders without force (no FRF there: no information).
    """
    w2 = (2 * np.pi * sweep.frequency_hz[:, None] * sweep.order_values[None, :]) ** 2
    floors = np.array([noise.floor_at(s) for s in sensors])
    Q = sweep.outputs
    F = np.abs(sweep.force)
    with np.errstate(divide="ignore", invalid="ignore"):
        if noise.quantity == "acceleration":
            # sigma_Q = sigma_A / (nu Omega)^2, |A| = (nu Omega)^2 |Q|
            sigma = np.sqrt((noise.relative * np.abs(Q)) ** 2 + (floors / w2[:, :, None]) ** 2)
        else:
            # sigma_Q = sigma_H |F|, |H| = |Q| / |F|
            sigma = np.sqrt((noise.relative * np.abs(Q)) ** 2 + (floors * F[None, :, None]) ** 2)
    sigma = np.where(F[None, :, None] > 0, sigma, np.inf)
    return sigma


def whitened_sensitivities(
    sweep: SweepSensitivities,
    sensors: tuple[int, ...],
    noise: NoiseModel,
    scales: np.ndarray,
) -> np.ndarray:
    """Sensitivities of the phasors in noise units, per scaled parameter.

    Parameters
    ----------
    scales : ndarray, shape (n_params,)
        ``s`` of ``theta = P / s`` [parameter units].

    Returns
    -------
    ndarray, shape (n_steps, n_orders, n_sensors, n_params), complex
        ``dQ/dtheta / sigma`` (dimensionless); its real and imaginary parts are rows of the
        whitened Jacobian.
    """
    sigma = phasor_sigma(sweep, sensors, noise)
    return sweep.d_outputs * np.asarray(scales)[None, None, None, :] / sigma[..., None]


def information_blocks(
    sweep: SweepSensitivities,
    sensors: tuple[int, ...],
    noise: NoiseModel,
    scales: np.ndarray,
) -> np.ndarray:
    """Fisher information of each sensor's data in one sweep, in scaled parameters.

    Returns
    -------
    ndarray, shape (n_sensors, n_params, n_params)
        ``sum over steps and orders of Re(conj(w) w^T)`` with ``w`` the whitened sensitivities
        (``Re^T Re + Im^T Im`` of the stacked real Jacobian rows); symmetric, positive
        semi-definite; per ``theta`` unit squared.
    """
    W = whitened_sensitivities(sweep, sensors, noise, scales)
    B = np.einsum("tosi,tosj->sij", W.conj(), W).real
    return 0.5 * (B + B.transpose(0, 2, 1))


def whitened_jacobian(
    sweeps: list[SweepSensitivities],
    sensors: tuple[int, ...],
    use: tuple[int, ...],
    noise: NoiseModel,
    scales: np.ndarray,
) -> np.ndarray:
    """The real stacked whitened Jacobian of a configuration's data, explicitly.

    Parameters
    ----------
    sweeps : list of SweepSensitivities
        One per level of the configuration (same range and actuator).
    sensors : tuple of int
        The sweeps' output points.
    use : tuple of int
        The configuration's sensor points (a subset of ``sensors``).

    Returns
    -------
    ndarray, shape (2 * n_data, n_params)
        Rows ``Re`` then ``Im`` of ``dz_n/dtheta / sigma_n`` over levels, steps, orders with
        force and the used sensors: ``J.T @ J`` is the configuration's FIM in scaled
        parameters.
    """
    cols = [sensors.index(s) for s in use]
    rows = []
    for sw in sweeps:
        forced = np.flatnonzero(np.abs(sw.force) > 0)
        W = whitened_sensitivities(sw, sensors, noise, scales)[:, forced][:, :, cols, :]
        rows.append(W.reshape(-1, W.shape[-1]))
    Wc = np.concatenate(rows)
    return np.concatenate([Wc.real, Wc.imag])


def jacobian_mac(J: np.ndarray) -> np.ndarray:
    """MAC between the columns of a Jacobian, ``|a^H b|^2 / (a^H a b^H b)``.

    Parameters
    ----------
    J : ndarray, shape (n_rows, n_params), real or complex

    Returns
    -------
    ndarray, shape (n_params, n_params)
        1 on the diagonal (``nan`` for a zero column); independent of column scaling.
    """
    G = J.conj().T @ J
    return correlation_indices(G)


def correlation_indices(fim: np.ndarray) -> np.ndarray:
    """Parameter correlation indices (MAC of the whitened Jacobian columns) from an FIM.

    With ``FIM = J^T J``, ``MAC_ij = FIM_ij^2 / (FIM_ii FIM_jj)``; the same in any parameter
    scaling.

    Parameters
    ----------
    fim : ndarray, shape (n_params, n_params)

    Returns
    -------
    ndarray, shape (n_params, n_params)
    """
    G = np.asarray(fim)
    d = np.real(np.diag(G))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(G) ** 2 / np.outer(d, d)
