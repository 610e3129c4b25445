"""Linear candidates on the linear (random-excitation) test.

A missing mass, spring or compliant joint changes the structure at every level, so the linear
test sees it, and the paper's linear calibration, which does not have it, absorbs it into the
wrong parameters (a frame stiffness, a corner density). Each linear candidate that changes the
mass or stiffness matrices is added to the model, and the model's linear parameters are
recalibrated with it on the linear test (damping equalization,
:func:`analysis.calibration.linear.calibrate_linear`, from the current values). The candidates
are ranked by BIC of the linear metric against the model recalibrated alone; a candidate that
earns its parameter there is verified on the stepped sine with those recalibrated values.

Jobs are picklable (:class:`LinearJob`) so they run on any executor.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.diagnosis.candidates import Candidate
from analysis.events import Listener, StageDone
from analysis.measurement_file import read_measurement
from analysis.model import Model

__all__ = [
    "LINEAR_SCREEN_KINDS",
    "LinearFit",
    "LinearJob",
    "linear_screen",
    "run_linear_job",
    "seen_by_linear_test",
]

log = logging.getLogger(__name__)

#: Candidate kinds that change the mass or stiffness matrices (what the linear test sees).
LINEAR_SCREEN_KINDS = ("mass", "linear_spring", "joint_spring")

#: Start values of a linear candidate's parameters (a spring's: :data:`SPRING_START` of the
#: structure's own stiffness where it acts).
START = {"m": 0.01, "k": 1e3, "k_joint": 1e6}

#: A spring candidate starts at this share of the static stiffness of the structure at its
#: place (``1 / d' K^-1 d``, ``d`` its incidence); its bounds (0 to 1000 times the start, as
#: every new linear coefficient's) then reach ten times that stiffness, where a spring acts
#: as a support.
SPRING_START = 0.01


@dataclass(frozen=True)
class LinearJob:
    """One linear calibration: the model (as model-file text) with ``candidate`` (or none)."""

    model_toml: str
    source: str
    run_path: str
    candidate: Candidate | None


@dataclass
class LinearFit:
    """A model recalibrated on the linear test, with or without a candidate.

    Attributes
    ----------
    candidate : Candidate or None
        None: the model's own linear parameters only.
    cost : float
        ``1/2 sum r^2`` of the linear metric (log10 magnitude).
    n, k : int
        Residuals and fitted parameters.
    bic : float
    delta_bic : float
        BIC minus that of the model recalibrated alone (set by :func:`linear_screen`).
    values : dict
        Candidate parameters (model names) at the optimum.
    parameters : dict
        Every recalibrated parameter.
    model_toml : str
        The recalibrated model (identified modal damping included).
    seconds : float
    message : str
        Why a fit failed (empty otherwise).
    """

    candidate: Candidate | None
    cost: float
    n: int
    k: int
    bic: float
    delta_bic: float = math.nan
    values: dict[str, float] = field(default_factory=dict)
    parameters: dict[str, float] = field(default_factory=dict)
    model_toml: str = ""
    seconds: float = 0.0
    message: str = ""

    @property
    def failed(self) -> bool:
        return not math.isfinite(self.bic)

    def model(self) -> Model:
        return Model.from_toml_text(self.model_toml, "<linear recalibration>")


def _bic(cost: float, n: int, k: int) -> float:
    rss = max(2.0 * cost, 1e-300)
    return n * math.log(rss / n) + k * math.log(n)


def seen_by_linear_test(cand: Candidate, model: Model) -> bool:
    """Whether ``cand`` changes the mass or stiffness matrices of ``model`` (what the linear
    test sees): a mass, a compliant joint, a spring of a frame model (a model given by
    matrices takes a spring only as an element of the balance)."""
    if cand.law.kind == "linear_spring":
        return model.frame is not None
    return cand.law.kind in LINEAR_SCREEN_KINDS


def local_stiffness(model: Model, cand: Candidate) -> float:
    """Static stiffness of the structure at ``cand``'s first incidence, ``1 / d' K^-1 d``
    (``d`` the unit relative displacement there) [N/m or N m/rad]."""
    asm = model.assemble()
    at, to = cand.location.incidences[0]
    d = np.zeros(asm.K.shape[0])
    d[asm.dof_index(at.node, at.direction)] = 1.0
    if to is not None:
        d[asm.dof_index(to.node, to.direction)] -= 1.0
    return 1.0 / float(d @ np.linalg.solve(asm.K, d))


def run_linear_job(job: LinearJob) -> LinearFit:
    """Recalibrate one model on the linear test (top level, so executors can run it)."""
    from analysis.calibration.linear import calibrate_linear

    t0 = time.perf_counter()
    cand = job.candidate
    try:
        model = Model.from_toml_text(job.model_toml, job.source)
        new: list[str] = []
        if cand is not None:
            names = cand.parameter_names()
            start = {p: START.get(p, 1.0) for p in names}
            if cand.law.kind == "linear_spring":
                start["k"] = SPRING_START * local_stiffness(model, cand)
            model, new = cand.apply(model, start)
        names = tuple(model.parameter_names(group="linear", calibrate=True))
        run = read_measurement(job.run_path)
        # every candidate fits the same parameters, or their costs do not compare
        res = calibrate_linear(
            model,
            run,
            parameters=names,
            min_modes=min(4, len(names)),
            zeta0_schedule=(),
            weak_parameters="fit",
        )
        n, k = int(res.jac.shape[0]), len(names)
        return LinearFit(
            cand,
            float(res.cost),
            n,
            k,
            _bic(float(res.cost), n, k),
            values={p: float(res.parameters[p]) for p in new if p in res.parameters},
            parameters=dict(res.parameters),
            model_toml=res.model.to_toml(),
            seconds=time.perf_counter() - t0,
        )
    except Exception as exc:  # a worker must return, whatever the candidate does
        label = "the model" if cand is None else cand.label
        log.warning("linear recalibration of %s failed: %s", label, exc)
        return LinearFit(
            cand, math.inf, 0, 0, math.inf, message=str(exc), seconds=time.perf_counter() - t0
        )


def linear_screen(
    model: Model,
    run_path: str,
    candidates: Sequence[Candidate],
    *,
    executor=None,
    progress: Listener | None = None,
) -> tuple[LinearFit, list[LinearFit]]:
    """Recalibrate the model alone and with each linear candidate on the linear test.

    Parameters
    ----------
    model : Model
    run_path : str
        The random-excitation file.
    candidates : sequence of Candidate
        Those the linear test sees (:func:`seen_by_linear_test`) are tried (one mass, spring
        or compliant joint each; a released joint is tried once, whatever law it carries).
    executor : Executor, optional
        Default: in this process.

    Returns
    -------
    base : LinearFit
        The model's own linear parameters recalibrated.
    fits : list of LinearFit
        Every candidate, best (lowest BIC) first, ``delta_bic`` against ``base``.
    """
    from analysis.executors import run_jobs

    cands = [c for c in candidates if seen_by_linear_test(c, model)]
    text, source = model.to_toml(), str(model.source)
    jobs = [LinearJob(text, source, str(run_path), None)]
    jobs += [LinearJob(text, source, str(run_path), c) for c in cands]
    if executor is None:
        done = [run_linear_job(j) for j in jobs]
    else:
        done = run_jobs(run_linear_job, jobs, executor)
    base, fits = done[0], done[1:]
    for f in fits:
        f.delta_bic = f.bic - base.bic
    fits.sort(key=lambda f: f.bic)
    if progress:
        progress(StageDone("linear screen", count=len(fits), cost=base.cost))
    return base, fits
