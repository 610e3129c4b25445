"""The damping-equalized FRF deviation and its analytic Jacobian.

Residuals, for calibration channels ``c`` and metric frequencies ``omega_k``::

    r_kc = log10 |H^A_c(omega_k; p)| - log10 |H^X_c(omega_k)|

with the model receptance ``H^A`` (every mode at ``zeta0``, residual flexibility for the modes
above ``f_max_hz``) and the equalized test receptance ``H^X``. With ``use_phase`` the phase
deviation ``arg(H^A / H^X) / ln 10`` is appended (the imaginary part of the complex log10
difference), which weighs phase like magnitude. The default leaves phase out: log-magnitudes
are smooth in the parameters and insensitive to sensor-phase errors.

Jacobian (chain rule through the log): ``d r / d theta = Re(dH / H) / ln 10 * dp / dtheta``
(``Im`` for the phase part), with ``dH/dp`` the exact receptance derivative of
:class:`analysis.linear.receptance.ModalLinearModel` (modal damping ratios held at ``zeta0``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from analysis.calibration.parameters import ParameterSpace
from analysis.linear.receptance import ModalLinearModel
from analysis.model import Model

__all__ = ["EqualizedFRFObjective"]

LN10 = np.log(10.0)


class EqualizedFRFObjective:
    """Residuals and Jacobian of the damping-equalized log-magnitude deviation.

    Parameters
    ----------
    model : Model
        With the sensor masses; the calibrated parameters are set from ``theta``.
    space : ParameterSpace
        Calibrated parameters (group ``"linear"``) and their scaling.
    rows : sequence of int
        Model DOF of each compared channel (length C).
    col : int
        Drive DOF.
    frequency_hz : ndarray, shape (nk,), Hz
        Metric frequencies.
    target : ndarray, shape (nk, C), complex, m/N
        Equalized test receptances.
    zeta0 : float
    f_max_hz : float
        Modes up to this frequency are superposed, the rest enter as residual flexibility.
    use_phase : bool
    """

    def __init__(
        self,
        model: Model,
        space: ParameterSpace,
        rows: Sequence[int],
        col: int,
        frequency_hz: np.ndarray,
        target: np.ndarray,
        zeta0: float,
        f_max_hz: float,
        use_phase: bool = False,
    ) -> None:
        self.model = model
        self.space = space
        self.rows = list(rows)
        self.col = int(col)
        self.omega = 2 * np.pi * np.asarray(frequency_hz, dtype=float)
        self.target = np.asarray(target, dtype=complex)
        if self.target.shape != (self.omega.size, len(self.rows)):
            raise ValueError(
                f"target must have shape {(self.omega.size, len(self.rows))}, "
                f"got {self.target.shape}"
            )
        self.zeta0 = float(zeta0)
        self.f_max_hz = float(f_max_hz)
        self.use_phase = bool(use_phase)
        self._log_target = np.log10(np.abs(self.target))
        self.nfev = 0

    @property
    def n_residuals(self) -> int:
        return self.target.size * (2 if self.use_phase else 1)

    def linear_model(self, values: dict[str, float]) -> ModalLinearModel:
        """The equalized model at parameter ``values`` (with derivatives for the space)."""
        asm = self.model.with_values(values).assemble()
        names = self.space.names
        return ModalLinearModel(
            asm.M, asm.K, self.zeta0, f_max_hz=self.f_max_hz,
            dM={n: asm.dM[n] for n in names}, dK={n: asm.dK[n] for n in names},
        )  # fmt: skip

    def frf(self, theta: np.ndarray, want_jac: bool = False):
        """Model receptances ``(nk, C)`` and, optionally, ``dH/dtheta`` ``(nk, C, n)``."""
        p = self.space.to_physical(theta)
        lin = self.linear_model(self.space.as_dict(p))
        blk = lin.block(self.rows, [self.col])
        blk.residual = _high_mode_flexibility(lin, self.rows, [self.col])
        H = blk(self.omega)[:, :, 0]
        if not want_jac:
            return H, None
        dp = self.space.dp_dtheta(theta)
        dH = np.stack(
            [blk.derivative(self.omega, n)[:, :, 0] * dp[j]
             for j, n in enumerate(self.space.names)], axis=-1,
        )  # fmt: skip
        return H, dH

    def __call__(self, theta: np.ndarray, want_jac: bool = True):
        """``(r, J)``: residuals shape (m,), Jacobian shape (m, n) or None."""
        self.nfev += 1
        H, dH = self.frf(np.asarray(theta, dtype=float), want_jac)
        r = np.log10(np.abs(H)) - self._log_target
        parts = [r.ravel()]
        if self.use_phase:
            parts.append(np.angle(H / self.target).ravel() / LN10)
        if not want_jac:
            return np.concatenate(parts), None
        q = dH / H[:, :, None]
        J = [q.real.reshape(-1, q.shape[-1]) / LN10]
        if self.use_phase:
            J.append(q.imag.reshape(-1, q.shape[-1]) / LN10)
        return np.concatenate(parts), np.concatenate(J)

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Residuals only, shape (m,)."""
        return self(theta, want_jac=False)[0]


def _high_mode_flexibility(lin: ModalLinearModel, rows: list[int], cols: list[int]) -> np.ndarray:
    """Static flexibility of the modes not superposed, summed mode by mode, shape (nr, nc).

    The same quantity as ``K^-1 - sum_retained phi phi^T / omega^2`` but free of its
    cancellation: on soft mounts ``K^-1`` is dominated by the mount modes, and the difference
    keeps only round-off noise of that size, which makes the FRFs of weakly responding channels
    jitter between nearby parameter values.
    """
    modes = lin.all_modes
    high = np.setdiff1d(np.arange(len(modes)), lin.keep)
    phi = modes.phi[:, high]
    return (phi[rows] / modes.omega[high] ** 2) @ phi[cols].T
