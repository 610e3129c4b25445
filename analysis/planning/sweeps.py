"""The expensive part of a plan: one stepped MHB sweep with sensitivities per job.

A :class:`SweepJob` is one (actuator, level, frequency range): the stepped sweep a test would
run, with outputs at every candidate sensor and the exact derivatives of the output phasors
with respect to the planned parameters (implicit differentiation at each converged step).
Jobs carry the model as its TOML text, so they pickle and run in any process; each process
re-creates the model and its linear part once and caches them. The result does not depend on
the noise model or on parameter scaling, so a plan can be re-ranked without new sweeps.
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections import OrderedDict
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from analysis.mhb.sensitivity import parameter_names, point_sensitivities
from analysis.mhb.sweep import solve_steps
from analysis.model import Model
from analysis.system import DEFAULT_HARMONICS, DEFAULT_TIME_SAMPLES, build_linear, build_problem

__all__ = ["SweepJob", "SweepSensitivities", "run_sweep"]

log = logging.getLogger(__name__)

_CACHE_SIZE = 4
_models: OrderedDict[tuple[str, float], tuple[Model, object]] = OrderedDict()
_problems: OrderedDict[tuple, object] = OrderedDict()


@dataclass(frozen=True)
class SweepJob:
    """One stepped sweep to solve: picklable, self-contained.

    Parameters
    ----------
    model_toml : str
        The model as model-file text (``Model.to_toml()``), values included.
    actuator : int
        Drive point.
    force : tuple of complex
        Force phasor per order [N].
    frequencies_hz : tuple of float
        Fundamental frequencies in stepping order [Hz].
    sensors : tuple of int
        Output points.
    parameters : tuple of str
        Parameters to differentiate with respect to.
    orders : tuple of Fraction
    n_harmonics, n_time : int
        Harmonics of the base and AFT samples per period.
    f_max_hz : float
        Highest retained mode of the linear part [Hz].
    key : tuple of int
        Caller's bookkeeping (e.g. actuator, level and range indices); returned unchanged.
    """

    model_toml: str
    actuator: int
    force: tuple[complex, ...]
    frequencies_hz: tuple[float, ...]
    sensors: tuple[int, ...]
    parameters: tuple[str, ...]
    orders: tuple[Fraction, ...] = (Fraction(1), Fraction(2), Fraction(3))
    n_harmonics: int = DEFAULT_HARMONICS
    n_time: int = DEFAULT_TIME_SAMPLES
    f_max_hz: float = 2000.0
    key: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if len(self.force) != len(self.orders):
            raise ValueError(
                f"SweepJob.force: {len(self.force)} phasors for {len(self.orders)} orders"
            )
        if not self.frequencies_hz or min(self.frequencies_hz) <= 0:
            raise ValueError("SweepJob.frequencies_hz: give positive frequencies")


@dataclass(frozen=True)
class SweepSensitivities:
    """Output phasors and their parameter derivatives along one sweep (converged steps only).

    Attributes
    ----------
    key : tuple of int
        The job's key.
    frequency_hz : ndarray, shape (n_steps,), Hz
        Fundamental of each converged step.
    force : ndarray, shape (n_orders,), complex, N
        Force phasor per order.
    order_values : ndarray, shape (n_orders,)
        The orders as numbers (order ``nu`` is at ``nu * frequency_hz``).
    outputs : ndarray, shape (n_steps, n_orders, n_sensors), complex, m
        Displacement phasors at the sensors.
    d_outputs : ndarray, shape (n_steps, n_orders, n_sensors, n_params), complex
        Their derivatives [m per parameter unit].
    failed_hz : tuple of float
        Steps that did not converge (left out above).
    elapsed_s : float
        Wall time of the sweep and its sensitivities [s].
    """

    key: tuple[int, ...]
    frequency_hz: np.ndarray
    force: np.ndarray
    order_values: np.ndarray
    outputs: np.ndarray
    d_outputs: np.ndarray
    failed_hz: tuple[float, ...]
    elapsed_s: float

    def __post_init__(self) -> None:
        for name in ("frequency_hz", "force", "order_values", "outputs", "d_outputs"):
            a = np.array(getattr(self, name))
            a.setflags(write=False)
            object.__setattr__(self, name, a)


def _lru_put(cache: OrderedDict, key, value) -> None:
    cache[key] = value
    if len(cache) > _CACHE_SIZE:
        cache.popitem(last=False)


def _model(text: str, f_max_hz: float) -> tuple[str, Model, object]:
    """The model and its linear part for a TOML text, built once per process."""
    key = (hashlib.sha256(text.encode()).hexdigest(), float(f_max_hz))
    if key not in _models:
        model = Model.from_toml_text(text, "<plan job>")
        _lru_put(_models, key, (model, build_linear(model, f_max_hz=f_max_hz)))
    _models.move_to_end(key)
    model, linear = _models[key]
    return key[0], model, linear


def _problem(job: SweepJob):
    digest, model, linear = _model(job.model_toml, job.f_max_hz)
    key = (digest, job.f_max_hz, job.actuator, job.sensors, job.orders, job.n_harmonics, job.n_time)
    if key not in _problems:
        problem = build_problem(
            model,
            drive_point=job.actuator,
            output_points=job.sensors,
            orders=job.orders,
            n_harmonics=job.n_harmonics,
            n_time=job.n_time,
            f_max_hz=job.f_max_hz,
            linear=linear,
        )
        known = set(parameter_names(problem))
        unknown = [p for p in job.parameters if p not in known]
        if unknown:
            raise ValueError(
                f"cannot plan for parameter(s) {unknown}: the model's element-mapped and "
                f"structural parameters are {sorted(known)}"
            )
        _lru_put(_problems, key, problem)
    _problems.move_to_end(key)
    return _problems[key]


def run_sweep(job: SweepJob) -> SweepSensitivities:
    """Solve one stepped sweep and the sensitivities of every converged step.

    A top-level function of a job spec, so any ``concurrent.futures.Executor`` can run it.

    Returns
    -------
    SweepSensitivities
    """
    t0 = time.perf_counter()
    problem = _problem(job)
    f = np.asarray(job.frequencies_hz, dtype=float)
    force = np.asarray(job.force, dtype=complex)
    sweep = solve_steps(problem, 2 * np.pi * f, force)
    params = list(job.parameters)
    keep, outs, douts, failed = [], [], [], []
    for i, point in enumerate(sweep.points):
        if not point.converged:
            failed.append(float(f[i]))
            continue
        sens = point_sensitivities(problem, point, params)
        keep.append(i)
        outs.append(point.outputs())
        douts.append(np.stack([sens[p].d_outputs(problem.order_k) for p in params], axis=-1))
    n_o, n_s, n_p = len(job.orders), len(job.sensors), len(params)
    if failed:
        log.warning(
            "sweep at actuator %d, %.3g N: %d step(s) did not converge and carry no information",
            job.actuator,
            abs(force[0]),
            len(failed),
        )
    return SweepSensitivities(
        key=tuple(job.key),
        frequency_hz=f[keep],
        force=force,
        order_values=np.array([float(o) for o in job.orders]),
        outputs=np.array(outs).reshape(len(keep), n_o, n_s),
        d_outputs=np.array(douts).reshape(len(keep), n_o, n_s, n_p),
        failed_hz=tuple(failed),
        elapsed_s=time.perf_counter() - t0,
    )
