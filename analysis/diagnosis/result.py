"""Settings and result of a diagnosis: the ranking, the verdict, the summary in words."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from analysis.calibration.uncertainty import ADEQUATE_RMS
from analysis.diagnosis.candidates import Candidate
from analysis.diagnosis.compare import Comparison
from analysis.diagnosis.linear_screen import LinearFit
from analysis.diagnosis.readout import ForceReadout
from analysis.diagnosis.screen import ScreenFit
from analysis.diagnosis.signatures import Evidence
from analysis.diagnosis.verify import Verified
from analysis.settings import Integer, NonNegative, Positive, declare, settings

__all__ = ["Diagnosis", "DiagnosisSettings", "RankedCandidate"]

# The work allowances of a diagnosis, in evaluations of the objective (the balance on every
# fitted step, with or without its Jacobian). Counting work, not time, keeps a diagnosis the
# same on any machine and under any load (docs/diagnosis.md, "Limits"). A verification's 25
# leave its 8 iterations about two rejected trial steps each; the stage's 90 is about six
# verifications, the first ones and the walks; a continued fit's 65, two passes of 8
# iterations with their rejections.
VERIFY_EVALUATIONS = 25
CONTINUE_EVALUATIONS = 65
BUDGET_EVALUATIONS = 90


@settings()
class DiagnosisSettings:
    """Settings of :func:`~analysis.diagnosis.diagnose.diagnose` (declared once: the command
    line's options, the GUI's form and its tooltips come from these declarations)."""

    adequate_rms: Positive = declare(
        "A model whose residual (root of chi-square per degree of freedom) is at most this, as "
        "it is or with its own parameters recalibrated, is adequate: nothing is claimed.",
        ADEQUATE_RMS,
    )
    explained_rms: Positive = declare(
        "A verified candidate explains the misfit when it brings the residual to at most this "
        "(above adequate_rms: a law whose force switches sharply leaves some of its harmonics "
        "beyond the balance's).",
        2.0,
    )
    tie_bic: NonNegative = declare(
        "Candidates within this BIC of the best are reported as a group (a tie).", 10.0
    )
    linear_bic: NonNegative = declare(
        "A linear candidate is verified on the stepped sine when it lowers the linear test's "
        "BIC by more than this (and its metric to linear_ratio of the model's).",
        10.0,
    )
    linear_ratio: Positive = declare(
        "A linear candidate is verified only when it also brings the linear test's metric to "
        "this share of the model's or less (a BIC gain alone can be a fit of small errors).",
        0.3,
    )
    n_verify: Integer = declare(
        "Distinct laws of the screen verified in the full model (the best also at its second "
        "location).",
        2,
        ge=1,
    )
    n_walk: Integer = declare(
        "When the best verified candidate explains too little: its law at this many more "
        "measured points, or this many other laws at an unmeasured location.",
        2,
        ge=0,
    )
    n_refine: Integer = declare(
        "Best screened candidates refined by the screen's alternations.", 6, ge=0
    )
    verify_iterations: Integer = declare(
        "Levenberg-Marquardt iterations per verification.", 8, ge=1
    )
    verify_evaluations: Integer = declare(
        "Evaluations of the objective (the balance on every fitted step) allowed to one "
        "verification's Levenberg-Marquardt (its last iterate is scored).",
        VERIFY_EVALUATIONS,
        ge=1,
    )
    reweight_drop: Positive = declare(
        "A verification recomputes its weights when it stalls at a metric this many times "
        "below the one they were computed at.",
        2.0,
    )
    continue_evaluations: Integer = declare(
        "When nothing explains the misfit, verifications stopped at their allowance while "
        "still improving go on for this many evaluations of the objective.",
        CONTINUE_EVALUATIONS,
        ge=0,
    )
    continue_decrease: NonNegative = declare(
        "Verifications stopped at their allowance go on only if their last iteration lowered "
        "the metric by this share or more.",
        0.1,
    )
    n_starts: Integer = declare(
        "Further Latin hypercube starts for the best two when no candidate reaches the noise.",
        4,
        ge=0,
    )
    workers: Integer = declare(
        "Processes for the verifications and the linear screen (1: in this process).", 2, ge=1
    )
    n_harmonics: Integer = declare("Harmonics of the balance in every prediction.", 9, ge=1)
    n_time: Integer = declare("Time samples per period of the balance's AFT.", 128, ge=8)
    budget_evaluations: Integer = declare(
        "Continued fits, the second stage and further starts begin only while the "
        "verifications so far made fewer evaluations of the objective than this.",
        BUDGET_EVALUATIONS,
        ge=0,
    )
    restart_fraction: Positive = declare(
        "Further starts only for a best candidate that brought the recalibrated model's "
        "residual to this share or below (a strong effect in a local minimum).",
        0.2,
    )
    rescreen_ratio: NonNegative = declare(
        "Screen again from the model with its own parameters recalibrated when that brings "
        "the residual to this share of the calibrated model's or below (0: never).",
        0.5,
        lt=1,
    )
    locations: Literal["measured", "structure"] = declare(
        "The candidates' places (LOCATION_SCOPES): every place of the structure (each point "
        "in every direction it moves in, each spring alone and each group, every joint "
        "direction, pairs of nodes), or only the ones the sensors see directly (a faster "
        "screen that cannot reach one spring of a group or an element between two nodes).",
        "structure",
    )


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
        BIC minus that of the model with its own parameters recalibrated (negative: better).
    screen : ScreenFit or None
        The screen's fit (None for a candidate proposed by the linear test).
    linear : LinearFit or None
        The linear test's recalibration with this candidate.
    """

    rank: int
    group: int
    candidate: Candidate
    bic: float
    delta_bic: float
    rms_over_noise: float
    verified: Verified
    screen: ScreenFit | None = None
    linear: LinearFit | None = None

    def start_values(self) -> tuple[dict, dict]:
        """Start values ``(values, known)`` for :func:`~analysis.diagnosis.augment.augment`:
        the recalibrated values of this candidate's parameters and the model's own."""
        names = self.candidate.parameter_names()
        back = {v: k for k, v in names.items()}
        values = {back[n]: v for n, v in self.verified.parameters.items() if n in back}
        known = {n: v for n, v in self.verified.parameters.items() if n not in back}
        if self.screen is not None:
            values = {**self.screen.values, **values}
        return values, known

    def to_json(self) -> dict:
        return {
            "rank": self.rank,
            "group": self.group,
            "label": self.candidate.label,
            "kind": self.candidate.law.kind,
            "location": self.candidate.location.name,
            "moves_as": list(self.candidate.location.moves_as),
            "linear": self.candidate.is_linear,
            "n_params": self.candidate.n_params,
            "bic": self.bic,
            "delta_bic": self.delta_bic,
            "rms_over_noise": self.rms_over_noise,
            "parameters": self.verified.parameters,
            "seconds": self.verified.seconds,
            "evaluations": self.verified.evaluations,
        }


@dataclass
class Diagnosis:
    """Result of :func:`~analysis.diagnosis.diagnose.diagnose`.

    Attributes
    ----------
    verdict : {"adequate", "explained", "unexplained"}
    comparison : Comparison
        The model against the file (before any change).
    evidence : Evidence
    screen : list of ScreenFit
        Every screened candidate, best first; ``baseline`` the model's own fit.
    linear : list of LinearFit
        Linear candidates on the linear test, best first (empty without a linear test).
    refit : Verified or None
        The model with its own parameters recalibrated on the stepped sine.
    ranking : list of RankedCandidate
        Verified candidates, best first.
    model_bic : float
        BIC of ``refit`` on the ranking's steps.
    recommendation : dict or None
        For a group: the measurement that separates its members best.
    timings : dict of str to float, s
    rescreened : bool
        The screen ran from the model with its own parameters recalibrated (see
        :attr:`DiagnosisSettings.rescreen_ratio`); ``screen`` and ``baseline`` are that run's.
    readout : ForceReadout or None
        When nothing explains the misfit: what the data show about the missing law at the
        best verified candidate's location (:mod:`analysis.diagnosis.readout`).
    """

    verdict: str
    comparison: Comparison
    evidence: Evidence
    screen: list[ScreenFit] = field(default_factory=list)
    baseline: ScreenFit | None = None
    linear: list[LinearFit] = field(default_factory=list)
    refit: Verified | None = None
    ranking: list[RankedCandidate] = field(default_factory=list)
    model_bic: float = math.nan
    recommendation: dict | None = None
    timings: dict[str, float] = field(default_factory=dict)
    settings: DiagnosisSettings = field(default_factory=DiagnosisSettings)
    rescreened: bool = False
    readout: ForceReadout | None = None

    @property
    def group(self) -> list[RankedCandidate]:
        """The best and those tied with it, when the misfit is explained (else empty)."""
        if self.verdict != "explained":
            return []
        return [r for r in self.ranking if r.group == 1]

    @property
    def best(self) -> RankedCandidate | None:
        return self.ranking[0] if self.ranking and self.verdict == "explained" else None

    @property
    def refit_rms(self) -> float:
        return self.refit.rms_over_noise() if self.refit is not None else math.nan

    def rank_of(self, kind: str, location: str, side: int | None = None) -> int | None:
        """Rank (1 = best) of a law at a location (or at a place that moves as it,
        :attr:`Location.moves_as`) among the verified candidates, with ties: a candidate in
        the best group counts as first; None if not verified."""
        for r in self.ranking:
            c = r.candidate
            if (
                c.law.kind == kind
                and location in (c.location.name, *c.location.moves_as)
                and (side is None or c.law.options.get("side") == side)
            ):
                return 1 if r.group == 1 else r.rank
        return None

    def summary(self, n: int = 8) -> str:
        cmp = self.comparison
        lines = [
            f"model against the file: residual {cmp.rms_over_noise:.3g} x noise "
            f"(chi2/dof {cmp.chi2_per_dof:.3g})"
            + (
                f"; {cmp.left_out.size} step(s) not converged under force control left out"
                if cmp.left_out.size
                else ""
            ),
            self.evidence.summary(),
        ]
        if self.refit is not None:
            lines.append(
                f"the model's own parameters recalibrated: residual {self.refit_rms:.3g} x noise"
                " (" + ", ".join(f"{k} {v:.4g}" for k, v in self.refit.parameters.items()) + ")"
            )
        if self.verdict == "adequate":
            lines.append(
                "verdict: the model is adequate (residual at the noise"
                + (" once its own parameters are recalibrated" if self.refit is not None else "")
                + "); nothing is claimed"
            )
            return "\n".join(lines)
        if self.linear:
            lines.append(
                "linear test, each linear candidate with the linear parameters "
                "recalibrated (delta BIC against the model):"
            )
            for f in self.linear[:4]:
                lines.append(
                    f"  {f.delta_bic:10.1f}  {f.candidate.label}  "
                    + ", ".join(f"{k} {v:.4g}" for k, v in f.values.items())
                )
        if self.baseline is not None and self.screen:
            against = (
                "the model with its own parameters recalibrated" if self.rescreened else "the model"
            )
            lines.append(f"screen ({len(self.screen)} candidates; delta BIC against {against}):")
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
                    f"verdict: explained ({kind}), but a tie: within {self.settings.tie_bic:g} "
                    "BIC, which this test cannot separate: "
                    + "; ".join(r.candidate.label for r in g)
                    + f" (best fit first: {g[0].candidate.label}, by "
                    f"{g[1].bic - g[0].bic:.1f} BIC)"
                )
            for r in g:
                if r.candidate.location.moves_as:
                    lines.append(
                        f"  {r.candidate.location.name} moves as "
                        f"{', '.join(r.candidate.location.moves_as)}: an element at any of "
                        "these is the same to this structure"
                    )
        else:
            best = self.ranking[0] if self.ranking else None
            lines.append(
                "verdict: nothing in the element library explains the misfit"
                + (
                    f"; the best, {best.candidate.label}, leaves {best.rms_over_noise:.3g} x noise"
                    if best
                    else ""
                )
            )
            if self.readout is not None:
                lines.append("what the data show about the missing law: " + self.readout.text)
        if self.recommendation:
            lines.append("to separate the tied candidates: " + self.recommendation["text"])
        return "\n".join(lines)

    def to_json(self) -> dict:
        base = self.baseline.bic if self.baseline is not None else 0.0
        return {
            "verdict": self.verdict,
            "tie": len(self.group) > 1,
            "comparison": {
                "chi2_per_dof": self.comparison.chi2_per_dof,
                "rms_over_noise": self.comparison.rms_over_noise,
                "adequate": self.comparison.adequate,
                "left_out_steps": self.comparison.left_out.tolist(),
            },
            "evidence": self.evidence.to_json(),
            "refit": None
            if self.refit is None
            else {"rms_over_noise": self.refit_rms, "parameters": self.refit.parameters},
            "linear": [
                {"label": f.candidate.label, "delta_bic": f.delta_bic, "values": f.values}
                for f in self.linear[:10]
            ],
            "screen": [
                {
                    "label": f.candidate.label,
                    "delta_bic": f.bic - base,
                    "chi2_per_dof": f.chi2_per_dof,
                    "values": f.values,
                    "known": f.known,
                }
                for f in self.screen[:30]
            ],
            "rescreened": self.rescreened,
            "ranking": [r.to_json() for r in self.ranking],
            "group": [r.candidate.label for r in self.group],
            "recommendation": self.recommendation,
            "readout": None if self.readout is None else self.readout.to_json(),
            "timings": self.timings,
        }
