"""Which physical effect is missing? Compare, read the evidence, screen, verify, rank.

>>> result = diagnose(model, data, linear_run="linear.h5")      # doctest: +SKIP
>>> print(result.summary())                                       # doctest: +SKIP

1. **Compare** the calibrated model with the file on the measured branch
   (:func:`~analysis.diagnosis.compare.compare`). A model within ``adequate_rms`` of the noise
   is adequate: nothing is claimed.
2. **Evidence**: the signature tests (:mod:`analysis.diagnosis.signatures`), in words.
3. In parallel: the model's **own parameters recalibrated** on the stepped sine (the baseline
   every candidate must beat; if it reaches the noise the model was only mis-calibrated and
   nothing is claimed; if it brings the residual to ``rescreen_ratio`` of the calibrated
   model's or below, the calibration was a poor start and the screen runs again from the
   recalibrated model, which the verifications then start from), each **linear candidate**
   (mass, spring, compliant joint) on the linear test with the linear parameters recalibrated
   (:mod:`analysis.diagnosis.linear_screen`), and the **screen** of every law of the element
   library at every plausible location by the harmonic-domain force estimate
   (:mod:`analysis.diagnosis.screen`), ranked by BIC.
4. **Verify** a short list in the full model (:mod:`analysis.diagnosis.verify`): the best
   distinct laws of the screen (the best one also at its second location: neighbours tie in
   a screen), the linear candidates that earn their parameter on the linear test, and the
   best picks at unmeasured locations (a group of springs, a joint); each recalibrated by
   Levenberg-Marquardt from the screen's (or the linear test's) values, at most ``workers``
   at a time. The picks at unmeasured locations are dropped once a verified candidate
   is at the noise or the stage's verifications have made ``budget_evaluations``
   evaluations of the objective. A fit that went most of the way but not to the explained
   level goes on with its weights recomputed as soon as it finishes (beside the stage's last
   verifications); if none explains it, so do, while allowance is left, those stopped at
   their allowance while still falling fast.
   Then, if the best sits at a measured point and explains the misfit or went most of the
   way, its law at the screen's next measured points, started from its fit (a neighbour can
   explain a strong effect nearly to the noise), or, at an unmeasured location, the
   simplest of the next laws there (look-alike laws there screen alike). Then, if the best
   explains the misfit or went most of the way, its law at its look-alike places (a
   group's springs each alone, a point's elements to the nodes near it, ...: see
   :func:`look_alike_places`), from its fit; should one of them be the best, the walk above
   from there. If none explains it, then, while allowance is left, the next laws, the best
   of each law family the evidence points at, and further starts for the best two. Every
   limit counts work (iterations, evaluations of the objective), never time: the same data
   and settings give the same diagnosis on any machine, however busy.
5. **Rank** the verified candidates by BIC on the same steps against the recalibrated model;
   candidates within ``tie_bic`` of the best form a tied group, ordered by BIC. The effect
   is *explained* when the best brings the residual to ``explained_rms`` of the noise;
   otherwise nothing in the library explains it and the tool says so, with what the data
   show about the missing law at the best candidate's location (its describing function
   against the amplitude, :mod:`analysis.diagnosis.readout`). For a group, the
   measurement that would separate its members is computed
   (:mod:`analysis.diagnosis.discriminate`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path

import numpy as np

from analysis.diagnosis.candidates import (
    Candidate,
    Location,
    default_candidates,
    default_locations,
)
from analysis.diagnosis.compare import compare
from analysis.diagnosis.linear_screen import (
    LinearFit,
    LinearJob,
    run_linear_job,
    seen_by_linear_test,
)
from analysis.diagnosis.policy import FitSummary, Policy, simplest_of_next, tie_groups
from analysis.diagnosis.readout import read_missing_force
from analysis.diagnosis.result import Diagnosis, DiagnosisSettings, RankedCandidate
from analysis.diagnosis.screen import (
    Screen,
    ScreenFit,
    ScreenJob,
    information_criteria,
    refine_pass,
    screen_pass,
)
from analysis.diagnosis.signatures import FAMILIES, Evidence, find_signatures
from analysis.diagnosis.verify import Verified, VerifyJob, run_verify
from analysis.events import Listener, StageDone
from analysis.executors import Deferred, open_executor
from analysis.measurement_file import SteppedSineData
from analysis.model import DofRef, Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["Diagnosis", "DiagnosisSettings", "RankedCandidate", "diagnose"]

log = logging.getLogger(__name__)


def _linear_steps(pred: BranchMatchedPredictor) -> np.ndarray:
    """Steps where the model's elements exert no force."""
    _, points = pred.solve()
    out = np.zeros(pred.data.n_steps, bool)
    for r, p in points.items():
        if p.converged:
            out[r] = p.f_nl.size == 0 or float(np.abs(p.f_nl).max()) < 1e-9
    return out


def _run_verifications(
    ex, jobs: list[VerifyJob], essential: int, enough, workers: int, follow=None, started=()
) -> tuple[dict, dict]:
    """Run verification jobs (on ``ex``, at most ``workers`` at a time, or in this process)
    in order; the jobs after the first ``essential`` start one at a time once the jobs before
    them are in, and are dropped once ``enough`` of the results so far holds (so which run
    does not depend on which finished first). ``follow(i, result)`` may return a further job
    for a finished one (a fit that went most of the way goes on at once, ahead of the jobs
    not yet started, instead of after all of them). ``started`` holds the futures of the
    first jobs, already submitted to ``ex``.

    Returns ``{index: Verified}`` of the jobs run, in job order, and ``{index: Verified}`` of
    the further jobs."""
    out: dict[int, Verified] = {}
    further: dict[int, Verified] = {}

    def next_of(i: int):
        return None if follow is None else follow(i, out[i])

    if ex is None:
        for i, job in enumerate(jobs):
            if i >= essential and enough([*out.values(), *further.values()]):
                break
            out[i] = run_verify(job)
            if (nxt := next_of(i)) is not None:
                further[i] = run_verify(nxt)
        return out, further
    running: dict = {f: (i, False) for i, f in enumerate(started)}
    queue = list(enumerate(jobs))[len(started) :]
    while queue or running:
        while queue and len(running) < workers:
            i, job = queue[0]
            if i >= essential:
                if any(not f for _, f in running.values()):
                    # one at a time after the essential ones: each depends on all before it
                    break
                if enough([*out.values(), *further.values()]):
                    queue.clear()
                    break
            queue.pop(0)
            running[ex.submit(run_verify, job)] = (i, False)
        if not running:
            break
        finished, _ = wait(running, return_when=FIRST_COMPLETED)
        for f in finished:
            i, is_further = running.pop(f)
            if is_further:
                further[i] = f.result()
                continue
            out[i] = f.result()
            if (nxt := next_of(i)) is not None:
                running[ex.submit(run_verify, nxt)] = (i, True)
    return dict(sorted(out.items())), further


def _screen_from(model: Model, data, st: DiagnosisSettings, pred=None) -> Screen:
    pred = pred or BranchMatchedPredictor(model, data, n_harmonics=st.n_harmonics, n_time=st.n_time)
    return Screen(model, data, predictor=pred, locations=default_locations(model, st.locations))


def _lead(fits: list[ScreenFit]) -> ScreenFit | None:
    """The screen's best nonlinear candidate: the first :func:`_shortlist` picks."""
    return next((f for f in fits if f.candidate.law.kind not in _LINEAR_KINDS), None)


def _ignore(event) -> None:
    """The listener when none is given."""


def _best_rms(done: list[Verified]) -> float:
    return min((v.rms_over_noise() for v in done), default=math.inf)


def _law_key(c: Candidate) -> tuple:
    return (c.law.kind, c.law.options.get("side"))


_LINEAR_KINDS = ("mass", "linear_spring", "joint_spring", "parameter")

#: Location kinds whose states the sensors do not measure directly (one spring, a group of
#: springs, a joint direction, a point's unmeasured direction, two nodes): a class each in the
#: short list (:func:`_shortlist`).
UNMEASURED_KINDS = ("group", "spring", "joint", "direction", "pair")

#: Locations of each unmeasured kind whose every law is refined for the short list.
REFINED_LOCATIONS = 3


def _shortlist(
    screen: Screen,
    fits: list[ScreenFit],
    evidence: Evidence,
    n_verify: int,
    baseline_bic: float,
    class_share: float = 0.25,
):
    """Screened candidates to verify, in two stages.

    First: the best law, also at its second location (neighbouring points tie in a screen);
    then the picks at each location class of unmeasured DOFs (a group of springs such as the
    mounts, a joint), where a screen's first pass reads the states less well than at a
    measured point and cannot tell look-alike laws apart: every candidate there is refined by
    the screen's alternations (a first pass can score the true law there worse than the model
    itself), and the best of them, the best law's candidate there and the best candidate of
    each law family the evidence points at are picked, each if it gains at least ``class_share`` of
    the best candidate's BIC gain (best first); then the next laws, up to ``n_verify``
    distinct ones. Second, only if none of those explains the misfit: the next two laws, and
    the best candidate of each law family the evidence points at a measured point.
    """
    nonlinear = [f for f in fits if f.candidate.law.kind not in _LINEAR_KINDS]
    first: list[ScreenFit] = []  # nonlinear[0] first (:func:`_lead`)
    laws: list = []
    for f in nonlinear:
        if _law_key(f.candidate) not in laws:
            laws.append(_law_key(f.candidate))
            first.append(f)
            if len(laws) >= n_verify:
                break
    n_lead = min(1, len(first))
    if first and first[0].candidate.location.kind == "point":
        # neighbouring measured points tie in a screen (a law in a joint or a group of
        # springs has no neighbour there: its next location is another kind of place)
        same = _other_points(nonlinear, first[0].candidate, ())[:1]
        first[1:1] = same
        n_lead += len(same)
    lead = first[0].candidate.law if first else None

    def screen_gain(f) -> float:
        return -np.inf if f is None else baseline_bic - f.bic

    best_gain = max((screen_gain(f) for f in nonlinear[:1]), default=np.inf)
    classes: list[ScreenFit] = []
    for where in UNMEASURED_KINDS:
        refined = [screen.refined(f) for f in _class_leaders(nonlinear, where)]
        by_bic = sorted(refined, key=lambda f: f.bic)
        picks = by_bic[:1] + [next((f for f in refined if f.candidate.law == lead), None)]
        for fam in evidence.families:
            # each family's best apart from the picks so far (a contact-like law in a joint
            # can lead and belong to one family while the evidence also points at another)
            kinds = FAMILIES.get(fam, ())
            picks.append(
                next(
                    (
                        f
                        for f in by_bic
                        if f.candidate.law.kind in kinds
                        and all(f.candidate != g.candidate for g in picks if g is not None)
                    ),
                    None,
                )
            )
        for f in picks:
            # only where the class explains a fair share of what the best candidate does
            gain = screen_gain(f)
            if (
                f is not None
                and gain >= class_share * best_gain
                and all(f.candidate != g.candidate for g in first + classes)
            ):
                classes.append(f)
    first[n_lead:n_lead] = sorted(classes, key=lambda f: f.bic)
    second: list[ScreenFit] = []
    for f in nonlinear:
        if len(second) >= 2:
            break
        if _law_key(f.candidate) not in laws:
            laws.append(_law_key(f.candidate))
            second.append(f)
    for fam in evidence.families:
        fam_kinds = FAMILIES.get(fam, ())
        best = next(
            (
                f
                for f in nonlinear
                if f.candidate.law.kind in fam_kinds and f.candidate.location.kind == "point"
            ),
            None,
        )
        if best is not None and all(best.candidate != g.candidate for g in first + second):
            second.append(best)
    return first, second[:4]


def _refine_leaders(screen: Screen, fits: list[ScreenFit], jobs: _Jobs, ex) -> None:
    """Refine every fit :func:`_shortlist` refines (:func:`_class_leaders`), half of them on
    a worker meanwhile (each refinement depends only on its own fit: the same fits result
    whichever process makes them)."""
    nonlinear = [f for f in fits if f.candidate.law.kind not in _LINEAR_KINDS]
    todo = {
        f.candidate.label: f
        for where in UNMEASURED_KINDS
        for f in _class_leaders(nonlinear, where)
        if not f.refined
    }
    fs = list(todo.values())
    mine, theirs = (fs[0::2], fs[1::2]) if ex is not None else (fs, [])
    later = Deferred(ex, refine_pass, jobs.screen(screen.locations, (), theirs)) if theirs else None
    for f in mine:
        screen.refined(f)
    if later is not None:
        screen.take_refined(later.result())


def _class_leaders(fits: list[ScreenFit], where: str) -> list[ScreenFit]:
    """Every law at the best :data:`REFINED_LOCATIONS` locations of kind ``where`` (by their
    best law in the screen's first pass): a first pass can score a law there worse than the
    model itself, but the location an effect sits at stands out under one law or another, so
    the refinements of a kind stay at that many times the laws, whatever the size of the
    structure."""
    here = [f for f in fits if f.candidate.location.kind == where]
    order = list(dict.fromkeys(f.candidate.location for f in sorted(here, key=lambda f: f.bic)))
    keep = set(order[:REFINED_LOCATIONS])
    return [f for f in here if f.candidate.location in keep]


def _other_points(
    fits: list[ScreenFit], cand: Candidate, done, kinds: tuple[str, ...] | None = ("point",)
) -> list[ScreenFit]:
    """Screened fits of ``cand``'s law at the other measured points (at other places of
    ``kinds``; None: any), best first, leaving out the candidates in ``done``."""
    return [
        f
        for f in fits
        if f.candidate.law == cand.law
        and (kinds is None or f.candidate.location.kind in kinds)
        and f.candidate.location != cand.location
        and f.candidate not in done
    ]


def _walk_jobs(best, fits: list[ScreenFit], tried, n: int, kinds=("point",)):
    """The best verified law at the next ``n`` measured points the screen ranks it at, each
    started from the best's fit (its own values and the model's nonlinear parameters): a
    screen ranks neighbouring points of a strong effect loosely, a fit from a neighbour's
    values is near. Returns ``[(ScreenFit, values, known)]``."""
    cand = best.candidate
    names = cand.parameter_names()
    values = {p: best.parameters[n] for p, n in names.items() if n in best.parameters}
    known = {n: v for n, v in best.parameters.items() if n not in names.values()}
    return [(f, values, known) for f in _other_points(fits, cand, tried, kinds)[:n]]


def _merge(done: list[Verified], i: int, v: Verified) -> None:
    """Take the continuation ``v`` of ``done[i]`` if it is better, with the history of both."""
    if v.chi2_per_dof() < done[i].chi2_per_dof():
        v.seconds += done[i].seconds
        v.cpu_seconds += done[i].cpu_seconds
        v.evaluations += done[i].evaluations
        v.history = done[i].history + v.history
        done[i] = v


def _other_laws(
    screen: Screen, fits: list[ScreenFit], cand: Candidate, tried, n: int
) -> list[ScreenFit]:
    """Other laws at ``cand``'s location (a group of springs, a joint), refined: of the next
    ``n + 1`` by BIC, the ``n`` simplest. Look-alike laws there screen alike (the mounts'
    cubic hardening ranked fourth behind a contact, a two-sided gap and a gap spring, all
    stiffening), and on a tie the simpler law is preferred."""
    there = [
        screen.refined(f)
        for f in fits
        if f.candidate.location == cand.location
        and f.candidate.law != cand.law
        and f.candidate not in tried
    ]
    keep = simplest_of_next([f.candidate.n_params for f in there], [f.bic for f in there], n)
    return [there[i] for i in keep]


def _linear_shortlist(base: LinearFit | None, fits: list[LinearFit], st: DiagnosisSettings):
    """Linear candidates that earn their parameter on the linear test and remove most of its
    misfit (the best, and those tied with it)."""
    if base is None or base.failed:
        return []
    good = [
        f
        for f in fits
        if not f.failed and f.delta_bic < -st.linear_bic and f.cost <= st.linear_ratio * base.cost
    ]
    if not good:
        return []
    return [f for f in good if f.bic - good[0].bic <= st.tie_bic][:2]


@dataclasses.dataclass
class _Jobs:
    """What every verification job of one diagnosis shares. ``text`` is the model the
    verifications start from: the recalibrated one once the screen ran again from it."""

    text: str
    source: str
    path: str
    linear_run: str | None
    st: DiagnosisSettings

    def verify(
        self, cand, values=None, known=None, start_toml=None, n_starts=0, seed=0
    ) -> VerifyJob:
        st = self.st
        return VerifyJob(
            self.text,
            self.source,
            self.path,
            None,
            cand,
            dict(values or {}),
            dict(known or {}),
            self.linear_run,
            st.verify_iterations,
            n_starts,
            seed,
            start_toml,
            st.n_harmonics,
            st.n_time,
            st.verify_evaluations,
            reweight_drop=st.reweight_drop,
        )

    def screen(self, places, candidates=(), refine=()) -> ScreenJob:
        """A share of the screen of ``text`` at ``places``: a first pass over ``candidates``
        or the refinement of the fits ``refine``."""
        st = self.st
        return ScreenJob(
            self.text,
            self.source,
            self.path,
            tuple(candidates),
            st.n_harmonics,
            st.n_time,
            locations=tuple(places),
            refine=tuple(refine),
        )

    def go_on(self, cand: Candidate | None, v: Verified) -> VerifyJob:
        """A verification continued from where ``v`` stopped."""
        job = self.verify(cand, start_toml=v.model_toml)
        return dataclasses.replace(
            job, max_evaluations=self.st.continue_evaluations, reweight_passes=1
        )


@dataclasses.dataclass
class _Screened:
    """The screen and what ran beside it: the recalibrated model, the linear test's fits and
    the lead's verification, started at once."""

    nonlinear: list[Candidate]
    screen: Screen
    baseline: ScreenFit
    fits: list[ScreenFit]
    first: list[ScreenFit]
    second: list[ScreenFit]
    lead: ScreenFit | None
    early: list
    refit: Verified
    lin_base: LinearFit | None
    lin_fits: list[LinearFit]


@dataclasses.dataclass
class _Verifying:
    """The verifications so far: ``done[i]`` verified ``origin[i]``."""

    origin: list
    done: list[Verified]
    refit: Verified
    policy: Policy

    @property
    def st(self) -> DiagnosisSettings:
        return self.policy.st

    @property
    def bar(self) -> float:
        return self.policy.bar

    def summaries(self) -> list[FitSummary]:
        return [FitSummary.of(v) for v in self.done]


def diagnose(
    model: Model,
    data: SteppedSineData,
    *,
    linear_run: str | Path | None = None,
    candidates: list[Candidate] | None = None,
    settings: DiagnosisSettings | None = None,
    progress: Listener | None = None,
) -> Diagnosis:
    """Find which physical effect the model misses.

    Parameters
    ----------
    model : Model
        The calibrated model (without sensor masses; the file's are added).
    data : SteppedSineData
        A stepped-sine file (read from disk: verifications re-read it by path).
    linear_run : path, optional
        The random-excitation test of the same rig: linear candidates are screened and
        recalibrated there.
    candidates : list of Candidate, optional
        Default: :func:`~analysis.diagnosis.candidates.default_candidates`.
    settings : DiagnosisSettings, optional
    progress : callable, optional
        Receives the diagnosis's :mod:`analysis.events`: a :class:`UnitDone` per candidate
        screened (stage ``"screen"``, then ``"refine"``) and per start scored, an
        :class:`Iteration` per Levenberg-Marquardt iteration of a fit run in this process, and
        a :class:`StageDone` at each milestone (``"compared"``, ``"screened"``,
        ``"verified"``, ...).

    Returns
    -------
    Diagnosis
    """
    st = settings or DiagnosisSettings()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    say: Listener = progress or _ignore
    pred = BranchMatchedPredictor(model, data, n_harmonics=st.n_harmonics, n_time=st.n_time)
    cmp = compare(model, data, predictor=pred)
    _, s = pred.measured()
    evidence = find_signatures(cmp, data, s, _linear_steps(pred))
    timings["compare_s"] = time.perf_counter() - t0
    say(StageDone("compared", rms_over_noise=cmp.rms_over_noise, seconds=timings["compare_s"]))
    if cmp.rms_over_noise <= st.adequate_rms:
        timings["total_s"] = time.perf_counter() - t0
        return Diagnosis("adequate", cmp, evidence, timings=timings, settings=st)
    cands = (
        default_candidates(model, scope=st.locations) if candidates is None else list(candidates)
    )
    jobs = _Jobs(
        model.to_toml(),
        str(model.source),
        str(data.path),
        None if linear_run is None else str(linear_run),
        st,
    )
    with open_executor(st.workers) as ex:
        sc = _screen_step(model, data, cands, pred, cmp, evidence, jobs, ex, say, timings)
        refit = sc.refit
        timings["refit_s"] = refit.seconds
        say(StageDone("recalibrated", rms_over_noise=refit.rms_over_noise()))
        result = Diagnosis(
            "adequate",
            cmp,
            evidence,
            sc.fits,
            sc.baseline,
            sc.lin_fits,
            refit,
            timings=timings,
            settings=st,
        )
        if Policy(st, FitSummary.of(refit)).adequate():
            timings["total_s"] = time.perf_counter() - t0
            return result
        if Policy(st, FitSummary.of(refit)).rescreen(cmp.rms_over_noise):
            _screen_again(sc, result, data, evidence, jobs, ex, say)
        t2 = time.perf_counter()
        run, further = _first_verifications(sc, jobs, ex, say)
        _continue_falling(run, further, jobs, ex, say)
        _walk_from_best(run, sc, jobs, ex, say)
        if _look_alikes(run, sc, jobs, ex, say):
            # the best moved to a look-alike place: the walk from there
            _walk_from_best(run, sc, jobs, ex, say)
        _second_picks(run, sc, jobs, ex, say)
        _restart_best(run, jobs, ex, say)
    timings["verify_s"] = time.perf_counter() - t2
    _conclude(result, model, data, run)
    if result.verdict == "unexplained":
        _read_out(result, sc)
    timings["total_s"] = time.perf_counter() - t0
    return result


def _screen_step(
    model: Model,
    data,
    cands,
    pred,
    cmp,
    evidence: Evidence,
    jobs: _Jobs,
    ex,
    say: Listener,
    timings,
) -> _Screened:
    """The screen, with the recalibration and the linear test's candidates on the workers
    meanwhile; the lead's verification started as soon as the screen has it."""
    st = jobs.st
    t1 = time.perf_counter()
    # the candidates the linear test sees are tested there, the others screened
    on_linear = [c for c in cands if jobs.linear_run is not None and seen_by_linear_test(c, model)]
    nonlinear = [c for c in cands if c not in on_linear]
    # the screen's first pass shared with a worker; the recalibration and the linear
    # test's candidates on the workers meanwhile
    mine, theirs = (nonlinear[0::2], nonlinear[1::2]) if ex is not None else (nonlinear, [])
    screen = _screen_from(model, data, st, pred)
    share = Deferred(ex, screen_pass, jobs.screen(screen.locations, theirs))
    refit_job = Deferred(ex, run_verify, jobs.verify(None))
    lin_jobs = []
    if jobs.linear_run is not None:
        lin_jobs = [
            Deferred(ex, run_linear_job, LinearJob(jobs.text, jobs.source, jobs.linear_run, c))
            for c in [None, *on_linear]
        ]
    baseline = screen.baseline()
    fits = screen.first_pass(mine, say) + (share.result() if theirs else [])
    fits = screen.refine(fits, st.n_refine, say)
    timings["screen_s"] = time.perf_counter() - t1
    say(StageDone("screened", count=len(fits), seconds=timings["screen_s"]))
    refit = refit_job.result()
    # the screen's best law goes first in any case: its verification starts as soon as a
    # worker is free, while this process makes the short list (its refinements at
    # unmeasured DOFs) and the workers finish the linear test
    lead = _lead(fits)
    early = []
    if (
        ex is not None
        and lead is not None
        and not Policy(st, FitSummary.of(refit)).settled(cmp.rms_over_noise)
    ):
        early = [
            ex.submit(
                run_verify,
                dataclasses.replace(
                    jobs.verify(lead.candidate, lead.values, lead.known),
                    give_up_chi2=refit.chi2_per_dof(),
                ),
            )
        ]
    t2 = time.perf_counter()
    _refine_leaders(screen, fits, jobs, ex)
    first, second = _shortlist(screen, fits, evidence, st.n_verify, baseline.bic)
    timings["shortlist_s"] = time.perf_counter() - t2
    lin_base, lin_fits = _linear_results(lin_jobs, say)
    return _Screened(
        nonlinear, screen, baseline, fits, first, second, lead, early, refit, lin_base, lin_fits
    )


def _linear_results(
    lin_jobs: list[Deferred], say: Listener
) -> tuple[LinearFit | None, list[LinearFit]]:
    """The linear test's recalibrated model and its candidates, best first."""
    if not lin_jobs:
        return None, []
    done = [j.result() for j in lin_jobs]
    lin_base, lin_fits = done[0], done[1:]
    for f in lin_fits:
        f.delta_bic = f.bic - lin_base.bic
    lin_fits.sort(key=lambda f: f.bic)
    best = lin_fits[0].candidate.label if lin_fits else ""
    say(StageDone("linear screen", count=len(lin_fits), note=f"best {best}" if best else ""))
    return lin_base, lin_fits


def _screen_again(
    sc: _Screened, result: Diagnosis, data, evidence: Evidence, jobs: _Jobs, ex, say: Listener
) -> None:
    """The calibration's values were a poor start (a missing effect can pull the model's own
    parameters into a far minimum), and a screen reads the states through the model's own
    elements: screen again from the recalibrated model, which every verification then starts
    from (``jobs.text``)."""
    st = jobs.st
    t3 = time.perf_counter()
    say(StageDone("screen again", rms_over_noise=sc.refit.rms_over_noise()))
    jobs.text = sc.refit.model_toml
    sc.screen = _screen_from(Model.from_toml_text(jobs.text, jobs.source), data, st)
    sc.baseline = sc.screen.baseline()
    sc.fits = sc.screen.run(sc.nonlinear, st.n_refine, say, ex)
    _refine_leaders(sc.screen, sc.fits, jobs, ex)
    sc.first, sc.second = _shortlist(sc.screen, sc.fits, evidence, st.n_verify, sc.baseline.bic)
    result.screen, result.baseline, result.rescreened = sc.fits, sc.baseline, True
    result.timings["rescreen_s"] = time.perf_counter() - t3


def _first_verifications(
    sc: _Screened, jobs: _Jobs, ex, say: Listener
) -> tuple[_Verifying, list[int]]:
    """The short list's first stage verified; returns the verifications and the indices of
    those that went on at once."""
    st, refit = jobs.st, sc.refit
    first = sc.first
    linear_first = _linear_shortlist(sc.lin_base, sc.lin_fits, st)
    # the best law at its two best locations, the linear test's candidates and the next
    # pick (at an unmeasured location, else the next law) first; the other picks are
    # dropped once a verified candidate is at the noise or the stage's allowance of
    # evaluations is spent
    n_lead = min(2, len(first))
    origin: list = [*first[:n_lead], *linear_first, *first[n_lead:]]
    essential = len(origin) - len(first) + min(3, len(first))
    policy = Policy(st, FitSummary.of(refit))
    bar = policy.bar
    vjobs = [
        dataclasses.replace(
            jobs.verify(o.candidate, start_toml=o.model_toml)
            if isinstance(o, LinearFit)
            else jobs.verify(o.candidate, o.values, o.known),
            give_up_chi2=bar,
        )
        for o in origin
    ]

    def enough(vs: list[Verified]) -> bool:
        return policy.enough([FitSummary.of(v) for v in vs])

    gone_on: list[int] = []

    def follow(i: int, v: Verified) -> VerifyJob | None:
        if len(gone_on) >= 2 or not policy.goes_on_at_once(FitSummary.of(v)):
            return None
        gone_on.append(i)
        say(StageDone("continued", count=1, rms_over_noise=v.rms_over_noise()))
        return jobs.go_on(vjobs[i].candidate, v)

    # the jobs run are the first len(ran), in order: their indices are their positions
    assert not sc.early or origin[0] is sc.lead
    ran, further = _run_verifications(ex, vjobs, essential, enough, st.workers, follow, sc.early)
    done = list(ran.values())
    for i, v in further.items():
        _merge(done, i, v)
    say(StageDone("verified", count=len(done), rms_over_noise=_best_rms(done)))
    return _Verifying(origin[: len(ran)], done, refit, policy), list(further)


def _continue_falling(run: _Verifying, further: list[int], jobs: _Jobs, ex, say: Listener) -> None:
    """The fits still falling fast go on (:meth:`Policy.to_continue`; those that went most of
    the way went on as soon as they finished)."""
    going = run.policy.to_continue(run.summaries(), further)
    if going:
        say(StageDone("continued", count=len(going)))
    cont = [
        Deferred(ex, run_verify, jobs.go_on(run.origin[i].candidate, run.done[i])) for i in going
    ]
    for i, p in zip(going, cont, strict=True):
        _merge(run.done, i, p.result())


def _walk_from_best(run: _Verifying, sc: _Screened, jobs: _Jobs, ex, say: Listener) -> None:
    """From the best, where :meth:`Policy.walk_to` sends it: its law at the next measured
    points by the screen (a linear candidate's: by the linear test), from the best's fit, or
    the next laws at its unmeasured location (docs/diagnosis.md, the rules table)."""
    done, origin = run.done, run.origin
    best = _best_index(run)
    if best is None:
        return
    lead = origin[best]
    kind = lead.candidate.location.kind
    walk_to = run.policy.walk_to(kind, FitSummary.of(done[best]))
    if not walk_to:
        return
    tried = [o.candidate for o in origin]
    if isinstance(lead, LinearFit):
        if walk_to != "points":
            return
        # a mass or a spring at a point: at the next points by the linear test, each from its
        # own recalibration there (the linear test ranks neighbouring points loosely: a spring
        # near a cantilever's tip acts on its first mode as one further in with more stiffness)
        nxt = [
            f
            for f in sc.lin_fits
            if f.candidate.law == lead.candidate.law
            and f.candidate.location.kind == kind
            and f.candidate not in tried
            and not f.failed
        ][: run.st.n_walk]
        say(StageDone("neighbours", count=len(nxt)))
        _verify_linear_walk(run, nxt, jobs, ex)
        return
    if walk_to == "points":
        walk = _walk_jobs(done[best], sc.fits, tried, run.st.n_walk)
        say(StageDone("neighbours", count=len(walk)))
    else:
        laws = _other_laws(sc.screen, sc.fits, lead.candidate, tried, run.st.n_walk)
        walk = [(f, f.values, f.known) for f in laws]
        say(StageDone("other laws", count=len(walk)))
    _verify_walk(run, walk, jobs, ex)


def _verify_linear_walk(run: _Verifying, fits: list[LinearFit], jobs: _Jobs, ex) -> None:
    """Verify linear candidates, each from its linear test's recalibration, and add them."""
    _verify_more(run, fits, [jobs.verify(f.candidate, start_toml=f.model_toml) for f in fits], ex)


def _verify_walk(run: _Verifying, walk: list, jobs: _Jobs, ex) -> None:
    """Verify ``[(ScreenFit, values, known)]``, each from its given values, and add them."""
    vjobs = [jobs.verify(f.candidate, values, known) for f, values, known in walk]
    _verify_more(run, [f for f, _, _ in walk], vjobs, ex)


def _verify_more(run: _Verifying, origins: list, vjobs: list[VerifyJob], ex) -> None:
    """Run ``vjobs`` (verifying ``origins``) against the stage's bar and add them."""
    more = [Deferred(ex, run_verify, dataclasses.replace(j, give_up_chi2=run.bar)) for j in vjobs]
    run.done += [p.result() for p in more]
    run.origin += origins


def look_alike_places(where: Location, places) -> list[Location]:
    """The places of ``places`` where an element acts as one at ``where`` would, seen
    through the sensors: a group's springs each alone and a spring's groups (one member's law
    fits as the group's with a smaller parameter, the group's as a member's), a point's pairs
    in the same direction (an element to ground, or to a node that barely moves, fit alike)
    and a pair's point to ground. A place stands also for those that move as it
    (:attr:`Location.alike`)."""

    def same(a: DofRef, b: DofRef) -> bool:
        return (a.node, a.direction) == (b.node, b.direction)

    def related(w: Location, loc: Location) -> bool:
        if not w.incidences or not loc.incidences:
            return False
        (at, _), (l_at, l_to) = w.incidences[0], loc.incidences[0]
        if w.kind == "group":
            return loc.kind == "spring" and loc.incidences[0] in w.incidences
        if w.kind == "spring":
            return loc.kind == "group" and w.incidences[0] in loc.incidences
        if w.kind in ("point", "direction"):
            return loc.kind == "pair" and same(l_at, at)
        if w.kind == "pair":
            return loc.kind in ("point", "direction") and l_to is None and same(l_at, at)
        return False

    return [
        loc
        for loc in places
        if loc != where
        and any(related(w, x) for w in (where, *where.alike) for x in (loc, *loc.alike))
    ]


def _best_index(run: _Verifying) -> int | None:
    """The index of the best verification that did not fail (None if all failed)."""
    ranked = [i for i in np.argsort([v.chi2_per_dof() for v in run.done]) if not run.done[i].failed]
    return int(ranked[0]) if ranked else None


def _look_alikes(run: _Verifying, sc: _Screened, jobs: _Jobs, ex, say: Listener) -> bool:
    """The best verified law at its look-alike places (:func:`look_alike_places`), each
    started from the best's fit, when the best explains the misfit or went most of the way:
    the full model's fit, not the screen's coarse reading of unmeasured places, then ranks
    them, and a tie among them is reported as one (docs/diagnosis.md, "Look-alike
    places"). Returns whether the best is now at one of them."""
    done, origin = run.done, run.origin
    lead = _best_index(run)
    if lead is None or not isinstance(origin[lead], ScreenFit):
        return False
    if not run.policy.look_alike(FitSummary.of(done[lead])):
        return False
    cand = origin[lead].candidate
    places = list(dict.fromkeys(f.candidate.location for f in sc.fits))
    alike = look_alike_places(cand.location, places)
    tried = [o.candidate for o in origin]
    fits = [
        f
        for f in sc.fits
        if f.candidate.law == cand.law
        and f.candidate.location in alike
        and f.candidate not in tried
    ]
    walk = _walk_jobs(done[lead], fits, tried, len(fits), kinds=None)
    if not walk:
        return False
    say(StageDone("look-alike places", count=len(walk)))
    _verify_walk(run, walk, jobs, ex)
    return _best_index(run) != lead


def _second_picks(run: _Verifying, sc: _Screened, jobs: _Jobs, ex, say: Listener) -> None:
    """If none explains it, while time is left, the short list's second stage."""
    if not run.policy.second_stage(run.summaries(), len(sc.second)):
        return
    more = [
        Deferred(ex, run_verify, jobs.verify(f.candidate, f.values, f.known)) for f in sc.second
    ]
    run.done += [p.result() for p in more]
    run.origin += sc.second
    say(StageDone("verified", count=len(run.done), rms_over_noise=_best_rms(run.done)))


def _restart_best(run: _Verifying, jobs: _Jobs, ex, say: Listener) -> None:
    """Further starts for the best two, only if the best went most of the way (a local
    minimum of a strong effect), not for one that explains little; a restart is kept where it
    fits better."""
    st, done = run.st, run.done
    again = run.policy.restarts(run.summaries())
    if not again:
        return
    say(StageDone("restarts", count=len(again)))
    retry = []
    for i in again:
        o = run.origin[i]
        if isinstance(o, LinearFit):
            job = jobs.verify(o.candidate, start_toml=o.model_toml, n_starts=st.n_starts)
        else:
            job = jobs.verify(o.candidate, o.values, o.known, n_starts=st.n_starts)
        retry.append(Deferred(ex, run_verify, job))
    for i, p in zip(again, retry, strict=True):
        v = p.result()
        if v.chi2_per_dof() < done[i].chi2_per_dof():
            v.seconds += done[i].seconds
            v.evaluations += done[i].evaluations
            done[i] = v


def _conclude(result: Diagnosis, model: Model, data, run: _Verifying) -> None:
    """The ranking, the verdict and, for a group, the measurement that would separate it."""
    ranking, model_bic = _rank(model, run.refit, run.origin, run.done, run.st)
    best = ranking[0] if ranking else None
    verdict = run.policy.verdict(
        None if best is None else best.rms_over_noise, None if best is None else best.delta_bic
    )
    result.verdict, result.ranking, result.model_bic = verdict, ranking, model_bic
    if verdict == "explained" and len(result.group) > 1:
        from analysis.diagnosis.discriminate import discriminate

        t3 = time.perf_counter()
        try:
            result.recommendation = discriminate(result.group, data)
        except (ValueError, RuntimeError) as exc:
            log.warning("no discriminating measurement: %s", exc)
        result.timings["discriminate_s"] = time.perf_counter() - t3


def _read_out(result: Diagnosis, sc: _Screened) -> None:
    """What the data show about the missing law, from the screen's force estimate at the best
    verified candidate's location (else the screen's best law's): nothing in the library
    explains the misfit, and the read-out says what kind of element to write."""
    where = next(
        (r.candidate.location for r in result.ranking if r.candidate.location.incidences), None
    )
    if where is None:
        lead = _lead(sc.fits)
        where = lead.candidate.location if lead is not None else None
    if where is None:
        return
    t = time.perf_counter()
    try:
        result.readout = read_missing_force(sc.screen, where)
    except (ValueError, np.linalg.LinAlgError) as exc:
        log.warning("no read-out of the missing force at %s: %s", where.name, exc)
    result.timings["readout_s"] = time.perf_counter() - t


def _rank(model: Model, refit: Verified, origin: list, done: list[Verified], st):
    """Rank the verified candidates by BIC on the steps every one of them (and the
    recalibrated model) converged at."""
    base_step = refit.step_chi2
    n_base = int(np.isfinite(base_step).sum())
    # a recalibrated model that fails on many steps the model solves is not comparable
    keep = [
        (o, v)
        for o, v in zip(origin, done, strict=True)
        if not v.failed and np.isfinite(v.step_chi2[np.isfinite(base_step)]).sum() >= 0.9 * n_base
    ]
    common = np.isfinite(base_step)
    for _, v in keep:
        common &= np.isfinite(v.step_chi2)
    n = int(common.sum()) * refit.values_per_step
    if n == 0:
        return [], math.nan
    n_known = len(model.parameter_names(group="nonlinear", calibrate=True))
    model_bic, _ = information_criteria(float(base_step[common].sum()), n, n_known)
    scored = []
    for o, v in keep:
        k = n_known + o.candidate.n_params
        bic, _ = information_criteria(float(v.step_chi2[common].sum()), n, k)
        scored.append((bic, o, v))
    if not scored:
        return [], model_bic
    # within a tie the fit orders (BIC already charges each parameter): docs/diagnosis.md, Ties
    scored.sort(key=lambda t: t[0])
    groups = tie_groups([t[0] for t in scored], st.tie_bic)
    ranked = []
    for i, ((bic, o, v), group) in enumerate(zip(scored, groups, strict=True)):
        ranked.append(
            RankedCandidate(
                rank=i + 1,
                group=group,
                candidate=o.candidate,
                bic=bic,
                delta_bic=bic - model_bic,
                rms_over_noise=v.rms_over_noise(common),
                verified=v,
                screen=o if isinstance(o, ScreenFit) else None,
                linear=o if isinstance(o, LinearFit) else None,
            )
        )
    return ranked, model_bic
