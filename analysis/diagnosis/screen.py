"""Harmonic-domain screen of candidate laws: force estimate, states from the data, BIC.

With the calibrated linear structure (receptances ``R``) and every nonlinear force acting at a
set of locations ``L`` (the model's own elements ``K`` and the candidate's ``b``), the measured
response harmonics at the sensors ``C`` are exactly

    Y_h = R_Cd(h W) F_h + R_CL(h W) g_h .

Per step and measured order the forces ``g`` are estimated by weighted least squares, and
from them the displacement at every location, ``U_h = R_.d F_h + R_.L g_h`` (no model of the
nonlinearity needed). The mean and the higher harmonics, which accelerometers do not give,
follow from the laws themselves (statics for the mean, ``U_h = R_.L(h W) f_L,h(U)``), iterated.
A law is then fitted in the response domain, its parameters entering linearly (a clearance is
refined continuously), the model's own elements refitted at the same states.

Evaluating a stiff law at states read from noisy data amplifies the noise through the loop
gain ``R J`` of the structure and the law (``J`` the law's harmonic Jacobian), and a state read
from the same data a law is fitted to would fit the noise. Both are undone by whitening each
step's residual with ``(I - M)^-1``, ``M = W R J R_UL A^+ W^-1`` the derivative of the residual
with respect to the data through the states: the screen's residual is then, to first order,
the output-error residual of the model with the law at the measured states, and a law at a
location the data cannot see explains nothing. The known element's clearance is profiled per
location and then linearised. A candidate's clearance is searched with its force sampled at
the AFT points (fast), then fitted with the jump of a contact's damping integrated exactly.

Every recorded order is used, an order the test holds at zero force included: the response
there is the nonlinear forces' alone. The screen proposes laws and their parameter values;
at unmeasured DOFs (the mounts, a joint) its ranking is coarse, and the verification in the
full model decides (:mod:`analysis.diagnosis.diagnose`).

Each fit is scored by BIC (and AICc) on the file's uncertainties; ranks and ties follow.

References
----------
G. Kerschen, K. Worden, A. F. Vakakis, J.-C. Golinval, "Past, present and future of nonlinear
system identification in structural dynamics", MSSP 20 (2006) 505-592 (restoring-force and
force-estimate methods). N. M. Mangan, J. N. Kutz, S. L. Brunton, J. L. Proctor, "Model
selection for dynamical systems via sparse regression and information criteria",
Proc. R. Soc. A 473 (2017) 20170009.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear, minimize_scalar

from analysis.diagnosis.candidates import (
    Candidate,
    Law,
    Location,
    default_locations,
    release_joint,
)
from analysis.elements import make_element
from analysis.events import Listener, UnitDone
from analysis.measurement_file import SteppedSineData
from analysis.mhb.aft import element_forces_batch
from analysis.mhb.harmonics import HarmonicBasis
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor
from analysis.system import attachments

__all__ = [
    "JOINT_ANCHOR",
    "Screen",
    "ScreenFit",
    "ScreenJob",
    "information_criteria",
    "refine_pass",
    "screen_pass",
]

log = logging.getLogger(__name__)

#: Stiffness [N m/rad or N/m] a released joint gets in the screen's linear model; the fitted
#: spring change of every joint law is added to it.
JOINT_ANCHOR = 1e5
_POSITIVE = ("k", "k_c", "k_t")
#: Friction laws are screened with their switch smoothed over this share of each step's
#: largest velocity at the location.
SMOOTH_FRICTION = 0.05
#: Fixed-point passes of the unmeasured harmonics under the model's own elements at the
#: measured states, before the first fit.
INITIAL_PASSES = 8


def _option_names(kind: str) -> dict:
    import analysis.elements as lib

    return lib.ELEMENT_TYPES[kind].option_names


def information_criteria(rss: float, n: int, k: int) -> tuple[float, float]:
    """``BIC = n ln(rss/n) + k ln n`` and ``AICc = n ln(rss/n) + 2k + 2k(k+1)/(n-k-1)``."""
    base = n * math.log(max(rss, 1e-300) / n)
    return base + k * math.log(n), base + 2 * k + 2 * k * (k + 1) / max(n - k - 1, 1)


@dataclass
class ScreenFit:
    """Fit of one candidate by the screen.

    Attributes
    ----------
    candidate : Candidate
    rss : float
        Whitened residual sum of squares (a chi-square) over ``n`` real residuals.
    n, k : int
        Residuals and fitted parameters (the model's own element parameters included).
    bic, aicc : float
    values : dict
        Law parameters (and ``k_joint`` of a released joint) in model units.
    known : dict
        The model's own element parameters refitted at the same states.
    refined : bool
        Already through :meth:`Screen.refined` (refining it again gives the same fit).
    """

    candidate: Candidate
    rss: float
    n: int
    k: int
    bic: float
    aicc: float
    values: dict[str, float] = field(default_factory=dict)
    known: dict[str, float] = field(default_factory=dict)
    refined: bool = False

    @property
    def chi2_per_dof(self) -> float:
        return self.rss / max(self.n - self.k, 1)


# -- real harmonic algebra on the measured orders --------------------------------------------
def _realify(Z: np.ndarray) -> np.ndarray:
    """Real operator of complex per-order matrices ``Z`` (n, K, r, c) on coefficients ordered
    (order, cos/sin, signal): shape (n, 2K r, 2K c)."""
    n, K, r, c = Z.shape
    out = np.zeros((n, K, 2, r, K, 2, c))
    for k in range(K):
        out[:, k, 0, :, k, 0, :] = Z[:, k].real
        out[:, k, 0, :, k, 1, :] = Z[:, k].imag
        out[:, k, 1, :, k, 0, :] = -Z[:, k].imag
        out[:, k, 1, :, k, 1, :] = Z[:, k].real
    return out.reshape(n, 2 * K * r, 2 * K * c)


def _vec(X: np.ndarray) -> np.ndarray:
    """Coefficients (n, 2K m) of phasors (n, K, m) in the order of :func:`_realify`."""
    return np.stack([X.real, -X.imag], axis=2).reshape(X.shape[0], -1)


class _Basis:
    """Samples of harmonics 0..H over one base period and the projections back."""

    def __init__(self, H: int, n_time: int, order_k: np.ndarray) -> None:
        tau = 2 * np.pi * np.arange(n_time) / n_time
        h = np.arange(H + 1)
        self.H, self.n_time = H, n_time
        self.E = np.exp(1j * np.outer(tau, h))  # x(t) = Re(E @ X)
        w = np.full(H + 1, 2.0 / n_time)
        w[0] = 1.0 / n_time
        self.P = np.exp(-1j * np.outer(h, tau)) * w[:, None]  # X = P @ x
        self.order_k = order_k
        self.other = np.setdiff1d(h, order_k)  # harmonics the file does not measure
        # real coefficient rows/columns of the measured orders
        cols = []
        for k in order_k:
            cols.append(np.cos(k * tau))
            cols.append(np.sin(k * tau))
        self.Eo = np.array(cols).T  # u(t) = Eo @ [a1, b1, a2, b2, ...]
        self.dEo = np.array(
            [c for k in order_k for c in (-k * np.sin(k * tau), k * np.cos(k * tau))]
        ).T
        self.Po = np.linalg.pinv(self.Eo)  # projection of samples on the order coefficients
        # real arithmetic in one product over every step and signal: the samples are real,
        # and a complex product per step, of which only the real part is kept, costs a
        # multiple of it
        D = self.E * (1j * h)  # d/dtau of the samples
        self._ED = np.hstack([np.vstack([M.real, -M.imag]) for M in (self.E.T, D.T)])
        self._P = np.hstack([self.P.real.T, self.P.imag.T])  # (T, 2H+2)

    def time(self, X: np.ndarray, omega: np.ndarray):
        """Displacement and velocity samples (n, T, m) of phasors X (n, H+1, m) at the steps'
        base frequencies ``omega`` (n,)."""
        n, _, m = X.shape
        parts = np.concatenate([X.real, X.imag], axis=1).transpose(0, 2, 1).reshape(n * m, -1)
        uv = (parts @ self._ED).reshape(n, m, 2, self.n_time).transpose(2, 0, 3, 1)
        return uv[0], uv[1] * omega[:, None, None]

    def phasors(self, x: np.ndarray) -> np.ndarray:
        """Phasors (n, H+1, m) of samples (n, T, m)."""
        if np.iscomplexobj(x):
            return self.P @ x
        n, _, m = x.shape
        c = (x.transpose(0, 2, 1).reshape(n * m, -1) @ self._P).reshape(n, m, 2, self.H + 1)
        return (c[:, :, 0] + 1j * c[:, :, 1]).transpose(0, 2, 1)


@dataclass
class _Frame:
    """A linear model's receptances on the measured steps."""

    model: Model
    dofs: list[int]  # D (positions: sensors first)
    R: np.ndarray  # (n, H+1, nD, nD + 1) complex: from [drive, D...] to D
    known: list  # (element, pos_a, pos_b, {model p: element p})
    X0: np.ndarray  # (n, H+1, nD) start phasors (the anchor's)
    omega: np.ndarray
    R_o: np.ndarray  # (n, K, nD, 1 + nD): R at the measured orders (every candidate's fit)


@dataclass
class _States:
    """The measured-order states of one force estimate (:meth:`Screen.states`) and what every
    fit at its location shares, computed once: the whitening at the data's states (``S0``),
    the start phasors (``X_init``), each incidence's state map (``maps``) and the model
    elements' forces at the data's states (``known``, by element).

    ``g`` are the estimated forces themselves, columns in the order of the estimate: one per
    model element, then one per incidence of the location, or, for a group larger than the
    sensors resolve, one generalized force (``grouped``); ``Pg`` their derivative with respect
    to the weighted data, from which their standard errors follow
    (:mod:`analysis.diagnosis.readout` reads the missing force from them)."""

    U: np.ndarray  # (n, K, nD) states at the measured orders
    P: np.ndarray  # (n, K, nD, C) d U / d (weighted data)
    W: np.ndarray  # (n, K, C) weights
    Y: np.ndarray  # (n, K, C) the data
    grouped: bool
    g: np.ndarray | None = None  # (n, K, nL) forces on the structure [N, or N m]
    Pg: np.ndarray | None = None  # (n, K, nL, C) d g / d (weighted data)
    S0: np.ndarray | None = None
    first: tuple | None = None  # the model's elements' part of the first system
    first_qr: _Projected | None = None  # its columns factorised, made with it
    X_init: np.ndarray | None = None
    maps: dict = field(default_factory=dict)
    known: dict = field(default_factory=dict)


class Screen:
    """The screen of candidates against one file, at a calibrated model.

    Parameters
    ----------
    model : Model
        The calibrated model (without sensor masses: the file's are added).
    data : SteppedSineData
    n_iterations : int
        Alternations of the whitening and the unmeasured harmonics with the fitted law.
    rcond : float
        Relative singular-value cut of the force estimate.
    n_time : int
        Samples per base period of the law evaluations.
    predictor : BranchMatchedPredictor, optional
    free_parameters : sequence of str
        Linear model parameters refitted (to first order, through the receptances'
        derivatives) with every candidate.
    """

    def __init__(
        self,
        model: Model,
        data: SteppedSineData,
        *,
        n_iterations: int = 3,
        rcond: float = 1e-8,
        n_time: int = 128,
        predictor: BranchMatchedPredictor | None = None,
        free_parameters: Sequence[str] = (),
        locations: Sequence[Location] = (),
    ) -> None:
        # the receptances cover the measured scope's places and these (the candidates' own
        # when they lie beyond it: another direction, one spring, a pair of nodes)
        self.locations = tuple(locations)
        self.model, self.data = model, data
        self.n_iterations, self.rcond, self.n_time = n_iterations, rcond, n_time
        self.free = tuple(free_parameters)
        self._sampled = False
        self._refined: dict[str, ScreenFit] = {}  # by candidate label
        self.predictor = p = predictor or BranchMatchedPredictor(model, data)
        self.n_channels = C = len(p.channel_indices)
        d = data
        # every recorded order (an order held at zero force still shows the response to the
        # nonlinear forces), as displacement phasors of the sensors
        orders = np.array([float(o) for o in p.orders])
        wk = 2 * np.pi * d.frequency_hz[:, None] * orders[None, :]
        sign = np.array(p._out_sign)[None, :, None]
        power = np.array(p._power)[None, :, None]
        conv = sign / (1j * wk[:, None, :]) ** power
        idx = p.channel_indices
        R, sR = d.response[:, idx, :], d.response_std[:, idx, :]
        F, sF = d.force[:, None, :], d.force_std[:, None, :]
        excited = np.zeros(orders.size, bool)
        excited[p.compared] = True
        with np.errstate(divide="ignore", invalid="ignore"):
            # the force's error enters through the response it drives (excited orders)
            sig = np.sqrt(sR**2 + np.where(excited, np.abs(R) * sF / np.abs(F), 0.0) ** 2)
        positive = sig[np.isfinite(sig) & (sig > 0)]
        sig = np.maximum(np.nan_to_num(sig, nan=positive.max()), positive.min())
        self._Y = (R * conv).transpose(0, 2, 1)  # (n, K, C)
        self._sigma = (sig * np.abs(conv)).transpose(0, 2, 1)
        self._F = p._force_sign * d.force  # (n, K) on the drive DOF
        self._frames: dict = {}
        self._states: dict = {}
        self._base_points = None
        self._syn: Screen | None = None
        self.rows: np.ndarray | None = None
        del C

    # -- linear frames ------------------------------------------------------------------------
    @staticmethod
    def _dof(asm, ref) -> int:
        if ref.node is not None and ref.direction is not None:
            return asm.dof_index(ref.node, ref.direction)
        return asm.point_dof(ref.point, ref.direction)

    def _anchor_points(self):
        """The calibrated model's solution on the measured branch, at every DOF of interest."""
        if self._base_points is None:
            p = self.predictor
            asm = p.model.assemble()
            extra = self._interesting(p.model, asm)
            pb, points = p.solve(p.model, extra_dofs=[x for x in extra if x not in p._out_dofs])
            self._base_points = (pb, points)
            rows = np.array(sorted(r for r, q in points.items() if q.converged), dtype=int)
            self.rows = rows
            H = pb.n_harmonics
            # the file's orders (a file's extra force orders drive the anchor solution only)
            K = len(self.predictor.orders)
            self._basis = _Basis(H, self.n_time, np.asarray(pb.order_k)[:K])
            self._harmonic_basis = HarmonicBasis(H, self.n_time)
        return self._base_points

    def _interesting(self, model, asm, joint=None) -> list[int]:
        atts = attachments(model)
        extra = [a.dof_a for a in atts] + [a.dof_b for a in atts if a.dof_b is not None]
        for loc in (*default_locations(model), *self.locations):
            if loc.joint is None:
                extra += [self._dof(asm, r) for inc in loc.incidences for r in inc if r]
        if joint is not None:
            nodes = next(j.nodes for j in model.frame.joints if j.name == joint[0])
            extra += [asm.dof_index(nd, joint[1]) for nd in nodes]
        return list(dict.fromkeys(extra))

    def frame(self, joint: tuple[str, str] | None = None) -> _Frame:
        """Receptances of the model (``joint=None``) or of the model with a joint direction
        released into a spring of :data:`JOINT_ANCHOR`; cached."""
        if joint in self._frames:
            return self._frames[joint]
        pb, points = self._anchor_points()
        p = self.predictor
        if joint is None:
            model = p.model
        else:
            name = f"k_{joint[0]}_{joint[1]}"
            bare = release_joint(self.model, joint, name, JOINT_ANCHOR, "screen")
            model = BranchMatchedPredictor(bare, self.data).model
        asm = model.assemble()
        dofs = list(p._out_dofs) + [
            x for x in self._interesting(model, asm, joint) if x not in p._out_dofs
        ]
        lin = p._linear_model(model) if joint is None else _linear(model)
        drive = asm.point_dof(self.data.actuator.point, self.data.actuator.direction.lstrip("-"))
        H = pb.n_harmonics
        rows = self.rows
        omega = 2 * np.pi * self.data.frequency_hz[rows] / pb.denominator
        hw = (omega[:, None] * np.arange(H + 1)[None, :]).ravel()
        R = lin.block(dofs, [drive, *dofs])(hw).reshape(rows.size, H + 1, len(dofs), len(dofs) + 1)
        R[:, 0] = R[:, 0].real
        # start phasors: the anchor's at DOFs the base model has (by node and direction)
        base_asm = p.model.assemble()
        base_out = list(pb.output_dofs)
        X0 = np.zeros((rows.size, H + 1, len(dofs)), complex)
        for j, dd in enumerate(dofs):
            label = asm.dofs[dd]
            try:
                bd = base_asm.dof_index(*label)
            except KeyError:
                continue
            if bd in base_out:
                col = base_out.index(bd)
                X0[:, :, j] = np.array([points[r].q_out[:, col] for r in rows])
        pos = {dd: j for j, dd in enumerate(dofs)}
        known = [
            (a.element, pos[a.dof_a], None if a.dof_b is None else pos[a.dof_b], dict(a.param_map))
            for a in attachments(model)
        ]
        fr = _Frame(model, dofs, R, known, X0, omega, R[:, self._basis.order_k])
        self._frames[joint] = fr
        return fr

    # -- states ------------------------------------------------------------------------------
    def _incidence(self, fr: _Frame, loc: Location) -> np.ndarray:
        asm = fr.model.assemble()
        pos = {dd: j for j, dd in enumerate(fr.dofs)}
        B = np.zeros((len(loc.incidences), len(fr.dofs)))
        for i, (at, to) in enumerate(loc.incidences):
            B[i, pos[self._dof(asm, at)]] += 1.0
            if to is not None:
                B[i, pos[self._dof(asm, to)]] -= 1.0
        return B

    def _known_incidence(self, fr: _Frame) -> np.ndarray:
        nD = len(fr.dofs)
        rows = []
        for _, a, b, _ in fr.known:
            r = np.zeros(nD)
            r[a] = 1.0
            if b is not None:
                r[b] = -1.0
            rows.append(r)
        return np.array(rows).reshape(-1, nD)

    def states(self, fr: _Frame, B_loc: np.ndarray | None, key) -> _States:
        """Force estimate and measured-order states with forces at the model's elements and
        at the incidences ``B_loc`` (a group larger than the sensors can resolve acts as one
        force distributed like the anchor's displacements there)."""
        if key in self._states:
            return self._states[key]
        C = self.n_channels
        bs = self._basis
        K = bs.order_k.size
        BK = self._known_incidence(fr)
        n = self.rows.size
        Y = self._Y[self.rows]
        W = 1.0 / self._sigma[self.rows]  # (n, K, C) complex-magnitude weights
        Bs = [BK] if BK.size else []
        if B_loc is not None:
            if B_loc.shape[0] + BK.shape[0] < C:
                Bs.append(B_loc)
        Lam = np.vstack(Bs) if Bs else np.zeros((0, len(fr.dofs)))
        grouped = B_loc is not None and B_loc.shape[0] + BK.shape[0] >= C
        out_U = np.empty((n, K, len(fr.dofs)), complex)
        ghat = []
        Pg = []  # d g / d (weighted data)
        P_rows = []  # d U(orders, all D) / d (weighted data), real per step
        for kk, h in enumerate(bs.order_k):
            R = fr.R[:, h]  # (n, nD, 1 + nD)
            Rd = R[:, :, 0]
            RL = R[:, :, 1:] @ Lam.T
            if grouped:
                shape = np.einsum("nj,lj->nl", fr.X0[:, h], B_loc)
                shape /= np.maximum(np.linalg.norm(shape, axis=1, keepdims=True), 1e-300)
                g_dir = np.einsum("nl,lj->nj", shape, B_loc)  # generalized force on D
                RL = np.concatenate(
                    [RL, np.einsum("nij,nj->ni", R[:, :, 1:], g_dir)[:, :, None]], axis=2
                )
            A = RL[:, :C, :]  # (n, C, nL)
            y = Y[:, kk] - Rd[:, :C] * self._F[self.rows, kk][:, None]
            Aw = A * W[:, kk, :, None]
            pinv = np.linalg.pinv(Aw, rcond=self.rcond)  # (n, nL, C)
            g = (pinv @ (y * W[:, kk])[:, :, None])[:, :, 0]
            ghat.append(g)
            Pg.append(pinv)
            out_U[:, kk] = Rd * self._F[self.rows, kk][:, None] + (RL @ g[:, :, None])[:, :, 0]
            P_rows.append(RL @ pinv)  # complex (n, nD, C)
        st = _States(
            out_U,
            np.stack(P_rows, axis=1),
            W,
            Y,
            grouped,
            g=np.stack(ghat, axis=1),
            Pg=np.stack(Pg, axis=1),
        )
        self._states[key] = st
        return st

    def _param_derivative(self, fr: _Frame, name: str) -> np.ndarray:
        key = ("dR", id(fr), name)
        if key not in self._states:
            lin = self.predictor._linear_model(fr.model)
            asm = fr.model.assemble()
            act = self.data.actuator
            drive = asm.point_dof(act.point, act.direction.lstrip("-"))
            bs = self._basis
            C = self.n_channels
            w = (fr.omega[:, None] * bs.order_k[None, :]).ravel()
            blk = lin.block(fr.dofs[:C], [drive, *fr.dofs])
            d = blk.derivative(w, name).reshape(self.rows.size, bs.order_k.size, C, -1)
            self._states[key] = d
        return self._states[key]

    # -- public ---------------------------------------------------------------------------------
    def fit(
        self, cand: Candidate, n_iterations: int | None = None, nonlinear: dict | None = None
    ) -> ScreenFit:
        """Fit one candidate (see the module notes).

        Parameters
        ----------
        cand : Candidate
        n_iterations : int, optional
            Alternations (default: the screen's); 0 is one pass at the data's states.
        nonlinear : dict, optional
            Fixed values of the law's nonlinear parameters (default: refined continuously).
        """
        its = self.n_iterations if n_iterations is None else n_iterations
        self._anchor_points()
        loc, law = cand.location, cand.law
        fr = self.frame(loc.joint)
        n_known = sum(len(pm) for *_, pm in fr.known)
        if law.kind == "parameter":
            st = self.states(fr, None, (id(fr), None))
            rss, n, theta, known = self._fit(fr, st, None, None, {}, cand.parameter, its)
            value = self.model.parameters[cand.parameter].value + theta[cand.parameter]
            k = 1 + n_known
            bic, aicc = information_criteria(rss, n, k)
            return ScreenFit(cand, rss, n, k, bic, aicc, {cand.parameter: value}, known)
        B = self._incidence(fr, loc)
        k = cand.n_params + n_known
        return self._fit_at(fr, cand, B, self.states(fr, B, (id(fr), loc)), its, nonlinear, k)

    def _fit_at(self, fr, cand, B, st, its, nonlinear, k) -> ScreenFit:
        loc, law = cand.location, cand.law
        # a location in the force estimate lets the states absorb part of the noise even with
        # no law there: scale by that share, measured on the model's own response plus noise
        syn = self._synthetic()
        absorbed = syn._null(fr, loc, B) / syn._null(fr, None, None)

        def run(nonlinear, exact=True):
            self._sampled = not exact
            try:
                return self._fit(fr, st, cand, B, nonlinear, None, its)
            finally:
                self._sampled = False

        def search(nonlinear) -> float:
            return run(nonlinear, exact=False)[0]

        if law.nonlinear and nonlinear:
            rss, n, theta, known = run(dict(nonlinear))
        elif law.nonlinear:
            # the clearance is searched with a jumping force sampled (fast), then fitted exactly
            name = law.nonlinear[0]
            Xi = np.einsum("nkj,lj->nkl", st.U, B)
            u = np.einsum("tk,nkl->ntl", self._basis.E[:, self._basis.order_k], Xi).real
            side = law.options.get("side")
            amp = float(np.abs(u).max() if side is None else max((side * u).max(), 1e-12))
            grid = amp * np.array([0.0, 0.2, 0.4, 0.6, 0.8])
            fits = [search({name: g}) for g in grid]
            i = int(np.argmin(fits))
            best_gap, best_rss = float(grid[i]), fits[i]
            lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
            if hi > lo:
                opt = minimize_scalar(
                    lambda g: search({name: g}),
                    bounds=(lo, hi),
                    method="bounded",
                    options={"xatol": 5e-3 * amp, "maxiter": 5},
                )
                if opt.fun < best_rss:
                    best_gap = float(opt.x)
            rss, n, theta, known = run({name: best_gap})
        else:
            rss, n, theta, known = run({})
        values = {p: theta[p] for p in (*law.linear, *law.nonlinear) if p in theta}
        if loc.joint is not None:
            values["k_joint"] = JOINT_ANCHOR + theta.get("k_joint_delta", 0.0)
        rss = rss / absorbed
        bic, aicc = information_criteria(rss, n, k)
        return ScreenFit(cand, rss, n, k, bic, aicc, values, known)

    def _synthetic(self) -> Screen:
        """This screen on synthetic data: the model's own response plus noise of the file's
        standard errors (seeded), sharing the linear frames."""
        if self._syn is None:
            self._anchor_points()
            syn = copy.copy(self)
            syn._states, syn._syn = {}, syn
            fr = self.frame(None)
            rng = np.random.default_rng(0)
            Y = self._Y.copy()
            C = self.n_channels
            model = fr.X0[:, self._basis.order_k, :C]
            noise = rng.standard_normal(model.shape) + 1j * rng.standard_normal(model.shape)
            Y[self.rows] = model + noise * self._sigma[self.rows] / np.sqrt(2)
            syn._Y = Y
            self._syn = syn
        return self._syn

    def _null(self, fr: _Frame, loc: Location | None, B) -> float:
        """Residual with forces estimated at the model's elements (and ``loc``) but no law
        at ``loc``; cached."""
        key = ("null", id(fr), loc)
        if key not in self._states:
            st = self.states(fr, B, (id(fr), loc))
            self._states[key] = self._fit(fr, st, None, None, {}, None, 0)[0]
        return self._states[key]

    def baseline(self) -> ScreenFit:
        """The model as it is, its own element parameters refitted at the measured states."""
        self._anchor_points()
        fr = self.frame(None)
        st = self.states(fr, None, (id(fr), None))
        rss, n, _, known = self._fit(fr, st, None, None, {})
        k = sum(len(pm) for *_, pm in fr.known)
        bic, aicc = information_criteria(rss, n, k)
        return ScreenFit(Candidate(Location("none"), Law("none")), rss, n, k, bic, aicc, {}, known)

    def run(
        self,
        candidates: Sequence[Candidate],
        n_refine: int = 12,
        progress: Listener | None = None,
        executor=None,
    ) -> list[ScreenFit]:
        """Fit every candidate in one pass at the data's states, then the best ``n_refine``
        with the alternations (keeping the better of the two fits); sorted by BIC.

        With an ``executor`` the first pass is shared between this process and one job on
        the executor (:func:`screen_pass`).
        """
        cands = list(candidates)
        later = None
        if executor is not None and len(cands) > 8:
            job = ScreenJob(
                self.model.to_toml(),
                str(self.model.source),
                str(self.data.path),
                tuple(cands[1::2]),
                self.predictor.settings["n_harmonics"],
                self.predictor.settings["n_time"],
                self.free,
                self.locations,
            )
            later = executor.submit(screen_pass, job)
            cands = cands[0::2]
        fits = self.first_pass(cands, progress)
        if later is not None:
            fits += later.result()
        return self.refine(fits, n_refine, progress)

    def first_pass(
        self, candidates: Sequence[Candidate], progress: Listener | None = None
    ) -> list[ScreenFit]:
        """One pass of every candidate at the data's states, best first."""
        fits = []
        for i, c in enumerate(candidates):
            try:
                fits.append(self.fit(c, n_iterations=0))
            except (ValueError, np.linalg.LinAlgError) as exc:
                log.warning("screen of %s failed: %s", c.label, exc)
            if progress:
                progress(UnitDone("screen", i + 1, len(candidates), c.label))
        return sorted(fits, key=lambda f: f.bic)

    def refine(
        self, fits: list[ScreenFit], n_refine: int, progress: Listener | None = None
    ) -> list[ScreenFit]:
        """The best ``n_refine`` fits again with the alternations (the better of the two
        kept); every fit sorted by BIC."""
        fits = sorted(fits, key=lambda f: f.bic)
        for i, f in enumerate(fits[:n_refine]):
            fits[i] = self.refined(f)
            if progress:
                progress(UnitDone("refine", i + 1, n_refine, f.candidate.label))
        return sorted(fits, key=lambda f: f.bic)

    def take_refined(self, fits: Sequence[ScreenFit]) -> None:
        """Keep refinements made by another process's screen of the same model and file
        (:func:`refine_pass`): :meth:`refined` returns them."""
        for f in fits:
            self._refined[f.candidate.label] = f

    def refined(self, f: ScreenFit) -> ScreenFit:
        """``f`` with the alternations at its clearance, or ``f`` if that is no better."""
        if f.refined:
            return f
        if f.candidate.label in self._refined:
            return self._refined[f.candidate.label]
        fixed = {p: f.values[p] for p in f.candidate.law.nonlinear if p in f.values}
        try:
            g = self.fit(f.candidate, nonlinear=fixed)
        except (ValueError, np.linalg.LinAlgError) as exc:
            log.warning("screen of %s failed: %s", f.candidate.label, exc)
            return f
        out = self._refined[f.candidate.label] = dataclasses.replace(
            g if g.bic < f.bic else f, refined=True
        )
        return out

    # -- one fit ------------------------------------------------------------------------------
    def _parts(self, fr: _Frame, cand: Candidate | None, B_loc, values: dict):
        """Force laws at the current values: (element or law, incidence rows (m, nD),
        {name: model parameter} of linear parameters, linear names)."""
        parts = []
        for element, a, b, pmap in fr.known:
            row = np.zeros((1, len(fr.dofs)))
            row[0, a] = 1.0
            if b is not None:
                row[0, b] = -1.0
            parts.append(("known", element, row, pmap))
        if cand is not None and cand.law.kind not in ("none",):
            parts.append(("cand", cand.law, B_loc, values))
        return parts

    def _law_eval(self, fr, law_or_element, X_inc, theta, want_basis, want_jac=True):
        """Forces (n, H+1, m) at incidence phasors X_inc, their order Jacobian (n, m, 2K, 2K)
        and, with ``want_basis``, the force of each linear parameter at unit value."""
        bs = self._basis
        u, v = bs.time(X_inc, fr.omega)
        n, T, m = u.shape
        v_scale = None
        if isinstance(law_or_element, Law):
            law = law_or_element
            if law.kind in ("mass", "linear_spring", "joint_spring"):
                return self._linear_law(fr, law, X_inc, theta, want_basis)
            kw = {}
            for p in law.linear:
                val = float(theta.get(p, 0.0))
                kw[p] = max(val, 1e-30) if p in _POSITIVE else val
            kw.update({p: float(theta[p]) for p in law.nonlinear})
            options = dict(law.options)
            if "v_reg" in _option_names(law.kind):
                # a friction law's sign switch, sampled, misplaces the switch and spikes the
                # Jacobian: screen it with the switch smoothed over a share of each velocity
                vmax = np.abs(v).max(axis=1, keepdims=True)
                options["v_reg"] = 1.0
                v_scale = 1.0 / np.maximum(SMOOTH_FRICTION * vmax, 1e-12)
                v = v * v_scale
            element = make_element(law.kind, **kw, **options)
            linear = law.linear
        else:
            el = law_or_element
            th = {p: (max(v, 1e-30) if p in el.positive_params else v) for p, v in theta.items()}
            element = el.with_params(**th) if th else el
            linear = element.param_names
        sampled = self._sampled and isinstance(law_or_element, Law)  # the candidate only
        if element.switch_threshold() is not None and not sampled:
            return self._exact_aft(fr, element, X_inc, linear if want_basis else None)
        ev = element.evaluate(u, v, want_basis)
        f = bs.phasors(ev.f)
        basis = None
        if want_basis:
            names = element.param_names
            basis = {p: bs.phasors(ev.df_dp[names.index(p)]) for p in linear}
        if not want_jac:
            return f, None, basis
        dfdv = ev.df_dv * (v_scale if v_scale is not None else 1.0)
        du = np.moveaxis(ev.df_du, 1, 2)[:, :, None, :]  # (n, m, 1, T)
        dv = np.moveaxis(dfdv * fr.omega[:, None, None], 1, 2)[:, :, None, :]
        Jm = (bs.Po * du) @ bs.Eo + (bs.Po * dv) @ bs.dEo  # (n, m, 2K, 2K)
        return f, Jm, basis

    def _exact_aft(self, fr, element, X_inc, linear):
        """:func:`_law_eval` for a law whose force jumps: the balance's own AFT, which
        integrates each jump exactly (sampling it would misplace it by half a sample, and
        miss the jump's share of the derivative with respect to the clearance)."""
        hb = self._harmonic_basis
        bs = self._basis
        n, H1, m = X_inc.shape
        K = bs.order_k.size
        f = np.zeros((n, H1, m), complex)
        Jm = np.zeros((n, m, 2 * K, 2 * K))
        names = element.param_names
        basis = None if linear is None else {p: np.zeros((n, H1, m), complex) for p in linear}
        idx = np.array([c for k in bs.order_k for c in (2 * k - 1, 2 * k)])
        # where the sampled law exerts no force and no sample comes near the switch, the
        # exact evaluation is zero too: only the other steps are integrated exactly
        u, v = bs.time(X_inc, fr.omega)
        ev = element.evaluate(u, v)
        u_s = element.switch_threshold()[0]
        span = np.ptp(u, axis=1) + 1e-300
        idle = np.all(ev.f == 0, axis=1) & (np.abs(u - u_s).min(axis=1) > 0.05 * span)
        for j in range(m):
            act = np.flatnonzero(~idle[:, j])
            if not act.size:
                continue
            Ue = hb.from_complex(X_inc[act, :, j].T).T  # (steps, 2H+1)
            F, D, dFp = element_forces_batch(
                hb, element, Ue, fr.omega[act], True, linear is not None
            )
            f[act, :, j] = hb.to_complex(F.T).T
            Jm[act, j] = D[:, idx][:, :, idx]
            if linear is not None:
                for p in linear:
                    basis[p][act, :, j] = hb.to_complex(dFp[:, :, names.index(p)].T).T
        return f, Jm, basis

    def _linear_law(self, fr, law, X, theta, want_basis):
        bs = self._basis
        n, H1, m = X.shape
        h = np.arange(H1)
        if law.kind == "mass":
            gain = (h[None, :] * fr.omega[:, None]) ** 2  # f = m (h w)^2 U
            name = "m"
        else:
            gain = -np.ones((n, H1))  # f = -k U
            name = "k"
        f = theta.get(name, 0.0) * gain[:, :, None] * X
        K = bs.order_k.size
        Jm = np.zeros((n, m, 2 * K, 2 * K))
        for kk, hk in enumerate(bs.order_k):
            Jm[:, :, 2 * kk, 2 * kk] = Jm[:, :, 2 * kk + 1, 2 * kk + 1] = (
                theta.get(name, 0.0) * gain[:, hk, None]
            )
        basis = {name: gain[:, :, None] * X} if want_basis else None
        return f, Jm, basis

    def _initial_states(self, fr: _Frame, st: _States) -> np.ndarray:
        """Phasors at D: the measured orders from the data, the mean and higher harmonics
        from the model's own elements at those states (fixed point; the anchor's solution may
        sit on another branch than the test)."""
        bs = self._basis
        if st.X_init is None and st is not self.states(fr, None, (id(fr), None)):
            # the unmeasured harmonics follow the model's elements, whose states the sensors
            # give whatever the location: take them from the model's own force estimate
            X = self._initial_states(fr, self.states(fr, None, (id(fr), None)))
            X[:, bs.order_k] = st.U
            st.X_init = X
        if st.X_init is None:
            X = fr.X0.copy()
            X[:, bs.order_k] = st.U
            other = bs.other
            fine = _Basis(bs.H, 1024, bs.order_k)
            for _ in range(INITIAL_PASSES):
                g = np.zeros_like(X)
                for element, a, b, _ in fr.known:
                    row = np.zeros(len(fr.dofs))
                    row[a] = 1.0
                    if b is not None:
                        row[b] = -1.0
                    Xi = np.einsum("nhd,d->nh", X, row)[:, :, None]
                    u, v = fine.time(Xi, fr.omega)  # finely sampled: no per-step loop
                    g += fine.phasors(element.evaluate(u, v).f) * row[None, None, :]
                X[:, other] = np.einsum("nhij,nhj->nhi", fr.R[:, other, :, 1:], g[:, other])
            st.X_init = X
        return st.X_init.copy()

    def _fit(self, fr, st, cand, B_loc, nonlinear: dict, param=None, n_iterations=None):
        """Alternate: whitening and unmeasured harmonics at the current values, then the
        linear least squares of every linear parameter. Returns (rss, n, values, known)."""
        params = tuple(dict.fromkeys(([param] if param else []) + list(self.free)))
        C, K = self.n_channels, self._basis.order_k.size
        n = self.rows.size
        X = self._initial_states(fr, st)
        law = None if cand is None or cand.law.kind == "none" else cand.law
        joint = cand is not None and cand.location.joint is not None
        theta = dict(nonlinear)
        if law is not None:
            theta.update({p: 0.0 for p in law.linear})
        if joint:
            theta["k_joint_delta"] = 0.0
        known = {mp: el.params[ep] for el, _, _, pmap in fr.known for mp, ep in pmap.items()}
        drive = fr.R_o[:, :, :C, 0] * self._F[self.rows][:, :, None]
        incid = _incidences(fr, law, joint, B_loc)
        rss = np.inf
        its = self.n_iterations if n_iterations is None else n_iterations
        for it in range(its + 1):
            if it == 0 and st.S0 is not None and not params:
                # at the data's states the candidate's coefficients start at zero, so its
                # force and Jacobian vanish and the whitening is the model's own elements':
                # computed once per location, shared by every law there
                lin, Am, y0 = self._first_system(fr, st, X, incid, law, joint, theta, known, drive)
                x, rss = self._first_lsq(st, Am, y0 + Am @ _current(lin.names, known, theta), lin)
            else:
                lin, Am, y0 = self._iteration(
                    fr, st, X, incid, law, joint, theta, known, drive, it, params
                )
                x, rss = _bounded_lsq(Am, y0 + Am @ _current(lin.names, known, theta), lin.lower)
            _take_values(lin.names, x, known, theta)
        return rss, 2 * K * C * n, theta, known

    def _iteration(self, fr, st, X, incid, law, joint: bool, theta, known, drive, it: int, params):
        """One alternation at the current values: the laws' forces, the unmeasured harmonics
        (updated in ``X``) and the whitening at them. Returns ``(forces, matrix, right-hand
        side)`` of the least squares."""
        bs = self._basis
        C, K = self.n_channels, bs.order_k.size
        n = self.rows.size
        whitened = it == 0 and st.S0 is not None
        lin = _Forces(
            np.zeros((n, bs.H + 1, len(fr.dofs)), complex),
            None if whitened else np.zeros((n, 2 * K * C, 2 * K * C)),
        )
        for i, (kind_, law_i, rows, pmap) in enumerate(incid):
            Xi = X @ rows.T
            if kind_ == "known":
                f, Jm = self._known_force(fr, st, i, law_i, Xi, rows, pmap, known, it, lin)
            else:
                f, Jm = self._candidate_force(fr, Xi, rows, law, joint, theta, it, lin)
            lin.g += f @ rows
            if whitened or (it == 0 and kind_ == "cand"):
                continue
            for j, row in enumerate(rows):
                Rr, Pr = self._state_map(fr, st, st.maps, row)
                lin.M += Rr @ Jm[:, j] @ Pr
        other = bs.other
        if it > 0 and other.size:
            # unmeasured harmonics follow the laws: U_h = R_DD(h W) g_h
            X[:, other] = np.einsum("nhij,nhj->nhi", fr.R[:, other, :, 1:], lin.g[:, other])
        if not whitened:
            Wr = np.stack([st.W, st.W], axis=2).reshape(n, -1)  # (n, 2KC)
            lin.M *= Wr[:, :, None]
            A = np.eye(2 * K * C)[None] - lin.M
            if it == 0:
                st.S0 = np.linalg.inv(A)  # kept: every law at the location starts here
                whitened = True
        # (I - M)^-1 applied: the stored inverse, or a solve for this iterate alone
        S = st.S0 if whitened else functools.partial(np.linalg.solve, A)
        Am, y0 = self._whitened_system(fr, st, S, st.W, drive, lin, params)
        return lin, Am, y0

    def _state_map(self, fr: _Frame, st: _States, maps: dict, row: np.ndarray):
        """Response at the sensors to a unit force at an incidence, and its state map."""
        key = row.tobytes()
        if key not in maps:
            C = self.n_channels
            Rr = np.einsum("nkcd,d->nkc", fr.R_o[:, :, :C, 1:], row)[:, :, :, None]
            Pr = np.einsum("d,nkdc->nkc", row, st.P)[:, :, None, :]
            maps[key] = (_realify(Rr), _realify(Pr))
        return maps[key]

    def _known_force(self, fr, st, i: int, element, Xi, rows, pmap, known, it: int, lin):
        """A model element's force and Jacobian at the states (kept from the first iteration
        at the data's states, which every law at the location shares); its linear parameters'
        columns added to ``lin``."""
        th = {ep: known[mp] for mp, ep in pmap.items()}
        if it == 0 and i in st.known:
            f, Jm, basis = st.known[i]
        else:
            f, Jm, basis = self._law_eval(fr, element, Xi, th, True)
            if it == 0:
                st.known[i] = (f, Jm, basis)
        for mp, ep in pmap.items():
            lin.columns.append(basis[ep] @ rows)
            lin.names.append(("known_delta" if ep == "gap" else "known", mp))
            lin.lower.append(-np.inf if ep == "gap" else 0.0)
        return f, Jm

    def _candidate_force(
        self, fr, Xi, rows, law, joint: bool, theta: dict, it: int, lin, local: bool = False
    ):
        """The candidate's force and Jacobian (its law's, and a joint's spring change) at its
        incidences; its linear parameters' columns added to ``lin`` (on every DOF, or at the
        incidences: ``local``)."""
        K = self._basis.order_k.size
        f = np.zeros_like(Xi)
        Jm = np.zeros((self.rows.size, rows.shape[0], 2 * K, 2 * K))
        if law is not None and law.kind != "joint_spring":
            th = {p: theta[p] for p in (*law.linear, *law.nonlinear)}
            f, Jm_c, basis = self._law_eval(fr, law, Xi, th, True, it > 0)
            Jm = Jm if Jm_c is None else Jm_c
            for p in law.linear:
                lin.columns.append(basis[p] if local else basis[p] @ rows)
                lin.names.append(("cand", p))
                lin.lower.append(0.0 if p in law.nonnegative else -np.inf)
        if joint:
            sp = Law("linear_spring")
            fs, Js, bsp = self._law_eval(fr, sp, Xi, {"k": theta["k_joint_delta"]}, True)
            f, Jm = f + fs, Jm + Js
            lin.columns.append(bsp["k"] if local else bsp["k"] @ rows)
            lin.names.append(("cand", "k_joint_delta"))
            lin.lower.append(-np.inf)
        return f, Jm

    def _first_system(self, fr, st, X, incid, law, joint: bool, theta, known, drive):
        """:meth:`_whitened_system` at the data's states without free parameters, where the
        model's elements' part (their forces, columns and the data's residual) is the same for
        every law at the location: computed once, only the candidate's columns added. Returns
        ``(forces with the names and bounds, matrix, right-hand side)``."""
        if st.first is None:
            lk = _Forces(np.zeros((self.rows.size, self._basis.H + 1, len(fr.dofs)), complex), None)
            for i, (kind_, element, rows, pmap) in enumerate(incid):
                if kind_ == "known":
                    f, _ = self._known_force(
                        fr, st, i, element, X @ rows.T, rows, pmap, known, 0, lk
                    )
                    lk.g += f @ rows
            Ro = fr.R_o[:, :, : self.n_channels, 1:]
            r = self._responses(Ro, st.W, lk.g, lk.columns, st.Y - drive)
            Zk = _whiten(st.S0, r)
            st.first = (Zk, tuple(lk.names), tuple(lk.lower))
            st.first_qr = _Projected(Zk[:, :, 1:].reshape(-1, Zk.shape[2] - 1))
        Zk, names, lower = st.first
        lc = _Forces(np.zeros((0,)), None, [], list(names), list(lower))
        rows = next((rows for kind_, _, rows, _ in incid if kind_ == "cand"), None)
        if rows is None:
            Z = Zk
        else:
            # the candidate's forces and columns at its incidences, responding through them
            f, _ = self._candidate_force(fr, X @ rows.T, rows, law, joint, theta, 0, lc, True)
            key = ("incidence", rows.tobytes())
            if key not in st.maps:
                C = self.n_channels
                st.maps[key] = np.einsum("nkcd,md->nkcm", fr.R_o[:, :, :C, 1:], rows)
            Zc = _whiten(st.S0, self._responses(st.maps[key], st.W, f, lc.columns))
            Z = np.concatenate([Zk, Zc[:, :, 1:]], axis=2)
            Z[:, :, 0] += Zc[:, :, 0]
        return lc, Z[:, :, 1:].reshape(-1, Z.shape[2] - 1), Z[:, :, 0].ravel()

    @staticmethod
    def _first_lsq(st: _States, A: np.ndarray, y: np.ndarray, lin: _Forces):
        """:func:`_bounded_lsq` of a first system, whose first columns (the model's elements')
        are the same for every law at the location: factorised once (:class:`_Projected`),
        each law reduces the problem to one of its size only."""
        small = None if st.first_qr is None else st.first_qr.reduce(A, y)
        if small is None:
            return _bounded_lsq(A, y, lin.lower)
        x, _ = _bounded_lsq(*small, lin.lower)
        r = y - A @ x
        return x, float(r @ r)

    def _responses(self, R, W, g, columns, data=None) -> np.ndarray:
        """Weighted responses at the sensors (n, K, C, 1 + columns) at the measured orders,
        through ``R`` (n, K, C, d) from forces on d places: first the residual of ``data``
        (minus the response alone without) to the forces ``g``, then the response to each
        column."""
        ok = self._basis.order_k
        cols = np.stack([g[:, ok], *(c[:, ok] for c in columns)], -1)
        r = np.matmul(R, cols) * W[..., None]
        r[..., 0] = (0.0 if data is None else data * W) - r[..., 0]
        return r

    def _whitened_system(self, fr, st, S, W, drive, lin: _Forces, params):
        """The data's residual and each column's response at the sensors, whitened at once
        (the free parameters' derivatives appended to ``lin``; ``S`` the whitening or a
        function applying it); returns the least-squares matrix and right-hand side at zero
        change."""
        bs = self._basis
        r = self._responses(
            fr.R_o[:, :, : self.n_channels, 1:], W, lin.g, lin.columns, st.Y - drive
        )
        fo = np.concatenate([self._F[self.rows][:, :, None], lin.g[:, bs.order_k]], axis=2)
        extra = []
        for name in params:
            dR = self._param_derivative(fr, name)  # (n, K, C, 1 + nD)
            extra.append(np.einsum("nkij,nkj->nki", dR, fo) * W)
            lin.names.append(("param", name))
            lin.lower.append(-np.inf)
        if extra:
            r = np.concatenate([r, np.stack(extra, -1)], axis=-1)
        Z = _whiten(S, r)
        return Z[:, :, 1:].reshape(-1, Z.shape[2] - 1), Z[:, :, 0].ravel()


def _whiten(S, r: np.ndarray) -> np.ndarray:
    """``S`` (a matrix per step, or a function applying one) on the real coefficients of the
    responses ``r`` (n, K, C, q), in the order of :func:`_vec`: (n, 2KC, q)."""
    n, K, C, q = r.shape
    V = np.stack([r.real, -r.imag], axis=2).reshape(n, 2 * K * C, q)
    return S(V) if callable(S) else np.matmul(S, V)


def _current(names, known: dict, theta: dict) -> np.ndarray:
    """The least squares' unknowns at their current values (a change is at zero)."""
    return np.array(
        [
            known[nm] if kd == "known" else theta.get(nm, 0.0) if kd == "cand" else 0.0
            for kd, nm in names
        ]
    )


@dataclass
class _Forces:
    """One iteration of :meth:`Screen._fit`: the laws' total force phasors, the whitening's
    sum of state maps (``None`` when the stored whitening is used) and the columns of the
    linear parameters, with their names and lower bounds."""

    g: np.ndarray
    M: np.ndarray | None
    columns: list = field(default_factory=list)
    names: list = field(default_factory=list)
    lower: list = field(default_factory=list)


def _incidences(fr: _Frame, law, joint: bool, B_loc) -> list:
    """Where laws act: the model's elements, then the candidate's."""
    incid = []
    for element, a, b, pmap in fr.known:
        row = np.zeros(len(fr.dofs))
        row[a] = 1.0
        if b is not None:
            row[b] = -1.0
        incid.append(("known", element, row[None, :], pmap))
    if law is not None or joint:
        incid.append(("cand", law, B_loc, None))
    return incid


def _take_values(names, x, known: dict, theta: dict) -> None:
    """The least squares' solution into the model's elements' values and the candidate's."""
    for (kd, nm), v in zip(names, x, strict=True):
        if kd == "known":
            known[nm] = max(float(v), 0.0)
        elif kd == "known_delta":
            known[nm] = max(float(known[nm] + v), 0.0)
        elif kd == "param":
            theta[nm] = theta.get(nm, 0.0) + float(v)
        else:
            theta[nm] = float(v)


@dataclass(frozen=True)
class ScreenJob:
    """A share of a screen, to run on an executor: the first pass over ``candidates``
    (:func:`screen_pass`) or the alternations of the fits ``refine`` (:func:`refine_pass`).
    ``locations`` are the screen's places (default: the candidates'); jobs with the same
    model, file and places share one screen in a worker process."""

    model_toml: str
    source: str
    data_path: str
    candidates: tuple[Candidate, ...]
    n_harmonics: int = 9
    n_time: int = 128
    free_parameters: tuple[str, ...] = ()
    locations: tuple[Location, ...] = ()
    refine: tuple[ScreenFit, ...] = ()


def screen_pass(job: ScreenJob) -> list[ScreenFit]:
    """The first pass of a screen over ``job.candidates`` (top level, for executors)."""
    return _job_screen(job).first_pass(job.candidates)


def refine_pass(job: ScreenJob) -> list[ScreenFit]:
    """``job.refine`` through the screen's alternations (:meth:`Screen.refined`; top level,
    for executors)."""
    screen = _job_screen(job)
    return [screen.refined(f) for f in job.refine]


def _job_screen(job: ScreenJob) -> Screen:
    """The screen of a job, kept for the next job of the same screen in this process (its
    receptances and force estimates are most of a small job's work)."""
    places = job.locations or tuple(c.location for c in job.candidates)
    key: tuple = (job.model_toml, job.source, job.data_path, job.n_harmonics, job.n_time)
    key = (*key, places, job.free_parameters)
    if _JOB_SCREEN and _JOB_SCREEN[0] == key:
        return _JOB_SCREEN[1]
    from analysis.measurement_file import read_measurement

    model = Model.from_toml_text(job.model_toml, job.source)
    data = read_measurement(job.data_path)
    pred = BranchMatchedPredictor(model, data, n_harmonics=job.n_harmonics, n_time=job.n_time)
    screen = Screen(
        model, data, predictor=pred, free_parameters=job.free_parameters, locations=places
    )
    _JOB_SCREEN[:] = [key, screen]  # one at a time: a screen's receptances are large
    return screen


_JOB_SCREEN: list = []


class _Projected:
    """Least squares ``min |y - [A_k, C] x|`` (bounded or not) for many ``C`` and ``y`` beside
    one ``A_k``: ``A_k = Q R`` once; each ``C`` projected out of ``Q``'s span (twice, so that
    the projection stays orthogonal to the rounding) and factorised gives the whole matrix's
    triangular factor, and the problem becomes one of the size of ``x`` with the same
    solution: ``min |Q'^T y - R' x|`` (``Q' = [Q, Q_C]``; the rest of ``y`` is orthogonal to
    every column). Where the columns are nearly dependent (a diagonal of the triangular factor
    below :data:`INDEPENDENT` of its column's norm: a law that exerts no force at the states,
    a model element that does not either), :meth:`reduce` declines and the caller solves the
    whole matrix (its minimum-norm solution)."""

    def __init__(self, A_k: np.ndarray) -> None:
        self.k = A_k.shape[1]
        Q, R = np.linalg.qr(A_k)
        self.Q: np.ndarray = Q
        self.R: np.ndarray = R
        self.ok = self.k > 0 and _independent(R, A_k)

    def reduce(self, A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """``(R', Q'^T y)`` for the whole matrix ``A`` (its first columns ``A_k``), None if
        declined."""
        k, C = self.k, A[:, self.k :]
        if not self.ok or C.shape[1] == 0:
            return None
        Q, c = self.Q, C.shape[1]
        Cy = np.column_stack([C, y])
        a = Q.T @ Cy
        P = Cy - Q @ a
        a2 = Q.T @ P
        P -= Q @ a2
        a += a2
        # the triangular factor of [C y] projected: C's factor and Q_C^T y in one
        Ry = np.asarray(np.linalg.qr(P, mode="r"))
        if not _independent(Ry[:c, :c], C):
            return None
        R = np.zeros((k + c, k + c))
        R[:k, :k], R[:k, k:], R[k:, k:] = self.R, a[:, :c], Ry[:c, :c]
        return R, np.concatenate([a[:, c], Ry[:c, c]])


#: A column is independent of those before it when its triangular factor's diagonal is at
#: least this share of its norm (numpy's least squares truncates at 2e-12 of the largest
#: singular value of the column-scaled matrix: far below).
INDEPENDENT = 1e-8


def _independent(R: np.ndarray, A: np.ndarray) -> bool:
    norms = np.linalg.norm(A, axis=0)
    return bool(np.all(np.abs(np.diag(R)) > INDEPENDENT * norms))  # a zero column fails too


def _bounded_lsq(A: np.ndarray, y: np.ndarray, lower: np.ndarray):
    """Least squares ``min |y - A x|`` with ``x >= lower``: the unconstrained solution when it
    satisfies the bounds (then it is the bounded one: the problem is convex), else BVLS."""
    lower = np.asarray(lower, dtype=float)
    if A.shape[1] == 0:
        return np.zeros(0), float(y @ y)
    s = np.linalg.norm(A, axis=0)
    s[s == 0] = 1.0
    x = np.linalg.lstsq(A / s, y, rcond=None)[0]
    if not np.all(x >= lower * s):
        bounds = (lower * s, np.full(lower.size, np.inf))
        x = lsq_linear(A / s, y, bounds=bounds, method="bvls").x
    x = x / s
    r = y - A @ x
    return x, float(r @ r)


def _linear(model: Model):
    from analysis.system import build_linear

    return build_linear(model)
