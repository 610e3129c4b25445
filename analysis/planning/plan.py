"""Pretest planning by the Fisher information matrix: the public entry point.

>>> from analysis.model import load_model
>>> from analysis.planning import PAPER_LINEAR, plan_tests, quick_candidates
>>> model = load_model().with_values(PAPER_LINEAR)   # Table 2 linear values, nominal contact
>>> result = plan_tests(model, quick_candidates(), executor=None)  # doctest: +SKIP
>>> print(result.format_table())                                   # doctest: +SKIP

The work is split where it is cheap to combine: a configuration's information is a sum of
(actuator, level, range, sensor) contributions, so each of the ``n_act x n_lev x n_rng``
stepped sweeps is solved once (outputs at every candidate sensor, exact sensitivities), on any
``concurrent.futures.Executor``; then all configurations are ranked by batched sums and
determinants of ``p x p`` blocks (:mod:`analysis.planning.ranking`).

References
----------
Y. Chen, A. Linderholt, T. Abrahamsson, Y. Xia, M. I. Friswell, ISMA 2016, sec. 2.1 and 3.3.1.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from analysis.executors import open_executor, run_jobs
from analysis.model import Model
from analysis.paper import PAPER_LINEAR
from analysis.planning.candidates import Candidates, Configuration, NoiseModel, paper_candidates
from analysis.planning.information import (
    correlation_indices,
    information_blocks,
    whitened_jacobian,
)
from analysis.planning.ranking import (
    combinations,
    configuration_at,
    configuration_index,
    log10_determinants,
    rank,
)
from analysis.planning.result import Correlations, PlanResult, RankedConfiguration
from analysis.planning.sweeps import SweepJob, SweepSensitivities, run_sweep
from analysis.system import DEFAULT_HARMONICS, DEFAULT_TIME_SAMPLES

__all__ = ["PAPER_LINEAR", "PlanSettings", "configuration_study", "parameter_scales", "plan_tests"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanSettings:
    """Numerical settings of a plan.

    Parameters
    ----------
    n_harmonics, n_time : int
        Harmonics of the base and AFT samples (the analysis defaults, validated on the rig).
    f_max_hz : float
        Highest retained mode of the linear part [Hz].
    parameter_scales : mapping of str to float, optional
        ``s_i`` of the scaled parameters ``theta_i = P_i / s_i`` in which the blocks are
        formed and ranked (default: the parameter's value, else its nominal, else 1).
        ``det FIM_P = det FIM_theta / prod(s_i)^2`` for every configuration, so the ranking
        is the same in any scaling and the reported determinants are in physical units.
    top : int
        Configurations listed in the result's table.
    refine_band_hz : (float, float) or None
        Band [Hz] refined in the correlation study of the chosen configuration (the paper's
        24-28 Hz around the first resonance); None skips it, as does a band outside the
        chosen range.
    refine_step_hz : float
        Step inside the band [Hz] (the paper's 0.1 Hz).
    """

    n_harmonics: int = DEFAULT_HARMONICS
    n_time: int = DEFAULT_TIME_SAMPLES
    f_max_hz: float = 2000.0
    parameter_scales: Mapping[str, float] | None = None
    top: int = 5
    refine_band_hz: tuple[float, float] | None = (24.0, 28.0)
    refine_step_hz: float = 0.1

    def __post_init__(self) -> None:
        for name in ("n_harmonics", "n_time", "top"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"PlanSettings.{name}: must be an integer >= 1, got {v!r}")
        if not (math.isfinite(self.f_max_hz) and self.f_max_hz > 0):
            raise ValueError(f"PlanSettings.f_max_hz: must be > 0, got {self.f_max_hz!r}")
        if not (math.isfinite(self.refine_step_hz) and self.refine_step_hz > 0):
            raise ValueError(f"PlanSettings.refine_step_hz: must be > 0, got {self.refine_step_hz}")
        if self.parameter_scales is not None:
            scales = {}
            for k, v in dict(self.parameter_scales).items():
                if (
                    isinstance(v, bool)
                    or not isinstance(v, int | float)
                    or not (math.isfinite(v) and v != 0)
                ):
                    raise ValueError(f"PlanSettings.parameter_scales[{k!r}]: finite, non-zero")
                scales[k] = float(v)
            object.__setattr__(self, "parameter_scales", scales)


def parameter_scales(
    model: Model, names: tuple[str, ...], given: Mapping[str, float] | None = None
) -> np.ndarray:
    """Scales ``s_i`` of ``theta_i = P_i / s_i``, shape (p,), parameter units."""
    given = given or {}
    out = []
    for n in names:
        p = model.parameters[n]
        out.append(given.get(n) or abs(p.value) or abs(p.nominal) or 1.0)
    return np.array(out, dtype=float)


def _check(model: Model, candidates: Candidates) -> None:
    for name in ("sensors", "actuators"):
        unknown = sorted(set(getattr(candidates, name)) - set(model.points))
        if unknown:
            raise ValueError(
                f"Candidates.{name}: unknown measurement point(s) {unknown}; "
                f"the model has {sorted(model.points)}"
            )
    unknown = sorted(set(candidates.parameters) - set(model.parameters))
    if unknown:
        raise ValueError(
            f"Candidates.parameters: unknown parameter(s) {unknown}; "
            f"the model has {sorted(model.parameters)}"
        )


def _job(text, cand, settings, actuator, level, frange, sensors, key=()) -> SweepJob:
    return SweepJob(
        model_toml=text,
        actuator=actuator,
        force=tuple(complex(v) for v in cand.force(level)),
        frequencies_hz=tuple(float(f) for f in frange.frequencies_hz()),
        sensors=tuple(sensors),
        parameters=cand.parameters,
        orders=cand.orders,
        n_harmonics=settings.n_harmonics,
        n_time=settings.n_time,
        f_max_hz=settings.f_max_hz,
        key=key,
    )


def configuration_study(
    sweeps: list[SweepSensitivities],
    sweep_sensors: tuple[int, ...],
    sensors: tuple[int, ...],
    noise: NoiseModel,
    scales: np.ndarray,
    step_plan: str,
) -> Correlations:
    """FIM, inverse and correlation indices of one configuration from its sweeps.

    Parameters
    ----------
    sweeps : list of SweepSensitivities
        One per level of the configuration.
    sweep_sensors : tuple of int
        The sweeps' output points; ``sensors`` (the configuration's) must be among them.
    scales : ndarray, shape (p,)
    """
    J = whitened_jacobian(sweeps, sweep_sensors, sensors, noise, scales)
    fim_theta = J.T @ J
    Jf = whitened_jacobian(sweeps, sweep_sensors, sensors, NoiseModel.uniform_frf(), scales)
    s = np.asarray(scales)
    try:
        inv = s[:, None] * np.linalg.inv(fim_theta) * s[None, :]
    except np.linalg.LinAlgError:
        inv = np.full_like(fim_theta, np.nan)
    return Correlations(
        step_plan=step_plan,
        n_steps=int(np.mean([sw.frequency_hz.size for sw in sweeps])) if sweeps else 0,
        fim=fim_theta / np.outer(s, s),
        fim_inverse=inv,
        mac=correlation_indices(fim_theta),
        mac_frf=correlation_indices(Jf.T @ Jf),
    )


def plan_tests(
    model: Model,
    candidates: Candidates | None = None,
    noise: NoiseModel | None = None,
    settings: PlanSettings | None = None,
    *,
    executor: Executor | str | None = "process",
    workers: int | None = None,
    chosen: Configuration | None = None,
) -> PlanResult:
    """Rank every candidate test configuration by ``det(FIM)`` and study the chosen one.

    Parameters
    ----------
    model : Model
        The model at the planning point (calibrated linear part, nominal nonlinear values).
    candidates : Candidates, optional
        Default: the paper's (:func:`paper_candidates`, 14 700 configurations).
    noise : NoiseModel, optional
        Default ``NoiseModel()``: 2 % of the acceleration phasor with a 0.01 m/s^2 floor.
    settings : PlanSettings, optional
    executor : Executor, "process" or None
        Where the sweeps run: any ``concurrent.futures.Executor`` (not shut down here, e.g.
        a Dask ``Client(address).get_executor()``: trusted clusters only, Dask moves pickles),
        ``"process"`` for a local process pool of ``workers`` processes made and shut down
        here, or ``None`` for serial in this process.
    workers : int, optional
        Processes of the ``"process"`` pool (default: the CPU count).
    chosen : Configuration, optional
        The configuration to study (FIM^-1, correlations, refinement); default the best.

    Returns
    -------
    PlanResult
    """
    t_start = time.perf_counter()
    cand = candidates or paper_candidates()
    noise = noise or NoiseModel()
    st = settings or PlanSettings()
    _check(model, cand)
    if isinstance(executor, str):
        if executor != "process":
            raise ValueError(f"executor: an Executor, 'process' or None, got {executor!r}")
        with open_executor(workers) as ex:
            return plan_tests(model, cand, noise, st, executor=ex, chosen=chosen)
    params = cand.parameters
    scales = parameter_scales(model, params, st.parameter_scales)
    text = model.to_toml()
    sensors = cand.sensors
    jobs = [
        _job(text, cand, st, act, lev, rng, sensors, key=(a, i, r))
        for a, act in enumerate(cand.actuators)
        for i, lev in enumerate(cand.levels_n)
        for r, rng in enumerate(cand.ranges)
    ]
    log.info("planning: %d sweeps for %d configurations", len(jobs), cand.n_configurations)
    sweeps = run_jobs(run_sweep, jobs, executor)
    t_sweeps = time.perf_counter()

    p = len(params)
    blocks = np.zeros(
        (len(cand.actuators), len(cand.levels_n), len(cand.ranges), len(sensors), p, p)
    )
    by_key = {}
    for sw in sweeps:
        blocks[sw.key] = information_blocks(sw, sensors, noise, scales)
        by_key[sw.key] = sw
    _, lev_ind = combinations(len(cand.levels_n), cand.n_levels)
    _, sen_ind = combinations(len(sensors), cand.n_sensors)
    ranking, _ = rank(blocks, lev_ind, sen_ind)
    offset = float(-2.0 * np.log10(np.abs(scales)).sum())
    t_rank = time.perf_counter()

    def ranked(flat: int) -> RankedConfiguration:
        pos = int(np.flatnonzero(ranking.order == flat)[0]) + 1
        ld = float(ranking.log10_det[flat])
        return RankedConfiguration(pos, configuration_at(cand, flat), ld + offset, ld)

    n_top = min(st.top, int(np.isfinite(ranking.log10_det).sum()))
    top = tuple(ranked(int(i)) for i in ranking.order[:n_top])
    if chosen is None:
        best = ranked(int(ranking.order[0]))
    else:
        flat = configuration_index(cand, chosen)
        best = ranked(flat) if flat is not None else None
    config = chosen if chosen is not None else best.configuration
    study, refined, extra = _study(text, cand, st, noise, scales, config, by_key, executor)
    if best is None:
        ld = float(log10_determinants(study.fim))
        best = RankedConfiguration(None, config, ld, ld - offset)
    t_end = time.perf_counter()

    per_range = ranking.log10_det.reshape(ranking.shape).max(axis=(0, 2, 3)) + offset
    return PlanResult(
        parameters=params,
        units=tuple(model.parameters[n].unit for n in params),
        scales=scales,
        candidates=cand,
        noise=noise,
        ranking=ranking,
        top=top,
        chosen=best,
        correlations=study,
        refined=refined,
        best_by_range={r.label: float(v) for r, v in zip(cand.ranges, per_range, strict=True)},
        n_sweeps=len(sweeps) + len(extra),
        n_steps=sum(sw.frequency_hz.size for sw in sweeps + extra),
        failed_steps=sum(len(sw.failed_hz) for sw in sweeps + extra),
        timings={
            "sweeps": t_sweeps - t_start,
            "ranking": t_rank - t_sweeps,
            "study": t_end - t_rank,
            "total": t_end - t_start,
        },
    )


def _study(text, cand, st, noise, scales, config, by_key, executor):
    """Correlations of the chosen configuration, as planned and with refined steps."""
    rng = config.frequency_range
    sensors = cand.sensors
    extra: list[SweepSensitivities] = []
    solved = (
        config.actuator in cand.actuators
        and rng in cand.ranges
        and set(config.levels_n) <= set(cand.levels_n)
        and set(config.sensors) <= set(cand.sensors)
    )
    if solved:
        a, r = cand.actuators.index(config.actuator), cand.ranges.index(rng)
        sweeps = [by_key[(a, cand.levels_n.index(v), r)] for v in config.levels_n]
    else:
        sensors = config.sensors
        jobs = [_job(text, cand, st, config.actuator, v, rng, sensors) for v in config.levels_n]
        sweeps = run_jobs(run_sweep, jobs, executor)
        extra += sweeps
    study = configuration_study(sweeps, sensors, config.sensors, noise, scales, rng.label)
    refined = None
    band = st.refine_band_hz
    if band is not None and rng.overlaps(band):
        fine = rng.refined(band, st.refine_step_hz)
        jobs = [
            _job(text, cand, st, config.actuator, v, fine, config.sensors) for v in config.levels_n
        ]
        fine_sweeps = run_jobs(run_sweep, jobs, executor)
        extra += fine_sweeps
        refined = configuration_study(
            fine_sweeps, config.sensors, config.sensors, noise, scales, fine.label
        )
    elif band is not None:
        log.info("refinement band %s Hz lies outside the chosen range %s", band, rng.label)
    return study, refined, extra
