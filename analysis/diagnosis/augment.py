"""Add the chosen effect to the model, recalibrate everything, and watch the error fall.

>>> result = augment(model, data, diagnosis.group[0].candidate)      # doctest: +SKIP
>>> result.save("clearance_rig_augmented.toml")                       # doctest: +SKIP
>>> print(result.summary())                                            # doctest: +SKIP

The candidate is written into a copy of the model (new parameters, a new element or mass, a
joint released into a spring); the original is kept. Then everything is recalibrated the
paper's way: a linear effect first with the model's linear parameters on the linear
(random-excitation) test when one is given (damping equalization,
:func:`analysis.calibration.linear.calibrate_linear`), then the new parameters with the
model's own (the contact's, and the modal damping of the band's modes for a law that acts at
rest or a released joint) on the stepped-sine levels kept for calibration, by
Levenberg-Marquardt on the measured branch from the given values (a diagnosis' recalibrated
ones, or the screen's estimate) and, on request, Latin hypercube starts. Steps the rig did not
converge at under force control are left out. The error history (the model's, then every
accepted iteration) and the residual maps before and after are kept.

Then the balance is checked at the fitted values: the prediction at about twice the harmonics
(:func:`finer_balance`) against the fitted one, over the file's noise. A law whose force
switches sharply (friction) drives harmonics beyond the balance's, which the longer a record
(the smaller its noise) the more it shows; when the truncation reaches ``TRUNCATION_SHARE`` of
the noise the fit goes on at the finer balance, and both residuals are scored there (a
96-period clamp-friction run: 9 harmonics leave 2.02 x noise, 20 harmonics 0.998).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.calibration.lhs import Distribution
from analysis.calibration.nonlinear import fitted_rows
from analysis.diagnosis.candidates import Candidate
from analysis.diagnosis.compare import Comparison, compare
from analysis.diagnosis.refit import FitLimits, Starts, refit
from analysis.diagnosis.screen import Screen
from analysis.diagnosis.verify import damping_parameters, start_distributions
from analysis.events import Listener, StageDone
from analysis.measurement_file import SteppedSineData
from analysis.model import Model
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["TRUNCATION_SHARE", "AugmentResult", "augment", "finer_balance", "truncation_over_noise"]

log = logging.getLogger(__name__)

#: The augmented model is refitted at a finer balance when the coarser one's truncation (the
#: change of the prediction, over the noise, root mean square) reaches this: it then adds
#: about ``TRUNCATION_SHARE ** 2 / 2`` to the residual's square, more than a fit should leave.
TRUNCATION_SHARE = 0.3


@dataclass
class AugmentResult:
    """Result of :func:`augment`.

    Attributes
    ----------
    candidate : Candidate
    model : Model
        The augmented, recalibrated model.
    before, after : Comparison
        The original and the augmented model against the whole file.
    parameters : dict
        Every recalibrated parameter (model units).
    history : list of dict
        The error by iteration: ``stage`` ("model", "linear", "lm", then "reweighted" for
        the fits with the weights recomputed at the last one's values), ``iteration``,
        ``chi2_per_dof`` (on the fitted steps, with that fit's weights) and ``parameters``.
    calibration_levels_n : tuple of float
        Levels fitted (the rest validate).
    linear : dict or None
        The linear recalibration's parameters and metric.
    path : Path or None
        Where the model was saved.
    seconds : float
    balance : dict
        ``n_harmonics`` and ``n_time`` of the final balance (``before`` and ``after`` are
        scored there), ``truncation_over_noise``: the truncation of the balance first fitted
        (``checked_harmonics``, when checked) at the first fit's values (NaN when not
        checked), ``refined``: whether the fit went on at a finer balance.
    """

    candidate: Candidate
    model: Model
    before: Comparison
    after: Comparison
    parameters: dict[str, float]
    history: list[dict] = field(default_factory=list)
    calibration_levels_n: tuple[float, ...] = ()
    linear: dict | None = None
    path: Path | None = None
    seconds: float = 0.0
    balance: dict = field(default_factory=dict)

    @property
    def residual_drop(self) -> float:
        """Residual before over residual after (root chi-square per degree of freedom)."""
        return self.before.rms_over_noise / self.after.rms_over_noise

    def save(self, path: str | Path) -> Path:
        """Write the augmented model to a new file."""
        self.path = self.model.save(path)
        return self.path

    def level_rms(self, which: str = "after") -> dict[float, float]:
        """Residual over noise per level."""
        cmp = self.after if which == "after" else self.before
        out = {}
        for lv in sorted(set(cmp.level_n.tolist())):
            z = np.abs(cmp.residual[cmp.level_n == lv]) ** 2
            out[lv] = float(np.sqrt(np.nanmean(z)))
        return out

    def summary(self) -> str:
        lines = [
            f"added: {self.candidate.label}",
            f"residual: {self.before.rms_over_noise:.3g} -> {self.after.rms_over_noise:.3g} x "
            f"noise ({self.residual_drop:.3g}-fold drop); calibrated on "
            f"{', '.join(f'{x:g}' for x in self.calibration_levels_n)} N",
            "per level after: "
            + ", ".join(f"{lv:g} N {v:.3g}" for lv, v in self.level_rms("after").items()),
            "parameters: " + ", ".join(f"{k} {v:.5g}" for k, v in self.parameters.items()),
        ]
        b = self.balance
        if np.isfinite(b.get("truncation_over_noise", np.nan)):
            lines.append(
                f"balance: {b['checked_harmonics']} harmonics truncate "
                f"{b['truncation_over_noise']:.2g} x noise "
                + (
                    f"at the fitted values; fitted on at {b['n_harmonics']} harmonics"
                    if b.get("refined")
                    else "(kept)"
                )
            )
        lines.append("error history (chi2/dof on the fitted steps):")
        for h in self.history:
            lines.append(f"  {h['stage']:>10} {h['iteration']:3d}  {h['chi2_per_dof']:.4g}")
        if self.path is not None:
            lines.append(f"model written to {self.path}")
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "candidate": self.candidate.label,
            "rms_before": self.before.rms_over_noise,
            "rms_after": self.after.rms_over_noise,
            "residual_drop": self.residual_drop,
            "level_rms_after": {str(k): v for k, v in self.level_rms("after").items()},
            "parameters": self.parameters,
            "history": self.history,
            "calibration_levels_n": list(self.calibration_levels_n),
            "linear": self.linear,
            "path": None if self.path is None else str(self.path),
            "seconds": self.seconds,
            "balance": self.balance,
        }


def _predictor(model, data, n_harmonics, n_time) -> BranchMatchedPredictor:
    return BranchMatchedPredictor(model, data, n_harmonics=n_harmonics, n_time=n_time)


def finer_balance(n_harmonics: int, n_time: int) -> tuple[int, int]:
    """The balance a truncation check compares with: ``2 n_harmonics + 2`` harmonics (9 ->
    20) on twice the time samples."""
    return 2 * n_harmonics + 2, 2 * n_time


def truncation_over_noise(coarse: Comparison, fine: Comparison) -> float:
    """Root mean square change of the normalised residuals from ``coarse`` to ``fine`` (the
    same model and file at two balances): the coarser balance's truncation over the noise."""
    d = np.abs(coarse.residual - fine.residual) ** 2
    return float(np.sqrt(np.nanmean(d))) if np.isfinite(d).any() else float("nan")


def _calibration_levels(data: SteppedSineData, validation_level_n: float | None):
    levels = sorted(float(x) for x in data.levels_n)
    if validation_level_n is None:
        validation_level_n = levels[-1] if len(levels) >= 3 else 0.0
    return tuple(lv for lv in levels if not np.isclose(lv, validation_level_n))


def augment(
    model: Model,
    data: SteppedSineData,
    candidate: Candidate,
    *,
    values: Mapping[str, float] | None = None,
    known: Mapping[str, float] | None = None,
    linear_run: str | Path | None = None,
    validation_level_n: float | None = None,
    n_starts: int = 0,
    max_iterations: int = 30,
    reweight_passes: int = 1,
    seed: int = 0,
    out: str | Path | None = None,
    progress: Listener | None = None,
    n_harmonics: int = 9,
    n_time: int = 128,
    check_balance: bool = True,
) -> AugmentResult:
    """Add ``candidate`` to ``model`` and recalibrate everything.

    Parameters
    ----------
    model : Model
        The calibrated model (not changed).
    data : SteppedSineData
    candidate : Candidate
        E.g. the best of :func:`~analysis.diagnosis.diagnose.diagnose`.
    values, known : mapping, optional
        Start values of the candidate's parameters and of the model's own nonlinear ones
        (default: the screen's estimate for this candidate).
    linear_run : path, optional
        The random-excitation test: a linear effect is recalibrated there first.
    validation_level_n : float, optional
        Level kept out of the fit (default: the highest of three or more; 0 keeps none).
    n_starts : int
        Latin hypercube starts besides the given (or the screen's) values.
    max_iterations : int
    reweight_passes : int
        Fits again from the fitted values with the steps' weights (the force's error through
        the model) recomputed there, keeping the fit that scores best with its own weights
        (:func:`~analysis.diagnosis.refit.refit`): the first fit weighs the steps by the
        tangents of the model with the candidate's start values, which near a jump can be far
        from the fitted model's.
    seed : int
    out : path, optional
        Write the augmented model there (a new file).
    progress : callable, optional
        Receives :mod:`analysis.events`: the recalibration's starts and iterations
        (:func:`~analysis.diagnosis.refit.refit`) and a :class:`~analysis.events.StageDone`
        for the screen's estimate, the linear recalibration and the balance's check.
    n_harmonics, n_time : int
        Balance settings.
    check_balance : bool
        Check the balance's truncation at the fitted values and, where it reaches
        :data:`TRUNCATION_SHARE` of the noise, fit on at :func:`finer_balance`.

    Returns
    -------
    AugmentResult
    """
    t0 = time.perf_counter()
    say: Listener = progress or _ignore
    before = compare(model, data, predictor=_predictor(model, data, n_harmonics, n_time))
    if values is None:
        screen = Screen(
            model,
            data,
            predictor=_predictor(model, data, n_harmonics, n_time),
            locations=(candidate.location,),
        )
        fit = screen.fit(candidate)
        values, known = dict(fit.values), dict(fit.known) if known is None else known
        say(StageDone("screened", values=values))
    m2, new = _with_candidate(model, candidate, values, known)
    base_rows = fitted_rows(data, _calibration_levels(data, validation_level_n))
    z = np.abs(before.residual[base_rows]) ** 2
    history: list[dict] = [
        {"stage": "model", "iteration": 0, "chi2_per_dof": float(np.nanmean(z)), "parameters": {}}
    ]
    m2, new, linear_info = _linear_first(m2, new, candidate, linear_run, history, say)
    names = list(
        dict.fromkeys(
            [
                *new,
                *model.parameter_names(group="nonlinear", calibrate=True),
                *damping_parameters(candidate, m2, data),
            ]
        )
    )
    levels = _calibration_levels(data, validation_level_n)
    rows = fitted_rows(data, levels)

    plain = [n for n in names if not n.startswith("zeta_")]
    starts = Starts(
        distributions=start_distributions(m2, plain, {})
        | {n: Distribution("loguniform", 0.002, 0.05) for n in names if n.startswith("zeta_")},
        n_random=n_starts,
        n_lm=2 if n_starts else 1,
        seed=seed,
    )
    limits = FitLimits(max_iterations=max_iterations, reweight_passes=reweight_passes)
    r = refit(
        m2,
        data,
        names,
        rows=rows,
        starts=starts,
        limits=limits,
        progress=say,
        n_harmonics=n_harmonics,
        n_time=n_time,
    )
    history += [{"stage": "reweighted" if h.get("pass") else "lm", **h} for h in r.history]
    after = compare(r.model, data, predictor=_predictor(r.model, data, n_harmonics, n_time))
    balance = {
        "n_harmonics": n_harmonics,
        "n_time": n_time,
        "truncation_over_noise": float("nan"),
        "refined": False,
    }
    if check_balance:
        nh, nt = finer_balance(n_harmonics, n_time)
        fine = compare(r.model, data, predictor=_predictor(r.model, data, nh, nt))
        t = truncation_over_noise(after, fine)
        balance.update(truncation_over_noise=t, checked_harmonics=n_harmonics)
        say(
            StageDone(
                "balance checked",
                rms_over_noise=t,
                note=f"truncation at {n_harmonics} harmonics",
            )
        )
        if t >= TRUNCATION_SHARE:
            r = refit(
                r.model,
                data,
                names,
                rows=rows,
                limits=limits,
                progress=say,
                n_harmonics=nh,
                n_time=nt,
            )
            history += [{**h, "stage": "finer balance"} for h in r.history]
            before = compare(model, data, predictor=_predictor(model, data, nh, nt))
            after = compare(r.model, data, predictor=_predictor(r.model, data, nh, nt))
            balance.update(n_harmonics=nh, n_time=nt, refined=True)
    params = {**(linear_info["parameters"] if linear_info else {}), **r.parameters}
    result = AugmentResult(
        candidate,
        r.model,
        before,
        after,
        params,
        history,
        levels,
        linear_info,
        seconds=time.perf_counter() - t0,
        balance=balance,
    )
    if out is not None:
        result.save(out)
    log.info(
        "augmented with %s: %.3g -> %.3g x noise",
        candidate.label,
        before.rms_over_noise,
        after.rms_over_noise,
    )
    return result


def _with_candidate(model: Model, candidate: Candidate, values, known):
    """The model with the candidate at ``values`` and its own nonlinear parameters at
    ``known`` (within their bounds); also the candidate's new parameter names."""
    m2, new = candidate.apply(model, dict(values))
    if candidate.law.kind == "parameter":
        m2 = m2.with_values({candidate.parameter: values[candidate.parameter]})
    start = {}
    for n, v in (known or {}).items():
        if n in m2.parameters:
            p = m2.parameters[n]
            start[n] = float(np.clip(v, p.lower, p.upper))
    return m2.with_values(start), new


def _ignore(event) -> None:
    """The listener when none is given."""


def _linear_first(
    m2: Model, new: list, candidate: Candidate, linear_run, history: list, say: Listener
):
    """A linear effect recalibrated on the linear test first (its linear parameters then stay
    out of the stepped sine's fit), or, without the test, fitted there with the linear ones.
    Returns the model, the names to fit and the linear calibration's summary."""
    linear_info = None
    linear_params = m2.parameter_names(group="linear", calibrate=True)
    if candidate.is_linear and linear_run is not None:
        from analysis.calibration.linear import calibrate_linear

        res = calibrate_linear(
            m2, linear_run, parameters=tuple(linear_params), min_modes=min(4, len(linear_params))
        )
        m2 = res.model
        linear_info = {"parameters": res.parameters, "cost": res.cost}
        history.append(
            {
                "stage": "linear",
                "iteration": res.nit,
                "chi2_per_dof": float("nan"),
                "parameters": res.parameters,
            }
        )
        say(StageDone("linear recalibration", cost=res.cost, values=res.parameters))
        new = [n for n in new if m2.parameters[n].group != "linear"]
    elif candidate.is_linear:
        new = list(dict.fromkeys([*new, *linear_params]))
    return m2, new, linear_info
