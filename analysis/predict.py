"""Model predictions of a stepped-sine measurement file.

The analytical multi-harmonic FRFs are computed as the paper prescribes: the model is driven by
the *measured* force phasors of every step, in the measured order of the steps (each sweep warm-
starts from its previous step), at the realised frequencies; where a bistable region lets the
model sit on another branch than the test did, the branch the measurement supports is taken.
The model's response is taken in each channel's quantity (acceleration phasors are ``-(k w)^2``
times displacement phasors) and divided by the measured force, like the measured FRF.
Sensor masses from the file's channel table are part of the model.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.linear.static_support import StaticSupport
from analysis.measurement_file import SteppedSineData
from analysis.mhb.sensitivity import point_sensitivities
from analysis.mhb.sweep import solve_steps
from analysis.model import Model
from analysis.system import (
    DEFAULT_HARMONICS,
    DEFAULT_TIME_SAMPLES,
    build_linear,
    build_problem_dofs,
)

__all__ = [
    "BOUNDED_MESSAGE",
    "STOPPED_MESSAGE",
    "CostBound",
    "Prediction",
    "SteppedSinePredictor",
    "ZeroStandardError",
    "check_standard_errors",
    "needed_rows",
    "sweeps_of",
]

_POWER = {"displacement": 0, "velocity": 1, "acceleration": 2}

#: The message of a prediction stopped at a needed step without a solution (``{n}``: the
#: needed steps left without one, that step included).
STOPPED_MESSAGE = (
    "stopped at a needed step without a solution (stop_at_failure): {n} needed step(s) left "
    "unsolved"
)
#: The message of a prediction stopped once its metric exceeded a bound's limit.
BOUNDED_MESSAGE = "stopped once the metric exceeded {limit:.6g} (its lower bound {floor:.6g})"


@dataclass
class CostBound:
    """A metric's running lower bound, for a prediction that may stop once the metric provably
    exceeds ``limit``.

    The metric is a sum of non-negative terms, one per step: ``step_cost(row, frf)`` of the
    step's final FRFs (channels, compared orders). A predictor adds each step's term to
    :attr:`floor` once no later stage can change that step's solution, so ``floor`` never
    exceeds the metric of the full prediction; once it exceeds ``limit`` the rest cannot bring
    the metric back under it, and the prediction stops there.
    """

    step_cost: Callable[[int, np.ndarray], float]
    limit: float
    floor: float = 0.0

    def add(self, row: int, frf: np.ndarray) -> bool:
        """Add step ``row``'s final term; whether the metric now exceeds the limit."""
        self.floor += self.step_cost(row, frf)
        return self.exceeded

    @property
    def exceeded(self) -> bool:
        # a relative margin far above the rounding of the two sums' different orders
        return self.floor > self.limit * (1.0 + 1e-9)


@dataclass(frozen=True)
class Prediction:
    """Model FRFs of the file's steps.

    Attributes
    ----------
    frf : ndarray, shape (n_steps, n_channels, n_orders), complex
        Model response per unit measured force, in each channel's unit per N.
    d_frf : dict name -> ndarray of the same shape
        Derivatives with respect to the requested parameters.
    converged : ndarray of bool, shape (n_steps,)
    messages : list of str
        Why unconverged steps failed.
    floor : float or None
        Set when the prediction stopped because its metric exceeded a :class:`CostBound`'s
        limit: the metric's lower bound reached (above that limit).
    """

    frf: np.ndarray
    d_frf: dict[str, np.ndarray]
    converged: np.ndarray
    messages: list[str]
    floor: float | None = None

    @classmethod
    def empty(cls, shape: tuple[int, int, int], params: Sequence[str]) -> Prediction:
        """NaN FRFs and derivatives of ``shape`` (steps, channels, orders), nothing converged,
        to be filled step by step."""
        return cls(
            np.full(shape, np.nan + 0j),
            {p: np.full(shape, np.nan + 0j) for p in params},
            np.zeros(shape[0], dtype=bool),
            [],
        )

    def mark(self, row: int, point, frequency_hz: float) -> bool:
        """Record whether the solution ``point`` of step ``row`` converged (with its message
        when not); returns ``point.converged``."""
        self.converged[row] = point.converged
        if not point.converged:
            self.messages.append(f"step {row} ({frequency_hz:.3f} Hz): {point.message}")
        return bool(point.converged)


def needed_rows(n_steps: int, rows: np.ndarray | None) -> np.ndarray:
    """Boolean mask of the steps asked for (all when ``rows`` is None), shape (n_steps,)."""
    return np.ones(n_steps, bool) if rows is None else np.isin(np.arange(n_steps), rows)


def sweeps_of(data: SteppedSineData) -> list[np.ndarray]:
    """Row indices of each sweep: consecutive steps at one level in one direction."""
    if data.n_steps == 0:
        return []
    key = np.stack([data.level_index, data.sweep_direction])
    breaks = np.flatnonzero(np.any(key[:, 1:] != key[:, :-1], axis=0)) + 1
    return [r for r in np.split(np.arange(data.n_steps), breaks) if r.size]


class SteppedSinePredictor:
    """Predicts the FRFs of a stepped-sine file from a model.

    Parameters
    ----------
    model : Model
        Without sensor masses: those of the file's channel table are added here.
    data : SteppedSineData
    channels : sequence of str, optional
        Response channels compared (default: every acceleration/velocity/displacement channel
        that is not the drive force).
    n_harmonics, n_time, f_max_hz
        Balance settings (defaults: the validated analysis defaults).
    branch_tolerance : float
        Relative miss of the fundamental beyond which the other branch of a bistable region is
        tried (see ``_follow``).
    """

    def __init__(
        self,
        model: Model,
        data: SteppedSineData,
        *,
        channels: Sequence[str] | None = None,
        n_harmonics: int = DEFAULT_HARMONICS,
        n_time: int = DEFAULT_TIME_SAMPLES,
        f_max_hz: float = 2000.0,
        branch_tolerance: float = 0.25,
    ) -> None:
        self.data = data
        self.settings = {"n_harmonics": n_harmonics, "n_time": n_time, "f_max_hz": f_max_hz}
        masses: dict[int, float] = {}
        for ch in data.channels:
            if ch.mass_kg > 0:
                if ch.point not in model.points:
                    raise ValueError(
                        f"{data.path}: channel {ch.name!r} sits at point {ch.point}, which the "
                        f"model does not have (model points: {sorted(model.points)})"
                    )
                masses[ch.point] = masses.get(ch.point, 0.0) + ch.mass_kg
        self.model = model.add_masses(masses) if masses else model
        if channels is None:
            idx = [
                i
                for i, ch in enumerate(data.channels)
                if ch.quantity in _POWER and ch.role != "drive-force"
            ]
        else:
            idx = [data.channel_index(c) for c in channels]
        if not idx:
            raise ValueError(f"{data.path}: no response channel to compare")
        self.channel_indices = idx
        self.channel_names = [data.channels[i].name for i in idx]
        asm = self.model.assemble()
        self._out_dofs, self._out_sign, self._power = [], [], []
        for i in idx:
            ch = data.channels[i]
            if ch.quantity not in _POWER:
                raise ValueError(f"channel {ch.name!r}: quantity {ch.quantity!r} is not a motion")
            self._out_dofs.append(self._dof(asm, ch.point, ch.direction, ch.name))
            self._out_sign.append(-1.0 if ch.direction.startswith("-") else 1.0)
            self._power.append(_POWER[ch.quantity])
        act = data.actuator
        self._force_dof = self._dof(asm, act.point, act.direction, "actuator")
        self._force_sign = -1.0 if act.direction.startswith("-") else 1.0
        self.orders = data.orders
        # the model is driven by every force the file measured: at the orders, and at the
        # extra orders where the shaker pushed back at the response's harmonics
        self.drive_orders = (*data.orders, *data.extra_orders)
        self.drive_force = np.concatenate([data.force, data.extra_force], axis=1)
        self.drive_force_std = np.concatenate([data.force_std, data.extra_force_std], axis=1)
        den = math.lcm(*(o.denominator for o in self.drive_orders))
        top = max(int(o * den) for o in self.drive_orders)
        if top > n_harmonics:
            self.settings["n_harmonics"] = top
        self.branch_tolerance = branch_tolerance
        self._linear_key: Any = None
        self._linear: Any = None
        #: Modes (1-based) whose damping ratios are parameters of the derivatives (``zeta_4``).
        self.damping_modes: tuple[int, ...] = ()
        #: Steps solved by stepping so far (every step of every pass, over all calls).
        self.steps_solved = 0
        #: Times each sweep (index among the needed ones) ended with a needed step unsolved
        #: (or, in a prediction with a bound, with the metric past it): the order a prediction
        #: that may stop early tries them in.
        self._failed_sweeps: dict[int, int] = {}

    def _dof(self, asm, point: int, direction: str, what: str) -> int:
        if point not in self.model.points:
            raise ValueError(f"{self.data.path}: {what} at point {point}, unknown to the model")
        node = self.model.points[point].node
        return asm.dof_index(node, direction.lstrip("-"))

    # ----------------------------------------------------------------------------------
    def measured(self) -> tuple[np.ndarray, np.ndarray]:
        """Measured FRFs and their standard errors, each shape (n_steps, n_channels, n_orders).

        ``std = |H| sqrt((s_R/|R|)^2 + (s_F/|F|)^2)`` (first order in the phasor errors).
        """
        d = self.data
        R = d.response[:, self.channel_indices, :]
        sR = d.response_std[:, self.channel_indices, :]
        F = d.force[:, None, :]
        sF = d.force_std[:, None, :]
        H = R / F
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.sqrt(
                np.nan_to_num((sR / np.abs(R)) ** 2) + np.nan_to_num((sF / np.abs(F)) ** 2)
            )
        return H, np.abs(H) * rel

    def _linear_model(self, model: Model):
        key = tuple(
            sorted(
                (n, v) for n, v in model.values().items() if model.parameters[n].group == "linear"
            )
        )
        if key != self._linear_key:
            lin = build_linear(
                model, f_max_hz=self.settings["f_max_hz"], damping_modes=self.damping_modes
            )
            static = self.data.actuator.static_stiffness_n_per_m
            # The unmeasured mean force: the shaker holds the drive point (see StaticSupport).
            self._linear = StaticSupport(lin, self._force_dof, static) if static > 0 else lin
            self._linear_key = key
        return self._linear

    def _frf_k(self, pb) -> np.ndarray:
        """Harmonic indices of the file's orders (the FRFs) in the balance ``pb``."""
        return pb.order_k[: len(self.orders)]

    def _follow(self, pb, row: int, F: np.ndarray, X, factor: np.ndarray, H_row: np.ndarray):
        """Solve one step, on the branch the test was on.

        The step starts from the previous step's solution, as the test's rig did. Where the
        fundamental then misses the measurement by more than ``branch_tolerance`` (relative), a
        second start from the linear response may find the other branch of a bistable region;
        the solution closer to the measured FRFs is taken: a test under force control can jump
        earlier or later than a model driven by the recorded forces (the shaker's voltage drive
        has its own fold).
        """
        w = 2 * np.pi * self.data.frequency_hz[row]
        p = solve_steps(pb, [w], F[:, None], X0=X).points[0]
        if X is None or not np.all(np.isfinite(H_row[:, 0])):
            return p

        def miss(q):
            if not q.converged:
                return np.inf
            model = q.q_out[self._frf_k(pb)].T * factor
            return float(np.max(np.abs(model[:, 0] - H_row[:, 0]) / np.abs(H_row[:, 0])))

        m0 = miss(p)
        if m0 <= self.branch_tolerance:
            return p
        alt = solve_steps(pb, [w], F[:, None]).points[0]
        return alt if miss(alt) < m0 else p

    def _sweep_order(self, sweeps: list[np.ndarray]) -> list[int]:
        """Indices into ``sweeps`` (row arrays), likeliest to end a prediction first: by how
        often each did in earlier calls, then by level (the contact's nonlinearity grows with it),
        highest first."""
        lv = self.data.levels_n[self.data.level_index]
        return sorted(
            range(len(sweeps)),
            key=lambda i: (-self._failed_sweeps.get(i, 0), -float(np.max(lv[sweeps[i]])), i),
        )

    def predict(
        self,
        values: Mapping[str, float] | None = None,
        params: Sequence[str] = (),
        rows: np.ndarray | None = None,
        *,
        stop_at_failure: bool = False,
    ) -> Prediction:
        """Model FRFs (and derivatives) at parameter ``values`` for the file's steps.

        Parameters
        ----------
        values : mapping, optional
            Parameter values replacing the model's.
        params : sequence of str
            Parameters to differentiate with respect to.
        rows : ndarray of int, optional
            Only these steps (each sweep still solved in order up to its last needed step).
        stop_at_failure : bool
            Stop at the first needed step without a solution (a metric over the needed steps
            is then ``inf`` whatever the others give): the steps not yet solved stay NaN and
            unconverged. The sweeps are independent (each starts from its first step's linear
            response), so they are then solved in the order likeliest to fail first
            (:meth:`_sweep_order`); every step solved is the same as without it.
        """
        model = self.model.with_values(values) if values else self.model
        lin = self._linear_model(model)
        pb = build_problem_dofs(
            model,
            [self._force_dof],
            self._out_dofs,
            orders=self.drive_orders,
            n_harmonics=self.settings["n_harmonics"],
            n_time=self.settings["n_time"],
            linear=lin,
        )
        d = self.data
        out = Prediction.empty((d.n_steps, len(self.channel_indices), len(self.orders)), params)
        need = needed_rows(d.n_steps, rows)
        orders = np.array([float(o) for o in self.orders])
        sign = np.array(self._out_sign)[:, None]
        power = np.array(self._power)[:, None]
        H_meas, _ = self.measured()
        k_frf = self._frf_k(pb)
        sweeps = [s for s in sweeps_of(d) if need[s].any()]
        order = self._sweep_order(sweeps) if stop_at_failure else range(len(sweeps))
        for i in order:
            if self._predict_sweep(
                out,
                pb,
                sweeps[i],
                need,
                params,
                orders,
                sign,
                power,
                H_meas,
                k_frf,
                stop_at_failure,
            ):
                self._failed_sweeps[i] = self._failed_sweeps.get(i, 0) + 1
                if stop_at_failure:
                    left = int((need & ~out.converged).sum())
                    out.messages.append(STOPPED_MESSAGE.format(n=left))
                    break
        return out

    def _predict_sweep(
        self, out, pb, sweep, need, params, orders, sign, power, H_meas, k_frf, stop_at_failure
    ) -> bool:
        """Fill ``out`` with the steps of ``sweep`` (up to its last needed one); whether a
        needed step failed (the sweep then ends there with ``stop_at_failure``)."""
        d = self.data
        failed = False
        last = sweep[np.flatnonzero(need[sweep]).max()]
        sweep = sweep[: np.flatnonzero(sweep == last)[0] + 1]
        F = self._force_sign * self.drive_force[sweep]
        X = None
        H = len(self.orders)
        if params:
            pb.prefetch(2 * np.pi * d.frequency_hz[sweep[need[sweep]]], params)
        for j, row in enumerate(sweep):
            wk = 2 * np.pi * d.frequency_hz[row] * orders  # (H,)
            factor = sign * (1j * wk[None, :]) ** power / F[j][None, :H] * self._force_sign
            p = self._follow(pb, row, F[j], X, factor, H_meas[row])
            self.steps_solved += 1
            if not out.mark(row, p, d.frequency_hz[row]):
                if need[row]:
                    failed = True
                    if stop_at_failure:
                        return True
                continue
            X = p.X
            out.frf[row] = p.q_out[k_frf].T * factor
            if params and need[row]:
                sens = point_sensitivities(pb, p, list(params))
                for name in params:
                    out.d_frf[name][row] = sens[name].d_outputs(k_frf).T * factor
        return failed


class ZeroStandardError(ValueError):
    """A measured FRF that a weighted comparison needs has a standard error of zero."""


def check_standard_errors(
    data: SteppedSineData,
    channel_names: Sequence[str],
    H: np.ndarray,
    std: np.ndarray,
    rows: np.ndarray | None = None,
    remedy: str = "",
) -> None:
    """Refuse measured FRFs with a standard error of zero (naming the file and the channels).

    The measurement-file contract allows a standard error of 0 (a value known exactly, e.g. a
    synthetic file written without noise). A residual divided by it is infinite, so the
    analysis used to put a floor under it (the smallest positive standard error of the file,
    or 1.0 in FRF units when none was positive) without a word: the chi-square, the verdicts
    and the calibrated values then depended on that arbitrary floor. Falling back to identity
    weighting silently would change them as well (chi-square no longer in units of the noise).
    So a weighted comparison refuses such a file with this error, and the user chooses: fix
    the file's uncertainties, or ask for the unweighted metric where there is one
    (``calibrate --identity``, the paper's ``W = I``), which the ``remedy`` text names.

    Parameters
    ----------
    data : SteppedSineData
        The file (its path is named).
    channel_names : sequence of str
        Names of the channels of ``H``'s second axis.
    H, std : ndarray, shape (n_steps, n_channels, n_orders)
        Measured FRFs and their standard errors; only finite FRFs are checked.
    rows : ndarray of bool, shape (n_steps,), optional
        The steps that enter (default: all).
    remedy : str
        What the user can do, appended to the message.

    Raises
    ------
    ZeroStandardError
        If a checked FRF has a standard error of zero.
    """
    bad = np.isfinite(H) & (np.asarray(std) == 0)
    if rows is not None:
        bad &= np.asarray(rows, bool)[:, None, None]
    if not bad.any():
        return
    per_channel = bad.sum(axis=(0, 2))
    where = ", ".join(
        f"{name} ({int(k)} value{'s' if k != 1 else ''})"
        for name, k in zip(channel_names, per_channel, strict=True)
        if k
    )
    raise ZeroStandardError(
        f"{data.path}: standard errors of zero in channel(s) {where}: a zero standard error "
        "claims an exact value, so the residuals cannot be weighted by it"
        + (f"; {remedy}" if remedy else "")
    )
