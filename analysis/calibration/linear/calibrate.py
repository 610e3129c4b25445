"""Linear calibration from a random-excitation run with damping equalization.

>>> result = calibrate_linear(load_model(), "random.h5")            # doctest: +SKIP
>>> result.parameters["k_mount"], result.std["k_mount"]              # doctest: +SKIP
>>> result.save_model("calibrated_model.toml")                       # doctest: +SKIP

Steps: the sensors' masses of the channel table are added to the model; the run's motion FRFs
become receptances along the model axes; the test modes in the band are identified
(:func:`~analysis.calibration.linear.modal_id.identify_modes`); the test FRFs are re-synthesised
with every mode at ``zeta0`` at frequencies within the modes' half-power bands, and the model's
FRFs with the same ``zeta0`` are fitted to them on log10 magnitude
(:class:`~analysis.calibration.linear.objective.EqualizedFRFObjective`) by a bounded
Levenberg-Marquardt with the analytic Jacobian. The fit runs as a damping continuation: first
at larger equalized damping (0.2, 0.1, 0.05, 0.02), whose smoother metric has a wide basin of
attraction, each stage starting the next, then at ``zeta0``. The identified modal damping is
paired with the calibrated model's modes (MAC and frequency) and written to its
``DampingSpec.per_mode``.

The split of the FRFs into calibration and validation sets is
:func:`~analysis.calibration.linear.split.split_channels` (default: points 1-8 and 11 calibrate,
9, 10, 12 and 13 validate).
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from analysis.calibration.linear.damping_equalization import equalize
from analysis.calibration.linear.modal_id import ModalFit, identify_modes
from analysis.calibration.linear.mode_matching import match_modes, renumber_modes
from analysis.calibration.linear.objective import EqualizedFRFObjective, receptance
from analysis.calibration.linear.result import LinearCalibration
from analysis.calibration.linear.run_frfs import (
    CalibrationError,
    RunFRFs,
    load_random_run,
    sensor_masses,
)
from analysis.calibration.linear.split import DEFAULT_CALIBRATION_POINTS, split_channels
from analysis.calibration.lm import LeastSquaresResult, least_squares_lm
from analysis.calibration.parameters import ParameterSpace
from analysis.linear.modal import modal_analysis, mode_sensitivities
from analysis.measurement_file import RandomData, RunData, read_measurement
from analysis.model import DampingSpec, Model

__all__ = [
    "DEFAULT_CALIBRATION_POINTS",
    "METHODS",
    "LinearCalibrationSettings",
    "calibrate_linear",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LinearCalibrationSettings:
    """Settings of :func:`calibrate_linear` (validated on construction).

    Parameters
    ----------
    parameters : tuple of str, optional
        Calibrated parameters (group ``"linear"``); default: those flagged ``calibrate``.
    calibration_points : tuple of int, "default" or "information"
        Points whose FRFs calibrate; the other measured points validate. ``"default"``:
        :data:`DEFAULT_CALIBRATION_POINTS` when all of them and another point are measured,
        otherwise ``"information"`` with ``n_calibration`` points.
    n_calibration : int, optional
        Points chosen by ``"information"`` (default ``round(9/13 * n_points)``).
    band_hz : (float, float), optional
        Band of the modal identification (default: the file's positive frequencies).
    zeta0 : float, optional
        Equalized damping (default: mean identified damping, clipped to [0.005, 0.05]).
    zeta0_schedule : tuple of float
        Damping continuation: the values above ``zeta0`` are calibrated first, in the given
        order, each stage starting the next, then ``zeta0``. A larger equalized damping gives
        a smoother metric with a wider basin of attraction (wider half-power bands); the last
        stage restores the resolution. ``()`` calibrates at ``zeta0`` only.
    n_per_band : int
        Metric frequencies per half-power band.
    use_phase : bool
        Add the phase deviation to the log-magnitude residuals.
    method : {"lm", "trf"}
        ``"lm"``: Levenberg-Marquardt with steps projected onto the bounds (the paper's
        method); ``"trf"``: scipy's trust-region reflective least squares.
    max_iterations : int
    min_modes : int, optional
        Fewest identified modes accepted (default: the number of parameters).
    min_coherence : float
        Frequencies where any channel's coherence is lower are left out of the identification.
    f_max_factor : float
        Model modes up to ``f_max_factor`` times the band's top are superposed; the rest enter
        as static flexibility.
    mac_min : float
        Least MAC for pairing a test mode with a model mode.
    keep_sensor_masses : bool
        Keep the run's sensor masses in the calibrated model file (default: the file describes
        the structure; each run adds its own sensors).
    weak_parameters : {"hold", "fit"}
        ``"hold"``: a parameter the test does not determine better than its prior (the model
        file's ``prior_rel_std``), or that runs to a bound, is held at its nominal value with
        its prior uncertainty, and the others are fitted again with it held
        (:func:`decide_weak`); its uncertainty is carried into theirs. ``"fit"``: every
        parameter is fitted whatever the test says of it (for comparing candidate models on
        the same parameters).
    """

    parameters: tuple[str, ...] | None = None
    calibration_points: tuple[int, ...] | str = "default"
    n_calibration: int | None = None
    band_hz: tuple[float, float] | None = None
    zeta0: float | None = None
    zeta0_schedule: tuple[float, ...] = (0.2, 0.1, 0.05, 0.02)
    n_per_band: int = 9
    use_phase: bool = False
    method: str = "lm"
    max_iterations: int = 100
    min_modes: int | None = None
    min_coherence: float = 0.0
    f_max_factor: float = 10.0
    mac_min: float = 0.5
    keep_sensor_masses: bool = False
    weak_parameters: str = "hold"

    def __post_init__(self) -> None:
        cp = self.calibration_points
        if isinstance(cp, str):
            if cp not in ("default", "information"):
                raise ValueError("calibration_points: 'default', 'information' or point numbers")
        else:
            object.__setattr__(self, "calibration_points", tuple(int(p) for p in cp))
            if not self.calibration_points:
                raise ValueError("calibration_points: give at least one point")
        if self.parameters is not None:
            object.__setattr__(self, "parameters", tuple(self.parameters))
        if self.band_hz is not None:
            lo, hi = map(float, self.band_hz)
            if not 0 < lo < hi:
                raise ValueError(f"band_hz: need 0 < low < high, got {self.band_hz!r}")
            object.__setattr__(self, "band_hz", (lo, hi))
        if self.zeta0 is not None and not 0 < self.zeta0 < 0.5:
            raise ValueError(f"zeta0: must be in (0, 0.5), got {self.zeta0!r}")
        object.__setattr__(self, "zeta0_schedule", tuple(float(z) for z in self.zeta0_schedule))
        if not all(0 < z < 0.5 for z in self.zeta0_schedule):
            raise ValueError(f"zeta0_schedule: values in (0, 0.5), got {self.zeta0_schedule!r}")
        if self.method not in METHODS:
            raise ValueError(f"method: one of {sorted(METHODS)}, got {self.method!r}")
        if self.n_per_band < 2 or self.max_iterations < 1 or self.f_max_factor < 1:
            raise ValueError("n_per_band >= 2, max_iterations >= 1 and f_max_factor >= 1")
        if not 0 <= self.min_coherence < 1 or not 0 <= self.mac_min <= 1:
            raise ValueError("min_coherence in [0, 1) and mac_min in [0, 1]")
        if self.weak_parameters not in ("hold", "fit"):
            raise ValueError(f"weak_parameters: 'hold' or 'fit', got {self.weak_parameters!r}")

    def to_json(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


# -- solvers ------------------------------------------------------------------------------
def _solve_lm(obj, x0, bounds, max_iterations) -> LeastSquaresResult:
    return least_squares_lm(obj, x0, bounds=bounds, max_iterations=max_iterations)


def _solve_trf(obj, x0, bounds, max_iterations) -> LeastSquaresResult:
    sol = least_squares(
        lambda x: obj(x, False)[0],
        x0,
        jac=lambda x: obj(x, True)[1],
        bounds=bounds,
        method="trf",
        max_nfev=max_iterations,
    )
    J = sol.jac
    cov = np.linalg.pinv(J.T @ J)
    njev = int(sol.njev or 0)
    return LeastSquaresResult(
        sol.x,
        float(sol.cost),
        sol.fun,
        J,
        cov,
        int(sol.nfev),
        njev,
        njev,
        bool(sol.success),
        str(sol.message),
    )


METHODS = {"lm": _solve_lm, "trf": _solve_trf}
"""Solver kernels by name: ``(objective, x0, bounds, max_iterations) -> LeastSquaresResult``."""


# -- the entry point ----------------------------------------------------------------------
def calibrate_linear(
    model: Model,
    run: RandomData | str | PathLike[str],
    settings: LinearCalibrationSettings | None = None,
    **changes: Any,
) -> LinearCalibration:
    """Calibrate the linear parameters of ``model`` on a random-excitation run.

    Parameters
    ----------
    model : Model
        The start model (its parameter values start the iteration).
    run : RandomData or path
        A ``kind = "random"`` measurement file (H1 of every channel to the drive force).
    settings : LinearCalibrationSettings, optional
    **changes
        Fields of ``settings`` to replace, e.g. ``zeta0=0.01``.

    Returns
    -------
    LinearCalibration
        ``validation["before"|"after"]`` holds, per channel and as RMS over the calibration and
        validation channels, the log10-magnitude deviation at the metric frequencies with every
        mode at ``zeta0`` (``"equalized"``) and over the band against the measured FRFs with
        the model's damping (``"measured"``: the start model's own, the calibrated model's
        identified per-mode damping).

    Raises
    ------
    CalibrationError
        Wrong file kind, a channel at a point the model lacks, parameters not of group
        ``"linear"``, or fewer identified modes than ``min_modes``.
    """
    st = dataclasses.replace(settings or LinearCalibrationSettings(), **changes)
    t0 = time.perf_counter()
    data = run if isinstance(run, RunData) else read_measurement(run)
    run_frfs = load_random_run(data, model)  # checks the kind and the points
    masses = sensor_masses(data)
    model_s = model.add_masses(masses) if masses else model
    names = _parameter_names(model, st.parameters)
    space = ParameterSpace.from_model(model_s, names)
    f, H, sH, g2, band = _band(run_frfs, st)
    fit = _identify(f, H, band, sH, g2)
    n_min = len(names) if st.min_modes is None else st.min_modes
    if fit.n_modes < n_min:
        raise CalibrationError(
            f"{run_frfs.source}: {fit.n_modes} mode(s) identified in {band[0]:g}-{band[1]:g} Hz; "
            f"calibrating {len(names)} parameter(s) needs at least {n_min}: widen the band or "
            "calibrate fewer parameters"
        )
    zeta0 = st.zeta0 if st.zeta0 is not None else float(np.clip(np.mean(fit.zeta), 0.005, 0.05))
    eq = equalize(fit, zeta0, st.n_per_band)
    t_id = time.perf_counter()

    rows, col = run_frfs.dofs(model_s)
    f_max = st.f_max_factor * band[1]
    p0 = np.array([model.parameters[n].value for n in names])
    lo, hi = space.theta_bounds()
    x0 = np.clip(space.to_theta(p0), lo, hi)

    def objective(
        channels: list[int], eq, base: Model = model_s, sub: ParameterSpace = space
    ) -> EqualizedFRFObjective:
        return EqualizedFRFObjective(
            base,
            sub,
            [rows[i] for i in channels],
            col,
            eq.frequency_hz,
            eq.H[:, channels],
            eq.zeta0,
            f_max,
            st.use_phase,
        )

    every = objective(list(range(len(rows))), eq)
    cal, val = split_channels(run_frfs, st.calibration_points, every, x0, st.n_calibration)
    zetas = [z for z in st.zeta0_schedule if z > zeta0] + [zeta0]
    clusters = _mode_clusters(fit.n_modes, st.n_per_band, len(cal), st.use_phase)
    nominal = {n: model.parameters[n].nominal for n in names}
    hf = _fit_determined(
        model,
        model_s,
        names,
        nominal,
        objective,
        cal,
        eq,
        fit,
        zetas,
        zeta0,
        clusters,
        st,
        run_frfs.source,
    )
    sol, precision, cov_f, estimator = _under_priors(
        model, hf, objective, cal, eq, nominal, zeta0, st
    )
    stages, held, fitted, sub, cov_d = hf.stages, hf.held, hf.fitted, hf.sub, hf.cov_d
    t_fit = time.perf_counter()

    values = {**sub.as_dict(sub.to_physical(sol.x)), **{n: nominal[n] for n in held}}
    values = {n: values[n] for n in names}
    x_all = space.to_theta([values[n] for n in names])
    jac_all = objective(cal, eq)(x_all, True)[1] if held else None
    cov = _with_held(space, x_all, fitted, cov_f, held, jac_all, model, cov_d, precision)
    status = {n: held[n]["status"] if n in held else "fitted" for n in names}
    reasons = {n: held[n]["reason"] for n in held}
    model_cal = model_s.with_values(values)
    asm_cal = model_cal.assemble()
    modes_cal = modal_analysis(asm_cal.M, asm_cal.K)
    pairs = _pair_modes(modes_cal, fit, rows, band, st.mac_min)
    unidentified = _unidentified_modes(model_cal, asm_cal, modes_cal, names, pairs, band)
    damping, out_model, zeta_std = _identified_damping(
        model, model_cal, values, fit, pairs, masses, st
    )

    def deviations(x: np.ndarray, m_: Model) -> dict[str, Any]:
        return _deviations(every, x, m_, run_frfs.channels, f, H, f_max, cal, val)

    validation = {
        "before": deviations(x0, model_s),
        "after": deviations(x_all, model_cal.with_damping(damping)),
    }
    t_end = time.perf_counter()
    log.info("linear calibration: %s, %d iterations, cost %.4g", sol.message, sol.nit, sol.cost)
    return LinearCalibration(
        x=x_all,
        cost=float(sol.cost),
        jac=sol.jac,
        cov=cov,
        nfev=sum(g["nfev"] for g in stages),
        njev=sum(g["njev"] for g in stages),
        nit=sum(g["nit"] for g in stages),
        success=sol.success,
        message=sol.message,
        names=tuple(names),
        stages=stages,
        status=status,
        status_reason=reasons,
        prior_rel_std={n: model.parameters[n].prior_rel_std for n in names},
        damping_rel_std=zeta_std,
        covariance_estimator=estimator,
        parameters=values,
        start=space.as_dict(p0),
        zeta0=zeta0,
        metric_frequency_hz=eq.frequency_hz,
        calibration_channels=tuple(run_frfs.channels[i] for i in cal),
        validation_channels=tuple(run_frfs.channels[i] for i in val),
        calibration_points=tuple(sorted({run_frfs.points[i] for i in cal})),
        validation_points=tuple(sorted({run_frfs.points[i] for i in val})),
        fit=fit,
        modes=pairs,
        validation=validation,
        model=out_model,
        settings={**st.to_json(), "zeta0_used": zeta0, "sensor_masses_kg": masses},
        source=run_frfs.source,
        timings={
            "identification_s": t_id - t0,
            "calibration_s": t_fit - t_id,
            "validation_s": t_end - t_fit,
            "total_s": t_end - t0,
        },
        unidentified_modes=unidentified,
    )


@dataclass
class _HeldFit:
    """The fit of the parameters the test determines, the others held at their nominal values
    (``held``: name -> status and reason)."""

    sol: LeastSquaresResult
    stages: list[dict]
    cov_d: np.ndarray
    estimator: str
    held: dict[str, dict[str, Any]]
    fitted: list[str]
    sub: ParameterSpace
    base: Model
    bounds: tuple[np.ndarray, np.ndarray]


def _fit_determined(
    model: Model,
    model_s: Model,
    names,
    nominal,
    objective,
    cal,
    eq,
    fit,
    zetas,
    zeta0,
    clusters,
    st,
    source: str,
) -> _HeldFit:
    """Fit, hold the first parameter the test determines worse than its prior at its nominal
    value, and fit again, until the test determines every one still fitted."""
    held: dict[str, dict[str, Any]] = {}
    while True:
        fitted = [n for n in names if n not in held]
        sub = ParameterSpace.from_model(model_s, fitted)
        base = model_s.with_values({n: nominal[n] for n in held})
        lo_f, hi_f = sub.theta_bounds()
        sol, stages = _continuation(
            lambda z, base=base, sub=sub: objective(
                cal, eq if z == zeta0 else equalize(fit, z, st.n_per_band), base, sub
            ),
            zetas,
            np.clip(sub.to_theta([model.parameters[n].value for n in fitted]), lo_f, hi_f),
            (lo_f, hi_f),
            st,
        )
        cov_d, estimator = data_covariance(sol.jac, sol.fun, clusters)
        new = {} if st.weak_parameters == "fit" else _first(decide_weak(model, sub, sol.x, cov_d))
        if not new:
            return _HeldFit(sol, stages, cov_d, estimator, held, fitted, sub, base, (lo_f, hi_f))
        held.update(new)
        if len(held) == len(names):
            raise CalibrationError(
                f"{source}: the test determines none of {names}: "
                + "; ".join(f"{n}: {h['reason']}" for n, h in held.items())
            )


def _under_priors(model: Model, hf: _HeldFit, objective, cal, eq, nominal, zeta0, st):
    """The fitted parameters under their priors (maximum a posteriori) where the model file
    gives them; returns the solution, the prior precision, the covariance and its
    estimator's description."""
    fitted, sub, sol = hf.fitted, hf.sub, hf.sol
    precision = _prior_precision(model, fitted) if st.weak_parameters == "hold" else None
    if precision is None or not precision.any():
        return sol, np.zeros(len(fitted)), hf.cov_d, hf.estimator
    # the data's weight is the one its covariance estimator gives it, so the prior counts
    # exactly as much as it should
    data_weight = _data_weight(sol, hf.cov_d)
    target = sub.to_theta([nominal[n] for n in fitted])
    sol = METHODS[st.method](
        _WithPrior(objective(cal, eq, hf.base, sub), target, precision, data_weight),
        sol.x,
        hf.bounds,
        st.max_iterations,
    )
    sol.fun = sol.fun[: -len(fitted)]
    sol.jac = sol.jac[: -len(fitted)]
    hf.stages.append(
        {
            "zeta0": zeta0,
            "prior": True,
            "cost": float(sol.cost),
            "nit": int(sol.nit),
            "nfev": int(sol.nfev),
            "njev": int(sol.njev),
            "success": bool(sol.success),
            "message": sol.message,
        }
    )
    cov_f = np.linalg.inv(np.linalg.inv(hf.cov_d) + np.diag(precision))
    return sol, precision, cov_f, hf.estimator + "; combined with the model file's priors (MAP)"


def _identified_damping(model: Model, model_cal: Model, values, fit, pairs, masses, st):
    """The identified per-mode damping, the calibrated model with it (without the sensors'
    masses unless kept) and the damping ratios' standard deviations by that model's modes."""
    damping = DampingSpec(
        default_zeta=model.damping.default_zeta,
        per_mode={pr.model_mode: pr.zeta for pr in pairs if pr.model_mode is not None},
    )
    zeta_std = {
        pr.model_mode: float(fit.x_std[fit.n_modes + pr.test_index])
        for pr in pairs
        if pr.model_mode is not None and fit.x_std is not None
    }
    if st.keep_sensor_masses or not masses:
        out_model = model_cal.with_damping(damping)
    else:
        out_model, numbers = _without_sensors(model.with_values(values), model_cal, damping)
        zeta_std = {numbers[k]: v for k, v in zeta_std.items()}
    return damping, out_model, zeta_std


# -- what the test determines -----------------------------------------------------------------
def _mode_clusters(n_modes: int, n_per_band: int, n_channels: int, use_phase: bool) -> np.ndarray:
    """The (identified mode, channel) each calibration residual belongs to (residuals are
    ordered ``(metric frequency, channel)``, the metric frequencies mode by mode, then the
    phases, which share their magnitude's cluster)."""
    by_mode = np.arange(n_modes * n_channels).reshape(n_modes, 1, n_channels)
    per = np.repeat(by_mode, n_per_band, axis=1).ravel()
    return np.concatenate([per, per]) if use_phase else per


def data_covariance(jac: np.ndarray, fun: np.ndarray, clusters: np.ndarray):
    """Covariance of a log-magnitude fit in scaled coordinates, and which estimator gave it.

    The residuals of one channel at one mode's metric frequencies all come from that mode's
    identified frequency, damping and modal constant: they are not independent, and the
    textbook ``s^2 (J^T J)^-1`` (``s^2 = 2 cost / (m - n)``) treats them as if they were. The
    cluster-robust (sandwich) estimator with one cluster per (identified mode, channel),
    ``c (J^T J)^-1 (sum_g J_g^T r_g r_g^T J_g) (J^T J)^-1`` with the small-sample factor
    ``c = G / (G - 1) (m - 1) / (m - n)`` (CR1), allows any correlation inside a mode. Each
    parameter's variance is the larger of the two (the sandwich, from few clusters, is itself
    uncertain and can come out smaller by chance); the correlations are the textbook ones.
    """
    m, n = jac.shape
    A = np.linalg.pinv(jac.T @ jac)
    s2 = float(fun @ fun) / max(m - n, 1)
    formal = A * s2
    groups = np.unique(clusters)
    G = groups.size
    if G <= n:
        return formal, f"textbook s^2 (J^T J)^-1 ({G} clusters are too few for the sandwich)"
    scores = np.array([jac[clusters == g].T @ fun[clusters == g] for g in groups])
    robust = (G / (G - 1)) * ((m - 1) / max(m - n, 1)) * (A @ (scores.T @ scores) @ A)
    scale = np.sqrt(np.maximum(np.diag(robust) / np.maximum(np.diag(formal), 1e-300), 1.0))
    return formal * np.outer(scale, scale), (
        f"per parameter the larger of the textbook s^2 (J^T J)^-1 and the cluster-robust "
        f"sandwich over {G} (identified mode, channel) clusters"
    )


def decide_weak(model: Model, space: ParameterSpace, x: np.ndarray, cov: np.ndarray) -> dict:
    """The fitted parameters to hold at their nominal value, with why.

    A parameter at a bound of its range is not a calibrated value: the fit ran out of room,
    whatever the data say. A parameter with a prior (``prior_rel_std``) of which the test
    carries less than half the information, once combined with the priors of all
    (``1 - posterior variance / prior variance < 1/2``, in scaled coordinates: relative for
    linear, of ``ln p`` for log scaling), is one the test says less about than was known
    before it: the fitted value mostly follows the noise and the other parameters' errors.
    Either is held at ``nominal``: with its prior uncertainty (``"held"``), or, without a
    prior, with none known (``"at_bound"``). ``cov`` is the data-only covariance of ``x``.
    """
    lo, hi = space.theta_bounds()
    precision = _prior_precision(model, space.names)
    post = np.linalg.inv(np.linalg.inv(cov) + np.diag(precision))
    share = 1.0 - np.diag(post) * precision  # the data's share of each parameter's information
    out: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(space.names):
        p = model.parameters[name]
        prior = p.prior_rel_std
        unit = f" {p.unit}" if p.unit else ""
        span = max(hi[i] - lo[i], 1e-12)
        side = ""
        if x[i] - lo[i] < 1e-6 * span:
            side = "lower"
        elif hi[i] - x[i] < 1e-6 * span:
            side = "upper"
        if side:
            bound = p.lower if side == "lower" else p.upper
            why = f"the fit ran to its {side} bound {bound:.4g}{unit}"
        elif prior is not None and share[i] < 0.5:
            why = (
                f"the test carries {100 * share[i]:.0f} % of its information (alone it "
                f"determines it to +-{100 * np.sqrt(cov[i, i]):.3g} %; the prior: "
                f"+-{100 * prior:.3g} %)"
            )
        else:
            continue
        held_at = f"held at its nominal {p.nominal:.4g}{unit}"
        if prior is not None:
            out[name] = {
                "status": "held",
                "reason": f"{why}: {held_at} with the prior's +-{100 * prior:.3g} %",
            }
        else:
            out[name] = {
                "status": "at_bound",
                "reason": (
                    f"{why}: {held_at}; no prior is known (give prior_rel_std in the model file), "
                    "so its uncertainty is not known"
                ),
            }
        # a bound first, then the least informed: the others are fitted again with it held
        out[name]["priority"] = (bool(side), float(1.0 - share[i]))
    return out


def _first(weak: dict) -> dict:
    """The one parameter to hold next: holding one changes what the test says of the others
    (a parameter that ran to its bound drags those it trades with along), so they are judged
    again after the refit."""
    if not weak:
        return {}
    name = max(weak, key=lambda n: weak[n]["priority"])
    return {name: {k: v for k, v in weak[name].items() if k != "priority"}}


def _prior_precision(model: Model, names) -> np.ndarray:
    """``1 / prior_rel_std^2`` per parameter in scaled coordinates (0: no prior)."""
    return np.array(
        [
            0.0
            if model.parameters[n].prior_rel_std is None
            else model.parameters[n].prior_rel_std ** -2
            for n in names
        ]
    )


def _data_weight(sol, cov_d: np.ndarray) -> float:
    """The residual scale ``w`` for which ``w^2 (J^T J)^-1`` has, on average over the
    parameters, the variance of the data covariance ``cov_d``: the data's cost divided by
    ``w^2`` is then their log-likelihood as that estimator sees it."""
    formal = np.diag(np.linalg.pinv(sol.jac.T @ sol.jac))
    return float(np.sqrt(np.mean(np.diag(cov_d) / np.maximum(formal, 1e-300))))


class _WithPrior:
    """A residual function with the priors appended: ``w (theta - target) / sigma_prior``
    per parameter (0 where no prior), so ``1/2 |r|^2 / w^2`` is the negative log posterior."""

    def __init__(self, objective, target, precision, weight) -> None:
        self.objective, self.target = objective, np.asarray(target, float)
        self.scale = weight * np.sqrt(precision)

    def __call__(self, theta, want_jac: bool = True):
        r, J = self.objective(theta, want_jac)
        rp = self.scale * (np.asarray(theta, float) - self.target)
        r = np.concatenate([r, rp])
        return r, (None if J is None else np.vstack([J, np.diag(self.scale)]))


def _with_held(space, x_all, fitted, cov_f, held, jac_all, model, cov_d, precision):
    """Physical covariance of every parameter: the fitted ones' (``cov_f``) plus what the held
    ones' prior uncertainty does to them (a held value off by ``d theta_h`` moves the fitted
    ones by ``G d theta_h``, ``G = -(cov_d^-1 + P)^-1 cov_d^-1 (J_f^T J_f)^-1 J_f^T J_h``: the
    data-only move, shrunk as the priors ``P`` shrink the fit); a held one's own variance is
    its prior's (NaN where no prior is known)."""
    names = list(space.names)
    idx_f = [names.index(n) for n in fitted]
    n = len(names)
    cov = np.zeros((n, n))
    cov[np.ix_(idx_f, idx_f)] = cov_f
    if held:
        idx_h = [names.index(h) for h in held]
        prior = np.array([model.parameters[h].prior_rel_std or np.nan for h in held])
        known = np.isfinite(prior)
        Jf, Jh = jac_all[:, idx_f], jac_all[:, idx_h]
        move = np.linalg.lstsq(Jf, Jh, rcond=None)[0]
        G = -cov_f @ np.linalg.solve(cov_d, move)
        S = np.diag(np.where(known, prior, 0.0) ** 2)
        cov[np.ix_(idx_f, idx_f)] += G @ S @ G.T
        cov[np.ix_(idx_f, idx_h)] = G @ S
        cov[np.ix_(idx_h, idx_f)] = S @ G.T
        cov[np.ix_(idx_h, idx_h)] = S + np.diag(np.where(known, 0.0, np.nan))
    D = space.dp_dtheta(x_all)
    return cov * np.outer(D, D)


# -- helpers ------------------------------------------------------------------------------
_IDENTIFIED: dict[bytes, ModalFit] = {}
_N_IDENTIFIED = 8


def _identify(f, H, band, sH, g2) -> ModalFit:
    """The run's modes (weighted by the H1 standard errors, starting poles by the coherence:
    the noisy lines away from the resonances must not pull the poles), remembered by their
    inputs: a diagnosis recalibrates dozens of candidate models on one run, and the modes of
    the measurement do not depend on the model (a :class:`ModalFit` is read-only)."""
    h = hashlib.sha1()
    for a in (f, H, sH, g2, np.asarray(band, dtype=float)):
        h.update(np.ascontiguousarray(a).tobytes())
    key = h.digest()
    if key not in _IDENTIFIED:
        if len(_IDENTIFIED) >= _N_IDENTIFIED:
            _IDENTIFIED.pop(next(iter(_IDENTIFIED)))
        _IDENTIFIED[key] = identify_modes(
            f, H, band, weights=1.0 / np.maximum(sH, 1e-300), start_weights=g2
        )
    return _IDENTIFIED[key]


def _continuation(make_objective, zetas, x0, bounds, st):
    """Solve stage by stage over ``zetas``; the last stage's solution and every stage's record."""
    x, stages, sol = x0, [], None
    for z in zetas:
        sol = METHODS[st.method](make_objective(z), x, bounds, st.max_iterations)
        x = sol.x
        stages.append(
            {
                "zeta0": z,
                "cost": float(sol.cost),
                "nit": int(sol.nit),
                "nfev": int(sol.nfev),
                "njev": int(sol.njev),
                "success": bool(sol.success),
                "message": sol.message,
            }
        )
        log.info("zeta0 = %.4g: cost %.4g after %d iterations", z, sol.cost, sol.nit)
    return sol, stages


def _parameter_names(model: Model, names: Sequence[str] | None) -> list[str]:
    names = list(names) if names is not None else model.parameter_names("linear", True)
    if not names:
        raise CalibrationError(f"{model.source}: no linear parameter is flagged calibrate")
    for n in names:
        if n not in model.parameters:
            raise CalibrationError(f"unknown parameter {n!r}; known: {sorted(model.parameters)}")
        if model.parameters[n].group != "linear":
            raise CalibrationError(
                f"parameter {n!r} is in group {model.parameters[n].group!r}; the linear "
                "calibration calibrates group 'linear' only"
            )
    return names


def _band(run: RunFRFs, st: LinearCalibrationSettings):
    f = run.frequency_hz
    band = st.band_hz or (float(f.min()), float(f.max()))
    keep = (f >= band[0]) & (f <= band[1])
    if st.min_coherence > 0:
        keep &= np.min(run.coherence, axis=1) >= st.min_coherence
    if np.count_nonzero(keep) < 16:
        raise CalibrationError(
            f"{run.source}: only {np.count_nonzero(keep)} frequencies in {band[0]:g}-"
            f"{band[1]:g} Hz (with coherence >= {st.min_coherence:g})"
        )
    return f[keep], run.H[keep], run.std()[keep], run.coherence[keep], band


def _pair_modes(modes, fit, rows: list[int], band, mac_min: float):
    q = max(int(np.count_nonzero(modes.frequency_hz <= 2 * band[1])), fit.n_modes)
    return match_modes(
        fit.frequency_hz, fit.zeta, fit.a.T, modes.frequency_hz[:q], modes.phi[rows, :q], mac_min
    )


def _unidentified_modes(model: Model, asm, modes, names, pairs, band) -> list[dict[str, Any]]:
    """The model's modes in ``band`` without a paired test mode, with ``d ln f / d ln p``
    (``asm`` and ``modes``: the model's assembly and modal analysis)."""
    paired = {pr.model_mode - 1 for pr in pairs if pr.model_mode is not None}  # 1-based
    idx = [
        i for i, f in enumerate(modes.frequency_hz) if band[0] <= f <= band[1] and i not in paired
    ]
    if not idx:
        return []
    dlam, _ = mode_sensitivities(
        asm.M,
        asm.K,
        modes,
        {n: asm.dM[n] for n in names},
        {n: asm.dK[n] for n in names},
        which=np.array(idx),
    )
    lam = modes.omega**2
    return [
        {
            "model_mode": int(i) + 1,
            "frequency_hz": float(modes.frequency_hz[i]),
            "sensitivity": {
                n: float(0.5 * dlam[n][j] / lam[i] * model.parameters[n].value) for n in names
            },
        }
        for j, i in enumerate(idx)
    ]


def _without_sensors(bare: Model, loaded: Model, damping: DampingSpec):
    """``bare`` with ``damping``'s mode numbers (of ``loaded``) carried over by MAC, and the
    carried numbers (``loaded``'s mode -> ``bare``'s)."""
    a, b = loaded.assemble(), bare.assemble()
    numbers = renumber_modes(a.M, a.K, b.M, b.K, list(damping.per_mode))
    per_mode = dict(zip(numbers, damping.per_mode.values(), strict=True))
    return bare.with_damping(DampingSpec(damping.default_zeta, per_mode)), dict(
        zip(damping.per_mode, numbers, strict=True)
    )


def _rms(x: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(x**2))) if x.size else None


def _deviations(obj, x, model, channels, f, H, f_max, cal, val) -> dict[str, Any]:
    """Log10-magnitude deviations, equalized at the metric frequencies and over the band."""
    r = obj.residuals(x)[: obj.target.size].reshape(obj.target.shape)
    values = obj.space.as_dict(obj.space.to_physical(x))
    Hm = receptance(model.with_values(values), obj.rows, obj.col, f, f_max_hz=f_max)
    d = np.log10(np.abs(Hm)) - np.log10(np.abs(H))
    out = {}
    for key, dev in (("equalized", r), ("measured", d)):
        out[key] = {
            "calibration": _rms(dev[:, cal]),
            "validation": _rms(dev[:, val]),
            "per_channel": {ch: _rms(dev[:, i]) for i, ch in enumerate(channels)},
        }
    return out
