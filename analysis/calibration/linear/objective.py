"""The damping-equalized FRF deviation and its analytic Jacobian.

Residuals, for calibration channels ``c`` and metric frequencies ``omega_k``::

    r_kc = log10 |H^A_c(omega_k; p)| - log10 |H^X_c(omega_k)|

with the model receptance ``H^A`` (every mode at ``zeta0``, residual flexibility for the modes
above ``f_max_hz``) and the equalized test receptance ``H^X``. With ``use_phase`` the phase
deviation ``arg(H^A / H^X) / ln 10`` is appended (the imaginary part of the complex log10
difference), which weighs phase like magnitude. The default leaves phase out: log-magnitudes
are smooth in the parameters and insensitive to sensor-phase errors.

Jacobian (chain rule through the log): ``d r / d theta = Re(dH / H) / ln 10 * dp / dtheta``
(``Im`` for the phase part), with ``dH/dp`` the exact receptance derivative of the blocks of
:class:`analysis.linear.receptance.ModalLinearModel` (modal damping ratios held at ``zeta0``).

The static flexibility of the modes above ``f_max_hz`` is summed mode by mode,
``R_h = P K^-1 P^T`` with the mass-orthogonal projector ``P = I - X_l X_l^T M`` off the retained
modes ``X_l``, and differentiated as

    dR_h = -R_h dK R_h - X_l (dX_l^T M + X_l^T dM) R_h - R_h (M dX_l + dM X_l) X_l^T,

which, unlike ``d(K^-1) - d(X_l diag(omega_l^-2) X_l^T)``, involves no cancellation of the
large flexibility of the mount modes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from analysis.calibration.parameters import ParameterSpace
from analysis.linear.modal import Modes
from analysis.linear.receptance import ModalLinearModel
from analysis.model import Model

__all__ = ["EqualizedFRFObjective", "receptance"]

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
        self._last: tuple[bytes, Any, Modes] | None = None

    @property
    def n_residuals(self) -> int:
        return self.target.size * (2 if self.use_phase else 1)

    def frf(self, theta: np.ndarray, want_jac: bool = False):
        """Model receptances ``(nk, C)`` and, optionally, ``dH/dtheta`` ``(nk, C, n)``."""
        key = theta.tobytes()
        if self._last is not None and self._last[0] == key:
            # the accepted trial of a fit, evaluated again for its Jacobian: its eigensolution
            _, asm, modes = self._last
        else:
            p = self.space.to_physical(theta)
            asm, modes = self.model.with_values(self.space.as_dict(p)).assemble(), None
        names = self.space.names
        dM = {n: asm.dM[n] for n in names} if want_jac else None
        dK = {n: asm.dK[n] for n in names} if want_jac else None
        lin = ModalLinearModel(
            asm.M, asm.K, self.zeta0, f_max_hz=self.f_max_hz, dM=dM, dK=dK, modes=modes
        )
        self._last = (key, asm, lin.all_modes)
        # its residual is the truncated modes' static flexibility, with exact derivatives
        blk = lin.block(self.rows, [self.col])
        H = blk(self.omega)[:, :, 0]
        if not want_jac:
            return H, None
        dp = self.space.dp_dtheta(theta)
        dH = np.stack(
            [blk.derivative(self.omega, n)[:, :, 0] * dp[j] for j, n in enumerate(names)],
            axis=-1,
        )
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


def receptance(
    model: Model,
    rows: Sequence[int],
    col: int,
    frequency_hz: np.ndarray,
    *,
    zeta: float | dict[int, float] | None = None,
    f_max_hz: float,
) -> np.ndarray:
    """Model receptances ``H[rows, col]``, shape (nf, C), m/N.

    Modes up to ``f_max_hz`` are superposed with damping ``zeta`` (one ratio, or
    ``{mode: ratio}``; default: the model's :class:`~analysis.model.DampingSpec`), the rest
    enter as their static flexibility.
    """
    asm = model.assemble()
    if zeta is None:
        zeta = dict(model.damping.per_mode)
    lin = ModalLinearModel(
        asm.M, asm.K, zeta, default_zeta=model.damping.default_zeta, f_max_hz=f_max_hz
    )
    blk = lin.block(list(rows), [col])
    return blk(2 * np.pi * np.asarray(frequency_hz, dtype=float))[:, :, 0]
