"""The ranking rules: a tie ordered by the fit, the refinements of each location kind bounded."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from analysis.diagnosis.diagnose import _rank
from analysis.diagnosis.result import DiagnosisSettings
from analysis.diagnosis.screen import information_criteria

N_STEPS, PER_STEP = 100, 6


def _verified(chi2_total: float):
    steps = np.full(N_STEPS, chi2_total / N_STEPS)
    return SimpleNamespace(
        failed=False,
        step_chi2=steps,
        values_per_step=PER_STEP,
        rms_over_noise=lambda common=None: float(np.sqrt(chi2_total / (N_STEPS * PER_STEP))),
    )


def _origin(label: str, n_params: int):
    return SimpleNamespace(candidate=SimpleNamespace(label=label, n_params=n_params))


def test_a_tie_is_ordered_by_bic_not_by_parameter_count() -> None:
    model = SimpleNamespace(parameter_names=lambda group, calibrate: ["k_c", "gap", "v_c"])
    refit = _verified(6000.0)
    n = N_STEPS * PER_STEP
    # three parameters that fit better than one, by less than the tie's 10 BIC
    few, many = _origin("one parameter", 1), _origin("three parameters", 3)
    chi2_few = 700.0
    bic_few = information_criteria(chi2_few, n, 3 + 1)[0]
    # the three-parameter law 4 BIC better, its two extra parameters charged:
    # BIC = N ln(RSS / N) + k ln N with k = 3 known + 3 of its own
    chi2_many = n * np.exp((bic_few - 4.0 - (3 + 3) * np.log(n)) / n)
    ranked, _ = _rank(
        model,
        refit,
        [few, many],
        [_verified(chi2_few), _verified(chi2_many)],
        DiagnosisSettings(),
    )
    assert [r.candidate.label for r in ranked] == ["three parameters", "one parameter"]
    assert [r.group for r in ranked] == [1, 1]  # still a tie, said to be one
    assert abs((ranked[1].bic - ranked[0].bic) - 4.0) < 1e-6


def test_the_refinements_of_a_kind_are_every_law_at_its_best_locations() -> None:
    from analysis.diagnosis.candidates import Location
    from analysis.diagnosis.diagnose import REFINED_LOCATIONS, _class_leaders

    def fit(kind: str, where: str, law: str, bic: float):
        loc = Location(where, kind_=kind)
        return SimpleNamespace(candidate=SimpleNamespace(location=loc, law=law), bic=bic)

    laws = ("cubic", "contact", "damper")
    # five springs; each stands out under one law (its best BIC), the others score alike
    fits = [
        fit("spring", f"spring {i}", law, -100.0 * i if law == laws[i % 3] else 0.0)
        for i in range(5)
        for law in laws
    ]
    fits.append(fit("point", "point 7", "cubic", -1e4))  # another kind, never refined here
    leaders = _class_leaders(fits, "spring")
    kept = {f.candidate.location.name for f in leaders}
    assert kept == {f"spring {i}" for i in range(5)[-REFINED_LOCATIONS:]}
    assert len(leaders) == REFINED_LOCATIONS * len(laws)


def test_the_best_linear_candidate_at_a_point_walks_to_the_linear_tests_next_points(
    reference_model, monkeypatch
) -> None:
    """A spring at a point that explains the misfit goes on to the same law at the linear
    test's next two points (by its ranking, masses and the joint's spring left aside), each
    verified from its own recalibration on the linear test; one at a joint goes nowhere."""
    import importlib

    from analysis.diagnosis.candidates import default_candidates
    from analysis.diagnosis.linear_screen import LinearFit
    from analysis.diagnosis.policy import FitSummary, Policy
    from analysis.diagnosis.verify import Verified

    dg = importlib.import_module("analysis.diagnosis.diagnose")  # the package names a function so
    cands = {c.label: c for c in default_candidates(reference_model)}
    order = [
        "linear_spring at point 7",
        "mass at point 6",
        "linear_spring at point 6",
        "compliant joint clamp rz (linear spring)",
        "linear_spring at point 5",
        "linear_spring at point 4",
    ]
    lin_fits = [
        LinearFit(cands[label], 1.0 + i, 100, 6, float(i), model_toml=f"toml of {label}")
        for i, label in enumerate(order)
    ]

    def verified(cand, chi2_per_dof: float) -> Verified:
        return Verified(cand, {}, np.full(N_STEPS, chi2_per_dof * PER_STEP), PER_STEP, "")

    asked = []

    def fake_verify(job):
        asked.append(job)
        return verified(job.candidate, 1.2)

    monkeypatch.setattr(dg, "run_verify", fake_verify)
    st = DiagnosisSettings()
    refit = verified(None, 400.0)
    jobs = dg._Jobs("model text", "source", "data.h5", "linear.h5", st)
    sc = SimpleNamespace(lin_fits=lin_fits, fits=[], screen=None)
    for first, walked in ((0, ["linear_spring at point 6", "linear_spring at point 5"]), (3, [])):
        asked.clear()
        run = dg._Verifying(
            [lin_fits[first]],
            [verified(lin_fits[first].candidate, 1.0)],
            refit,
            Policy(st, FitSummary.of(refit)),
        )
        dg._walk_from_best(run, sc, jobs, None, lambda event: None)
        assert [o.candidate.label for o in run.origin[1:]] == walked
        assert [j.start_toml for j in asked] == [f"toml of {label}" for label in walked]
        assert len(run.done) == 1 + len(walked)
