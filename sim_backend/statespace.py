"""State-space form of the coupled rig, diagonalised, with exact sampled-time discretisation.

The structure is the second-order reduced model of the truth (retained modes plus residual
static shapes of the loaded DOFs, :func:`analysis.linear.reduced.reduced_model`), coupled to
the shaker and amplifier of :mod:`sim_backend.shaker`::

    s = [z, z', x_a, x_a', I, V_amp]
    z''    = -K z - C z' + T_d^T k_st (x_a - T_d z) + T_n^T f_nl
    m_a x_a'' = -k_s x_a - c_s x_a' - k_st (x_a - T_d z) + Bl I
    L I'   = V_amp - (R + R_o) I - Bl x_a'
    V_amp' = w_c (u - V_amp)          u = amplifier gain x DAQ output voltage

``s' = A s + b u + B_n f_nl`` is diagonalised, ``A = W diag(lam) W^-1``; with modal coordinates
``eta = W^-1 s`` every mode is a scalar first-order system. Over a step ``h`` the DAQ output and
the forces are taken linear between their samples (first-order hold), so
``eta[j+1] = E eta[j] + gA u[j] + gB u[j+1] + H0 f[j] + H1 f[j+1]`` exactly for those inputs.

The DAQ output is modelled as the linear interpolation of its samples: a DAC with an
anti-imaging filter puts out a smooth, band-limited signal, whereas a held staircase would
carry images near the sample rate that alias back onto the measured harmonics. Its in-band
response is ``sinc^2(f / fs)`` (zero phase; 5e-4 droop at fs / 80), applied to the periodic
drive in the balance as well, and its images are down by ``(f / fs)^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from analysis.linear.reduced import SecondOrderModel
from sim_backend.shaker import ShakerConstants

__all__ = ["Discretised", "ModalStateSpace", "build_state_space"]


@dataclass(frozen=True)
class Discretised:
    """Exact per-mode update over one step (see the module notes).

    Attributes
    ----------
    step_s : float
    E : ndarray, shape (p,), complex
    gA, gB : ndarray, shape (p,), complex
        Input vectors of ``u`` at the start and end of the step.
    H0, H1 : ndarray, shape (p, n_nl), complex
        Force inputs at the start and end of the step (first-order hold).
    """

    step_s: float
    E: np.ndarray
    gA: np.ndarray
    gB: np.ndarray
    H0: np.ndarray
    H1: np.ndarray


@dataclass(frozen=True)
class ModalStateSpace:
    """Diagonalised coupled rig.

    Attributes
    ----------
    lam : ndarray, shape (p,), complex, 1/s
        Eigenvalues (poles) of the coupled linear system.
    W, Winv : ndarray, shape (p, p), complex
        Right eigenvectors and their inverse.
    g : ndarray, shape (p,), complex
        Modal input of ``u`` (gain times DAQ voltage) [1/(V s)].
    hn : ndarray, shape (p, n_nl), complex
        Modal input of forces on the nonlinear DOFs.
    reduced : SecondOrderModel
        The structure's reduced model (``q = T z``).
    n_modes : int
        Structural generalised coordinates ``m``.
    A : ndarray, shape (p, p)
        The state matrix (for reference solutions).
    """

    lam: np.ndarray
    W: np.ndarray
    Winv: np.ndarray
    g: np.ndarray
    hn: np.ndarray
    reduced: SecondOrderModel
    n_modes: int
    A: np.ndarray
    b: np.ndarray
    Bn: np.ndarray
    stinger_stiffness: float

    @property
    def size(self) -> int:
        return self.lam.size

    # -- output rows in state coordinates (real), shape (r, p) plus feedthrough (r, n_nl)
    def displacement_rows(self, dofs: list[int]) -> np.ndarray:
        m = self.n_modes
        rows = np.zeros((len(dofs), self.size))
        rows[:, :m] = self.reduced.T[dofs]
        return rows

    def velocity_rows(self, dofs: list[int]) -> np.ndarray:
        m = self.n_modes
        rows = np.zeros((len(dofs), self.size))
        rows[:, m : 2 * m] = self.reduced.T[dofs]
        return rows

    def acceleration_rows(self, dofs: list[int]) -> tuple[np.ndarray, np.ndarray]:
        m = self.n_modes
        Td = self.reduced.T[dofs]
        return Td @ self.A[m : 2 * m], Td @ self.Bn[m : 2 * m]

    def force_row(self, drive_dof: int) -> np.ndarray:
        m = self.n_modes
        row = np.zeros(self.size)
        row[:m] = -self.stinger_stiffness * self.reduced.T[drive_dof]
        row[2 * m] = self.stinger_stiffness
        return row

    def current_row(self) -> np.ndarray:
        row = np.zeros(self.size)
        row[2 * self.n_modes + 2] = 1.0
        return row

    def modal(self, rows: np.ndarray) -> np.ndarray:
        """Output rows in modal coordinates: ``y = Re(rows @ W @ eta)``, shape (r, p)."""
        return np.asarray(rows) @ self.W

    def discretise(self, step_s: float) -> Discretised:
        """Exact update over ``step_s`` for inputs and forces linear over the step."""
        x = self.lam * step_s
        E = np.exp(x)
        small = np.abs(x) < 1e-4
        xs = np.where(small, 1.0, x)
        # phi0 = (e^x - 1)/x * h,  phi1 = (e^x - 1 - x)/x^2 * h  (series for small x)
        p0 = np.where(small, 1 + x / 2 + x**2 / 6, np.expm1(xs) / xs) * step_s
        p1 = np.where(small, 0.5 + x / 6 + x**2 / 24, (np.expm1(xs) - xs) / xs**2) * step_s
        return Discretised(
            step_s,
            E,
            self.g * (p0 - p1),
            self.g * p1,
            self.hn * (p0 - p1)[:, None],
            self.hn * p1[:, None],
        )

    def steady_phasors(self, omega: np.ndarray, u: np.ndarray, f_nl: np.ndarray) -> np.ndarray:
        """Modal state phasors of a periodic steady state.

        Parameters
        ----------
        omega : ndarray, shape (K,), rad/s
            Harmonic angular frequencies (index 0 may be 0 for the mean).
        u : ndarray, shape (K,), complex
            Phasors of ``u`` (gain times DAQ voltage, the hold factor applied).
        f_nl : ndarray, shape (K, n_nl), complex
            Force phasors on the nonlinear DOFs.

        Returns
        -------
        ndarray, shape (K, p), complex
            ``eta_k`` with ``eta(t) = Re-sum`` as in :meth:`state_at`.
        """
        rhs = u[:, None] * self.g[None, :] + f_nl @ self.hn.T
        return rhs / (1j * omega[:, None] - self.lam[None, :])

    def state_at(
        self, omega: np.ndarray, u: np.ndarray, f_nl: np.ndarray, t: np.ndarray
    ) -> np.ndarray:
        """Modal state of a steady state at times ``t`` [s] (shape (n_t, p)).

        The physical input is ``Re sum_k U_k exp(i w_k t)``; the complex modal state of a
        real signal is ``sum_k (eta_k e^{i w_k t} + eta'_k e^{-i w_k t}) / 2`` with ``eta'_k``
        the response to the conjugate phasor (the mean term counted once).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pos = self.steady_phasors(omega, u, f_nl)
        neg = self.steady_phasors(-omega, np.conj(u), np.conj(f_nl))
        ph = np.exp(1j * np.outer(t, omega))
        return 0.5 * (ph @ pos + np.conj(ph) @ neg)


def build_state_space(
    reduced: SecondOrderModel,
    drive_dof: int,
    nl_dofs: list[int],
    shaker: ShakerConstants,
    output_resistance_ohm: float,
    bandwidth_hz: float,
) -> ModalStateSpace:
    """Assemble and diagonalise the coupled rig of the module notes.

    Parameters
    ----------
    reduced : SecondOrderModel
        Structure in generalised coordinates (``M = I`` expected).
    drive_dof : int
        Structural DOF of the stinger.
    nl_dofs : list of int
        DOFs the nonlinear forces act on (their column order in ``hn``).
    shaker : ShakerConstants
    output_resistance_ohm : float
        Amplifier source resistance [ohm].
    bandwidth_hz : float
        Amplifier -3 dB corner [Hz].
    """
    m = reduced.size
    Minv = np.linalg.inv(reduced.M)
    T = reduced.T
    Td = T[drive_dof]
    s = shaker
    kst, Bl = s.stinger_stiffness_n_per_m, s.force_constant_n_per_a
    p = 2 * m + 4
    ia, iv, ii, iu = 2 * m, 2 * m + 1, 2 * m + 2, 2 * m + 3
    A = np.zeros((p, p))
    A[:m, m : 2 * m] = np.eye(m)
    A[m : 2 * m, :m] = -Minv @ (reduced.K + kst * np.outer(Td, Td))
    A[m : 2 * m, m : 2 * m] = -Minv @ reduced.C
    A[m : 2 * m, ia] = Minv @ Td * kst
    A[ia, iv] = 1.0
    ma = s.armature_mass_kg
    A[iv, :m] = kst * Td / ma
    A[iv, ia] = -(s.suspension_stiffness_n_per_m + kst) / ma
    A[iv, iv] = -s.suspension_damping_ns_per_m / ma
    A[iv, ii] = Bl / ma
    L = s.coil_inductance_h
    A[ii, iu] = 1.0 / L
    A[ii, ii] = -(s.coil_resistance_ohm + output_resistance_ohm) / L
    A[ii, iv] = -Bl / L
    wc = 2 * np.pi * bandwidth_hz
    A[iu, iu] = -wc
    b = np.zeros(p)
    b[iu] = wc
    Bn = np.zeros((p, len(nl_dofs)))
    Bn[m : 2 * m] = Minv @ T[nl_dofs].T
    lam, W = sla.eig(A)
    order = np.argsort(np.abs(lam))
    lam, W = lam[order], W[:, order]
    Winv = np.linalg.inv(W)
    return ModalStateSpace(
        lam=lam,
        W=W,
        Winv=Winv,
        g=Winv @ b,
        hn=Winv @ Bn,
        reduced=reduced,
        n_modes=m,
        A=A,
        b=b,
        Bn=Bn,
        stinger_stiffness=kst,
    )
