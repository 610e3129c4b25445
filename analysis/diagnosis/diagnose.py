"""Which physical effect is missing? Compare, read the evidence, screen, verify, rank.

>>> result = diagnose(model, data)              # doctest: +SKIP
>>> print(result.summary())                      # doctest: +SKIP

1. **Compare** the calibrated model with the file on the measured branch
   (:func:`~analysis.diagnosis.compare.compare` with a
   :class:`~analysis.diagnosis.branches.BranchMatchedPredictor`). A model within
   ``adequate_rms`` of the noise is adequate: nothing is claimed.
2. **Evidence**: the signature tests (:mod:`analysis.diagnosis.signatures`), in words.
3. **Screen** every candidate (each law of the element library at each plausible location,
   linear changes) by the harmonic-domain force estimate (:mod:`analysis.diagnosis.screen`),
   ranked by BIC.
4. **Verify** the best distinct candidates, plus the best of each law family the evidence
   points at, in the full model (:mod:`analysis.diagnosis.verify`): everything recalibrated.
5. **Rank** the verified candidates by BIC on the same steps; candidates within ``tie_bic``
   of the best form a group (the simplest law first). The effect is *explained* when the best
   brings the residual to ``explained_rms`` of the noise; otherwise nothing in the library
   explains it and the tool says so. For a group, the measurement that would separate its
   members is computed (:mod:`analysis.diagnosis.discriminate`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.diagnosis.branches import BranchMatchedPredictor
from analysis.diagnosis.candidates import Candidate, default_candidates
from analysis.diagnosis.compare import Comparison, compare
from analysis.diagnosis.screen import Screen, ScreenFit, information_criteria
from analysis.diagnosis.signatures import FAMILIES, Evidence, find_signatures
from analysis.diagnosis.verify import Verified, VerifyJob, run_verify
from analysis.measurement_file import SteppedSineData
from analysis.model import Model
from analysis.planning.executors import open_executor, run_jobs

__all__ = ["Diagnosis", "DiagnosisSettings", "RankedCandidate", "diagnose"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DiagnosisSettings:
    """Settings of :func:`diagnose`.

    Parameters
    ----------
    adequate_rms : float
        A model whose residual (root of chi-square per degree of freedom) is at most this is
        adequate and nothing is claimed.
    explained_rms : float
        A verified candidate explains the misfit when it brings the residual to at most this.
    tie_bic : float
        Candidates within this BIC of the best are reported as a group.
    n_verify : int
        Best distinct screened candidates verified in the full model.
    n_refine : int
        Best screened candidates refined by the screen's alternations.
    verify_iterations : int
        LM iterations per verification.
    n_starts : int
        Further Latin hypercube starts of a verification that does not reach the noise.
    workers : int
        Processes for the verifications (1: in this process).
    """

    adequate_rms: float = 1.5
    explained_rms: float = 1.5
    tie_bic: float = 10.0
    n_verify: int = 2
    n_refine: int = 12
    verify_iterations: int = 10
    n_starts: int = 6
    workers: int = 2

    def __post_init__(self) -> None:
        if self.adequate_rms <= 0 or self.explained_rms <= 0 or self.tie_bic < 0:
            raise ValueError("DiagnosisSettings: thresholds must be positive")
        if self.n_verify < 1 or self.workers < 1:
            raise ValueError("DiagnosisSettings: n_verify and workers must be >= 1")


@dataclass
class RankedCandidate:
    """A verified candidate in the final ranking.

    Attributes
    ----------
    rank : int
        1 = best.
    group : int
        Candidates with the same group number tie (within ``tie_bic``).
    delta_bic : float
        BIC minus the model's (negative: better).
    """

    rank: int
    group: int
    candidate: Candidate
    bic: float
    delta_bic: float
    rms_over_noise: float
    verified: Verified
    screen: ScreenFit | None

    def to_json(self) -> dict:
        return {
            "rank": self.rank,
            "group": self.group,
            "label": self.candidate.label,
            "kind": self.candidate.law.kind,
            "location": self.candidate.location.name,
            "linear": self.candidate.is_linear,
            "n_params": self.candidate.n_params,
            "bic": self.bic,
            "delta_bic": self.delta_bic,
            "rms_over_noise": self.rms_over_noise,
            "parameters": self.verified.parameters,
            "seconds": self.verified.seconds,
        }


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes
    ----------
    verdict : {"adequate", "explained", "unexplained"}
    comparison : Comparison
        The model against the file (before any change).
    evidence : Evidence
    screen : list of ScreenFit
        Every screened candidate, best first; ``baseline`` the model's own fit.
    ranking : list of RankedCandidate
        Verified candidates, best first.
    group : list of RankedCandidate
        The best and those tied with it.
    recommendation : dict or None
        For a group: the measurement that separates its members best.
    timings : dict of str to float, s
    """

    verdict: str
    comparison: Comparison
    evidence: Evidence
    screen: list[ScreenFit] = field(default_factory=list)
    baseline: ScreenFit | None = None
    ranking: list[RankedCandidate] = field(default_factory=list)
    model_bic: float = math.nan
    recommendation: dict | None = None
    timings: dict[str, float] = field(default_factory=dict)
    settings: DiagnosisSettings = field(default_factory=DiagnosisSettings)

    @property
    def group(self) -> list[RankedCandidate]:
        return [r for r in self.ranking if r.group == 1] if self.ranking else []

    @property
    def best(self) -> RankedCandidate | None:
        return self.ranking[0] if self.ranking and self.verdict == "explained" else None

    def rank_of(self, kind: str, location: str, side: int | None = None) -> int | None:
        """Rank (1 = best) of a law at a location among the verified candidates, with ties:
        a candidate in the best group counts as first; None if not verified."""
        for r in self.ranking:
            c = r.candidate
            if (
                c.law.kind == kind
                and c.location.name == location
                and (side is None or c.law.options.get("side") == side)
            ):
                return 1 if r.group == 1 else r.rank
        return None

    def summary(self, n: int = 8) -> str:
        cmp = self.comparison
        lines = [
            f"model against the file: residual {cmp.rms_over_noise:.3g} x noise "
            f"(chi2/dof {cmp.chi2_per_dof:.3g})",
            self.evidence.summary(),
        ]
        if self.verdict == "adequate":
            lines.append(
                "verdict: the model is adequate (residual at the noise); nothing is claimed"
            )
            return "\n".join(lines)
        if self.baseline is not None and self.screen:
            lines.append(f"screen ({len(self.screen)} candidates; delta BIC against the model):")
            for f in self.screen[:n]:
                lines.append(
                    f"  {f.bic - self.baseline.bic:10.1f}  {f.candidate.label}  "
                    + ", ".join(f"{k} {v:.4g}" for k, v in f.values.items())
                )
        lines.append("verified in the full model (everything recalibrated):")
        for r in self.ranking:
            lines.append(
                f"  #{r.rank} (group {r.group}) {r.candidate.label}: residual "
                f"{r.rms_over_noise:.3g} x noise, delta BIC {r.delta_bic:.1f}, "
                + ", ".join(f"{k} {v:.4g}" for k, v in r.verified.parameters.items())
            )
        if self.verdict == "explained":
            g = self.group
            kind = "a linear effect" if g[0].candidate.is_linear else "a nonlinear effect"
            if len(g) == 1:
                lines.append(f"verdict: explained by {g[0].candidate.label} ({kind})")
            else:
                lines.append(
                    f"verdict: explained ({kind}); tied within {self.settings.tie_bic:g} BIC: "
                    + "; ".join(r.candidate.label for r in g)
                    + f" (the simplest first: {g[0].candidate.label})"
                )
        else:
            best = self.ranking[0] if self.ranking else None
            lines.append(
                "verdict: nothing in the element library explains the misfit"
                + (f"; the best, {best.candidate.label}, leaves {best.rms_over_noise:.3g} x "
                   "noise" if best else "")
            )  # fmt: skip
        if self.recommendation:
            lines.append("to separate the tied candidates: " + self.recommendation["text"])
        return "\n".join(lines)

    def to_json(self) -> dict:
        base = self.baseline.bic if self.baseline is not None else 0.0
        return {
            "verdict": self.verdict,
            "comparison": {
                "chi2_per_dof": self.comparison.chi2_per_dof,
                "rms_over_noise": self.comparison.rms_over_noise,
                "adequate": self.comparison.adequate,
            },
            "evidence": self.evidence.to_json(),
            "screen": [
                {"label": f.candidate.label, "delta_bic": f.bic - base, "chi2_per_dof":
                 f.chi2_per_dof, "values": f.values, "known": f.known}
                for f in self.screen[:30]
            ],
            "ranking": [r.to_json() for r in self.ranking],
            "group": [r.candidate.label for r in self.group],
            "recommendation": self.recommendation,
            "timings": self.timings,
        }  # fmt: skip


def _linear_steps(pred: BranchMatchedPredictor) -> np.ndarray:
    """Steps where the model's elements exert no force."""
    _, points = pred.solve()
    out = np.zeros(pred.data.n_steps, bool)
    for r, p in points.items():
        if p.converged:
            out[r] = p.f_nl.size == 0 or float(np.abs(p.f_nl).max()) < 1e-9
    return out


def _shortlist(fits: list[ScreenFit], evidence: Evidence, n_verify: int):
    """Candidates to verify, in two stages.

    First: the best screened candidate, the next location of the same law (neighbouring
    locations tie in a screen) and the best of the next ``n_verify - 1`` distinct laws.
    Then, only if none of those explains the misfit: the next locations and laws, and the best
    candidate of each law family the evidence points at (among the best 30).
    """
    first: list[ScreenFit] = []
    laws: list = []
    for f in fits:
        if f.candidate.law not in laws:
            laws.append(f.candidate.law)
            first.append(f)
            if len(laws) >= n_verify:
                break
    second: list[ScreenFit] = []
    if fits:
        same = [f for f in fits[1:] if f.candidate.law == fits[0].candidate.law]
        first[1:1] = same[:1]
        second += same[1:2]
    for f in fits:
        if f.candidate.law not in laws:
            laws.append(f.candidate.law)
            second.append(f)
            break
    # the evidence's law families: the best of each at a point, at a group and at a joint
    # (a screen reads the states of a structural location less well than a measured point's)
    for fam in evidence.families:
        kinds = FAMILIES.get(fam, ())
        for where in ("point", "group", "joint"):
            best = next((f for f in fits if f.candidate.law.kind in kinds
                         and _location_class(f.candidate) == where), None)  # fmt: skip
            if best is not None and best not in first and best not in second:
                second.append(best)
    return first, second[:6]


def _location_class(c: Candidate) -> str:
    if c.location.joint is not None:
        return "joint"
    if c.location.point is not None:
        return "point"
    return "group" if c.location.incidences else "structure"


def diagnose(
    model: Model,
    data: SteppedSineData,
    *,
    linear_run: str | Path | None = None,
    candidates: list[Candidate] | None = None,
    settings: DiagnosisSettings | None = None,
    progress: Callable[[str, dict], None] | None = None,
) -> Diagnosis:
    """Find which physical effect the model misses.

    Parameters
    ----------
    model : Model
        The calibrated model (without sensor masses; the file's are added).
    data : SteppedSineData
        A stepped-sine file (read from disk: verifications re-read it by path).
    linear_run : path, optional
        The random-excitation test of the same rig, used to recalibrate linear candidates.
    candidates : list of Candidate, optional
        Default: :func:`~analysis.diagnosis.candidates.default_candidates`.
    settings : DiagnosisSettings, optional
    progress : callable, optional
        ``progress(stage, info)`` for command lines.

    Returns
    -------
    Diagnosis
    """
    st = settings or DiagnosisSettings()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    say = progress or (lambda stage, info: None)
    pred = BranchMatchedPredictor(model, data)
    cmp = compare(model, data, predictor=pred)
    H, s = pred.measured()
    evidence = find_signatures(cmp, data, s, _linear_steps(pred))
    timings["compare_s"] = time.perf_counter() - t0
    say("compare", {"rms_over_noise": cmp.rms_over_noise, "seconds": timings["compare_s"]})
    if cmp.rms_over_noise <= st.adequate_rms:
        timings["total_s"] = time.perf_counter() - t0
        return Diagnosis("adequate", cmp, evidence, timings=timings, settings=st)
    t1 = time.perf_counter()
    screen = Screen(model, data, predictor=pred)
    cands = default_candidates(model) if candidates is None else list(candidates)
    baseline = screen.baseline()
    fits = screen.run(cands, n_refine=st.n_refine, progress=progress)
    timings["screen_s"] = time.perf_counter() - t1
    say("screened", {"n": len(fits), "seconds": timings["screen_s"]})
    t2 = time.perf_counter()
    first, second = _shortlist(fits, evidence, st.n_verify)
    ranking, model_bic = _verify(model, data, first, second, cmp, linear_run, st, say)
    timings["verify_s"] = time.perf_counter() - t2
    verdict = "unexplained"
    if ranking and ranking[0].rms_over_noise <= st.explained_rms and ranking[0].delta_bic < 0:
        verdict = "explained"
    result = Diagnosis(verdict, cmp, evidence, fits, baseline, ranking, model_bic,
                       timings=timings, settings=st)  # fmt: skip
    if verdict == "explained" and len(result.group) > 1:
        from analysis.diagnosis.discriminate import discriminate

        t3 = time.perf_counter()
        try:
            result.recommendation = discriminate(result.group, data)
        except (ValueError, RuntimeError) as exc:
            log.warning("no discriminating measurement: %s", exc)
        timings["discriminate_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    return result


def _verify(model, data, first, second, cmp, linear_run, st, say):
    """Verify the shortlist (the second stage only when the first explains nothing); rank by
    BIC on the steps every recalibrated model converged at."""

    def job(f, n_starts=0, seed=0):
        return VerifyJob(
            model.to_toml(), model.source, str(data.path), None, f.candidate, dict(f.values),
            dict(f.known), None if linear_run is None else str(linear_run),
            st.verify_iterations, n_starts, seed,
        )  # fmt: skip

    short = list(first)
    with open_executor(min(st.workers, max(len(first), 1))) as ex:
        done = run_jobs(run_verify, [job(f) for f in first], ex)
        say("verified", {"n": len(done), "best_rms": min(v.rms_over_noise() for v in done)})
        if min(v.rms_over_noise() for v in done) > st.explained_rms and second:
            done += run_jobs(run_verify, [job(f) for f in second], ex)
            short += second
            say("verified", {"n": len(done), "best_rms": min(v.rms_over_noise() for v in done)})
        # strong effects: more starts for the best two when none reached the noise
        order = np.argsort([v.chi2_per_dof() for v in done])
        if st.n_starts > 0 and done[order[0]].rms_over_noise() > st.explained_rms:
            again = [int(i) for i in order[:2] if not done[i].failed]
            say("restart", {"n": len(again)})
            retry = [job(short[i], st.n_starts, 1) for i in again]
            for i, v in zip(again, run_jobs(run_verify, retry, ex), strict=True):
                if v.chi2_per_dof() < done[i].chi2_per_dof():
                    v.seconds += done[i].seconds
                    done[i] = v
    z0 = 2 * np.abs(cmp.residual) ** 2
    base_step = z0.sum(axis=(1, 2))
    base_step[~np.all(np.isfinite(z0), axis=(1, 2))] = np.nan
    # a recalibrated model that fails on many steps the model solves is not comparable
    n_base = int(np.isfinite(base_step).sum())
    keep = [
        (f, v) for f, v in zip(short, done, strict=True)
        if not v.failed and np.isfinite(v.step_chi2[np.isfinite(base_step)]).sum() >= 0.9 * n_base
    ]  # fmt: skip
    common = np.isfinite(base_step)
    for _, v in keep:
        common &= np.isfinite(v.step_chi2)
    vps = int(2 * z0.shape[1] * z0.shape[2])
    n = int(common.sum()) * vps
    if n == 0:
        return [], math.nan
    n_known = len(model.parameter_names(group="nonlinear", calibrate=True))
    model_bic, _ = information_criteria(float(base_step[common].sum()), n, n_known)
    scored = []
    for f, v in keep:
        k = n_known + f.candidate.n_params
        bic, _ = information_criteria(float(v.step_chi2[common].sum()), n, k)
        scored.append((bic, f, v))
    if not scored:
        return [], model_bic
    scored.sort(key=lambda t: t[0])
    best = scored[0][0]
    ranked = []
    tied = sorted(
        [t for t in scored if t[0] - best <= st.tie_bic],
        key=lambda t: (t[1].candidate.n_params, t[0]),
    )
    rest = [t for t in scored if t[0] - best > st.tie_bic]
    for i, (bic, f, v) in enumerate(tied + rest):
        ranked.append(
            RankedCandidate(
                rank=i + 1, group=1 if i < len(tied) else i - len(tied) + 2,
                candidate=f.candidate, bic=bic, delta_bic=bic - model_bic,
                rms_over_noise=v.rms_over_noise(common), verified=v, screen=f,
            )
        )  # fmt: skip
    return ranked, model_bic
