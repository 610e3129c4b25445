"""What a diagnosis does next, given the results so far: the scheduling rules, apart from how
the fits are run.

Every rule here is a plain function of typed results (:class:`FitSummary`, one per fit) and the
settings, with no processes, models or files, so each can be tested on a hand-made table. The
rules themselves, why each exists and the case that first needed it, are the table in
``docs/diagnosis.md`` ("The rules that find strong effects"); :mod:`analysis.diagnosis.diagnose`
runs what these functions ask for.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

from analysis.diagnosis.result import DiagnosisSettings

__all__ = ["FitSummary", "Policy", "Walk", "simplest_of_next", "tie_groups"]

#: Where the best verified candidate goes on after the first verifications: its law at the next
#: measured points, the next laws at its (unmeasured) location, or nowhere.
Walk = Literal["points", "laws"] | None


class _Fit(Protocol):
    """What a verification offers the policy (:class:`~analysis.diagnosis.verify.Verified`)."""

    @property
    def failed(self) -> bool: ...

    @property
    def stopped(self) -> bool: ...

    evaluations: int

    def chi2_per_dof(self) -> float: ...

    def last_decrease(self) -> float: ...


@dataclass(frozen=True)
class FitSummary:
    """One fit as the policy reads it.

    Parameters
    ----------
    chi2_per_dof : float
        Chi-square per degree of freedom on the fitted steps, with the file's uncertainties
        (``inf`` for a failed fit).
    failed : bool
        The fitted model converged at no step.
    stopped : bool
        The fit was stopped before it converged (for its work allowance, or as hopeless).
    last_decrease : float
        Share by which its last iteration lowered the metric.
    spent : float
        What the fit used of the stage's allowance: its evaluations of the objective
        (``DiagnosisSettings.budget_evaluations``).
    """

    chi2_per_dof: float
    failed: bool = False
    stopped: bool = False
    last_decrease: float = 0.0
    spent: float = 0.0

    @property
    def rms_over_noise(self) -> float:
        return math.sqrt(self.chi2_per_dof)

    @classmethod
    def of(cls, v: _Fit) -> FitSummary:
        return cls(v.chi2_per_dof(), v.failed, v.stopped, v.last_decrease(), v.evaluations)


@dataclass(frozen=True)
class Policy:
    """The rules of one diagnosis: its settings and the model's own parameters recalibrated
    (``refit``, the baseline every candidate must beat)."""

    st: DiagnosisSettings
    refit: FitSummary

    # -- before the verifications -------------------------------------------------------------

    def adequate(self) -> bool:
        """The recalibrated model is at the noise: the model was only mis-calibrated."""
        return self.refit.rms_over_noise <= self.st.adequate_rms

    def rescreen(self, calibrated_rms: float) -> bool:
        """The recalibrated model is far below the calibrated one (``calibrated_rms``, its
        residual over the noise): the calibration was a poor start, and the screen runs again
        from the recalibrated model."""
        r = self.refit
        return not r.failed and r.rms_over_noise <= self.st.rescreen_ratio * calibrated_rms

    def settled(self, calibrated_rms: float) -> bool:
        """Nothing to verify yet from the calibrated model: the recalibrated one is at the noise
        or the screen runs again from it."""
        return self.adequate() or self.rescreen(calibrated_rms)

    @property
    def bar(self) -> float:
        """A candidate no better than the model recalibrated without it stops early."""
        return self.refit.chi2_per_dof

    # -- the stage's allowance and the stop ---------------------------------------------------

    def left(self, done: Sequence[FitSummary]) -> float:
        """What is left of the stage's allowance after ``done``."""
        return self.st.budget_evaluations - sum(f.spent for f in done)

    def enough(self, done: Sequence[FitSummary]) -> bool:
        """The optional picks stop: one fit is at the noise, or the stage's allowance is spent."""
        return any(f.rms_over_noise <= self.st.adequate_rms for f in done) or self.left(done) <= 0

    def unexplained(self, done: Sequence[FitSummary]) -> bool:
        """No fit so far reaches the explained level."""
        best = min((f.rms_over_noise for f in done), default=math.inf)
        return best > self.st.explained_rms

    # -- fits that go on ----------------------------------------------------------------------

    def promising(self, f: FitSummary) -> bool:
        """The fit went most of the way: a strong effect's, not one that explains little."""
        return f.rms_over_noise <= self.st.restart_fraction * self.refit.rms_over_noise

    def goes_on_at_once(self, f: FitSummary) -> bool:
        """A fit that went most of the way but not to the explained level goes on as soon as it
        finishes (beside the stage's last fits, not after them)."""
        return not f.failed and self.promising(f) and f.rms_over_noise > self.st.explained_rms

    def to_continue(self, done: Sequence[FitSummary], continued: Sequence[int] = ()) -> list[int]:
        """Indices of the fits that go on from where they stopped when none explains the
        misfit: at most two (best first) with those in ``continued`` (gone on already). Those
        that went most of the way go on in any case; those stopped while still falling fast
        (``continue_decrease``) only while the stage's allowance lasts."""
        if not self.unexplained(done):
            return []
        allowance = self.left(done) > 0
        going = [
            i
            for i, f in enumerate(done)
            if i not in continued
            and not f.failed
            and (
                self.promising(f)
                or (f.stopped and f.last_decrease >= self.st.continue_decrease and allowance)
            )
        ]
        going.sort(key=lambda i: done[i].chi2_per_dof)
        return going[: max(2 - len(continued), 0)]

    # -- after the first verifications --------------------------------------------------------

    def walk_to(self, kind: str | None, best: FitSummary) -> Walk:
        """Where the best verified candidate goes on: ``kind`` is its location's kind (None:
        nowhere). From a measured point (``"point"``), its law at the next points when it
        explains the misfit or went most of the way; from an unmeasured location, the next
        laws there, even at the noise: look-alike laws there screen alike (the screen reads
        the place's states coarsely), so the first verified is not yet the best, and only the
        fit orders them or says they tie. (A linear candidate, ranked by the linear test and
        not by the screen, goes on from a point only, to its law at the next points.)"""
        if kind is None or best.failed:
            return None
        rms = best.rms_over_noise
        if kind == "point":
            return "points" if rms <= self.st.explained_rms or self.promising(best) else None
        return "laws"

    def look_alike(self, best: FitSummary) -> bool:
        """The best's law goes to its look-alike places (one spring of its group, its point's
        element to a nearby node, ...) when it explains the misfit or went most of the way:
        where it explains little, no place of it is the answer."""
        return not best.failed and (
            best.rms_over_noise <= self.st.explained_rms or self.promising(best)
        )

    def second_stage(self, done: Sequence[FitSummary], n_second: int) -> bool:
        """The short list's second stage runs: none explains the misfit and allowance is left."""
        return n_second > 0 and self.unexplained(done) and self.left(done) > 0

    def restarts(self, done: Sequence[FitSummary]) -> list[int]:
        """Indices of the fits given further starts: the best two (not failed), only when the
        best is short of the explained level but went most of the way (a strong effect in a
        local minimum) and allowance is left."""
        if self.st.n_starts <= 0 or not done:
            return []
        order = sorted(range(len(done)), key=lambda i: done[i].chi2_per_dof)
        best = done[order[0]]
        if best.rms_over_noise <= self.st.explained_rms or not self.promising(best):
            return []
        if self.left(done) <= 0:
            return []
        return [i for i in order[:2] if not done[i].failed]

    # -- the ranking --------------------------------------------------------------------------

    def verdict(self, best_rms: float | None, best_delta_bic: float | None) -> str:
        """``"explained"`` when the best candidate reaches the explained level and beats the
        recalibrated model by BIC, else ``"unexplained"``."""
        if best_rms is None or best_delta_bic is None:
            return "unexplained"
        ok = best_rms <= self.st.explained_rms and best_delta_bic < 0
        return "explained" if ok else "unexplained"


def tie_groups(bics: Sequence[float], tie_bic: float) -> list[int]:
    """The group of each candidate, ``bics`` ascending: 1 for those within ``tie_bic`` of the
    best (a tie, kept in BIC order), then one each."""
    if not bics:
        return []
    n_tied = sum(b - bics[0] <= tie_bic for b in bics)
    return [1 if i < n_tied else i - n_tied + 2 for i in range(len(bics))]


def simplest_of_next(n_params: Sequence[int], bics: Sequence[float], n: int) -> list[int]:
    """Of the next ``n + 1`` laws at a location by BIC, the ``n`` with the fewest parameters
    (look-alike laws at a DOF no sensor measures screen alike): their indices."""
    near = sorted(range(len(bics)), key=lambda i: bics[i])[: n + 1]
    return sorted(near, key=lambda i: (n_params[i], bics[i]))[:n]
