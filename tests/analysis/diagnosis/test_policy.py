"""The diagnosis's scheduling rules on hand-made result tables: no processes, no models."""

from __future__ import annotations

import math

import pytest

from analysis.diagnosis.policy import FitSummary, Policy, simplest_of_next, tie_groups
from analysis.diagnosis.result import DiagnosisSettings

ST = DiagnosisSettings()


def fit(rms: float, *, stopped: bool = False, fall: float = 0.0, spent: float = 0.0, failed=False):
    """A fit at ``rms`` x the noise."""
    return FitSummary(math.inf if failed else rms**2, failed, stopped, fall, spent)


def policy(refit_rms: float, **settings) -> Policy:
    st = DiagnosisSettings(**settings) if settings else ST
    return Policy(st, fit(refit_rms))


def test_the_summary_reads_a_verification() -> None:
    import numpy as np

    from analysis.diagnosis.verify import Verified

    v = Verified(
        None,
        {},
        np.array([8.0, 8.0, np.nan]),
        2,
        "",
        history=[{"chi2_per_dof": 10.0}, {"chi2_per_dof": 4.0}],
        message="stopped: the evaluations allowed are used",
        evaluations=14,
    )
    s = FitSummary.of(v)
    assert s.chi2_per_dof == pytest.approx(4.0) and s.rms_over_noise == pytest.approx(2.0)
    assert s.stopped and not s.failed and s.spent == 14
    assert s.last_decrease == pytest.approx(0.6)


@pytest.mark.parametrize(
    ("refit_rms", "calibrated_rms", "adequate", "rescreen"),
    [
        (1.2, 40.0, True, True),  # at the noise (and far below the calibration)
        (19.0, 40.0, False, True),  # below half the calibrated model's residual
        (21.0, 40.0, False, False),
        (1.4, 1.45, True, False),
    ],
)
def test_before_the_verifications(refit_rms, calibrated_rms, adequate, rescreen) -> None:
    p = policy(refit_rms)
    assert p.adequate() is adequate
    assert p.rescreen(calibrated_rms) is rescreen
    assert p.settled(calibrated_rms) is (adequate or rescreen)
    assert p.bar == pytest.approx(refit_rms**2)
    # a failed recalibration never restarts the screen
    assert not Policy(ST, fit(0.0, failed=True)).rescreen(calibrated_rms)


def test_the_optional_picks_stop_at_the_noise_or_when_the_allowance_is_spent() -> None:
    p = policy(30.0)
    half = ST.budget_evaluations / 2
    assert not p.enough([fit(10.0, spent=half), fit(5.0, spent=half - 1)])
    assert p.enough([fit(10.0, spent=half), fit(5.0, spent=half)])
    assert p.enough([fit(ST.adequate_rms, spent=1.0)])
    assert p.left([fit(3.0, spent=10.0)]) == ST.budget_evaluations - 10.0
    assert p.unexplained([fit(ST.explained_rms * 1.01)])
    assert not p.unexplained([fit(9.0), fit(ST.explained_rms)])
    assert p.unexplained([])


def test_a_fit_that_went_most_of_the_way_goes_on() -> None:
    """Once the allowance is spent only fits at a fifth of the recalibrated model's residual or
    less go on; with allowance left, fits stopped while still falling fast too; two at most,
    best first, counting those gone on already; none once one explains the misfit."""
    p = policy(100.0)
    spent = ST.budget_evaluations
    done = [
        fit(70.0, stopped=True, fall=0.6),  # falling fast but far
        fit(2.8, stopped=True, fall=0.005),  # most of the way
        fit(19.0, fall=0.005),  # a fifth of 100 or less, converged
        fit(50.0, fall=0.005),
    ]
    assert p.to_continue([*done, fit(60.0, spent=spent)]) == [1, 2]
    assert p.to_continue(done) == [1, 2]
    assert p.to_continue([done[0], done[3]]) == [0]
    assert p.to_continue([done[0], done[3], fit(60.0, spent=spent)]) == []
    assert p.to_continue(done, continued=[1]) == [2]
    assert p.to_continue(done, continued=[1, 2]) == []
    assert p.to_continue([*done, fit(1.9)]) == []  # explained
    assert p.goes_on_at_once(done[1])
    assert not p.goes_on_at_once(fit(1.9))  # explained already
    assert not p.goes_on_at_once(done[0])  # explains little
    assert not p.goes_on_at_once(fit(2.8, failed=True))


@pytest.mark.parametrize(
    ("kind", "best_rms", "refit_rms", "walk"),
    [
        ("point", 1.27, 32.8, "points"),  # explains it
        ("point", 6.0, 32.8, "points"),  # 6 / 32.8 < 0.2: most of the way
        ("point", 1.9, 5.6, "points"),
        ("point", 2.5, 5.6, None),  # neither
        ("point", 321.0, 533.0, None),
        ("springs", 1.02, 32.8, "laws"),  # at the noise: a look-alike law may fit better
        ("springs", 1.8, 32.8, "laws"),
        ("joint", 40.0, 32.8, "laws"),
        (None, 3.0, 32.8, None),  # a linear candidate
    ],
)
def test_where_the_best_walks(kind, best_rms, refit_rms, walk) -> None:
    assert policy(refit_rms).walk_to(kind, fit(best_rms)) == walk


def test_the_second_stage_and_the_restarts() -> None:
    p = policy(100.0)
    spent = fit(90.0, spent=ST.budget_evaluations)
    assert p.second_stage([fit(10.0)], 2)
    assert not p.second_stage([fit(10.0)], 0)
    assert not p.second_stage([fit(1.5)], 2)
    assert not p.second_stage([fit(10.0), spent], 2)
    # restarts: the best two not failed, when the best went most of the way short of explained
    done = [fit(30.0), fit(8.0), fit(0.0, failed=True), fit(12.0)]
    assert p.restarts(done) == [1, 3]
    assert p.restarts([fit(8.0), fit(0.0, failed=True)]) == [0]
    assert p.restarts([fit(30.0), fit(25.0)]) == []  # explains too little
    assert p.restarts([fit(1.5), fit(8.0)]) == []  # explained
    assert p.restarts([fit(8.0), spent]) == []
    assert policy(100.0, n_starts=0).restarts(done) == []
    assert p.restarts([]) == []


def test_the_tie_groups_and_the_verdict() -> None:
    assert tie_groups([-500.0, -495.0, -490.0, -489.0, -300.0], 10.0) == [1, 1, 1, 2, 3]
    assert tie_groups([-500.0, -300.0], 10.0) == [1, 2]
    assert tie_groups([], 10.0) == []
    p = policy(30.0)
    assert p.verdict(1.9, -40.0) == "explained"
    assert p.verdict(2.1, -40.0) == "unexplained"
    assert p.verdict(1.5, 3.0) == "unexplained"  # no better than the model by BIC
    assert p.verdict(None, None) == "unexplained"


def test_the_simplest_of_the_next_laws() -> None:
    """The two simplest of the next three by BIC; among equals in parameters, the better."""
    n_params = [3, 3, 2, 1, 1]
    bics = [-22123.0, -19043.0, -18942.0, -15960.0, -100.0]
    assert simplest_of_next(n_params, bics, 2) == [2, 0]
    assert simplest_of_next([1, 1, 1], [-5.0, -9.0, -7.0], 2) == [1, 2]
    assert simplest_of_next([], [], 2) == []


@pytest.mark.parametrize(
    ("best_rms", "refit_rms", "failed", "goes"),
    [
        (1.1, 3.0, False, True),  # explains the misfit
        (2.5, 17.0, False, True),  # short of it, but went most of the way (2.5 <= 0.2 x 17)
        (2.5, 3.0, False, False),  # explains little: none of its places is the answer
        (1.0, 3.0, True, False),  # a failed fit has no law to move
    ],
)
def test_the_best_goes_to_its_look_alike_places(best_rms, refit_rms, failed, goes) -> None:
    assert policy(refit_rms).look_alike(fit(best_rms, failed=failed)) is goes
