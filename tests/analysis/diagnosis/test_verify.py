"""Verification in the full model: a candidate at unmeasured DOFs gets further starts, since the
screen reads its coefficients coarsely there."""

from __future__ import annotations

import pytest

from analysis.diagnosis import default_candidates
from analysis.diagnosis.diagnose import _other_laws, _shortlist, _walk_jobs
from analysis.diagnosis.policy import FitSummary, Policy
from analysis.diagnosis.result import DiagnosisSettings
from analysis.diagnosis.screen import ScreenFit
from analysis.diagnosis.signatures import Evidence
from analysis.diagnosis.verify import UNMEASURED_START_FACTORS, VerifyJob, run_verify
from tests.analysis.diagnosis.conftest import truth_as_model


def _candidate(model, label):
    return next(c for c in default_candidates(model) if c.label == label)


def _screened(model, label, bic=0.0, **kw) -> ScreenFit:
    """A screen's fit of the candidate ``label`` scoring ``bic``."""
    return ScreenFit(_candidate(model, label), 0.0, 1000, 1, bic, bic, **kw)


def _job(model, data_path, cand, values, **kw) -> VerifyJob:
    return VerifyJob(
        model.to_toml(),
        str(model.source),
        str(data_path),
        None,
        cand,
        dict(values),
        {},
        None,
        10,
        0,
        0,
        kw.pop("start_toml", None),
        9,
        128,
        60.0,
        **kw,
    )


def test_further_starts_only_for_coefficients_at_unmeasured_dofs(reference_model) -> None:
    from analysis.diagnosis.verify import _scaled_starts

    m = reference_model
    mounts = _candidate(m, "cubic_spring at springs k_mount")
    applied, _ = mounts.apply(m, {"k3": 1e12})
    starts = _scaled_starts(_job(m, "x.h5", mounts, {"k3": 1e12}), applied)
    assert starts == [
        {"k3_cubic_spring_springs_k_mount": 1e12 * f} for f in UNMEASURED_START_FACTORS
    ]
    # a clearance is not scaled, only the coefficients
    contact = _candidate(m, "hertz_contact (above) at springs k_mount")
    values = {"k_c": 1e6, "v": 10.0, "gap": 1e-4}
    applied, _ = contact.apply(m, values)
    for s in _scaled_starts(_job(m, "x.h5", contact, values), applied):
        assert not any(name.startswith("gap") for name in s) and len(s) == 2
    # a measured point, a candidate with no screen values, one already placed: no further starts
    point = _candidate(m, "cubic_spring at point 5")
    applied, _ = point.apply(m, {"k3": 1e8})
    assert _scaled_starts(_job(m, "x.h5", point, {"k3": 1e8}), applied) == []
    assert _scaled_starts(_job(m, "x.h5", mounts, {}), m) == []
    placed = _job(m, "x.h5", mounts, {"k3": 1e12}, start_toml=m.to_toml())
    assert _scaled_starts(placed, m) == []


@pytest.mark.slow
def test_mounts_screened_twice_too_stiff_still_reach_the_noise(runs, reference_model) -> None:
    """Started at twice the truth's k3 (a 48-period run of the benchmark screened 1.9 times),
    the mounts' hardening reaches the noise within 2 % of the truth's k3. (At the
    accelerometer noise of the other truths a fit from that start alone stopped at about twice
    the noise and the halved start was needed; at this truth's quieter accelerometers either
    start gets there, and from 2.5 times neither does.)"""
    data = runs("hardening_mounts")
    cand = _candidate(reference_model, "cubic_spring at springs k_mount")
    k3 = truth_as_model("hardening_mounts").parameters["k3_mount"].value
    v = run_verify(_job(reference_model, data.path, cand, {"k3": 2 * k3}))
    assert v.rms_over_noise() <= 1.1, v.message
    assert abs(v.parameters["k3_cubic_spring_springs_k_mount"] / k3 - 1) < 0.02


def test_unmeasured_picks_are_refined_whatever_their_first_pass(reference_model) -> None:
    """The hardening mounts of the benchmark: the screen's first pass scores the mounts' cubic
    spring worse than the model itself (the states there are read coarsely), refined it gains
    two thirds of the best law's BIC: it is verified right after the best law's two
    locations, ahead of the next law."""

    m = reference_model
    first_pass = {
        "hertz_contact (above) at point 6": -12516.0,
        "hertz_contact (above) at point 7": -12367.0,
        "cubic_spring at point 5": -12259.0,
        "linear_damper at springs k_mount": -1552.0,
        "cubic_spring at springs k_mount": 858.0,
        "coulomb_friction with a joint spring at joint clamp rz": 50000.0,
    }
    refined = {
        "cubic_spring at springs k_mount": -8405.0,
        "linear_damper at springs k_mount": -2866.0,
    }

    class Refiner:
        calls: list[str] = []

        def refined(self, f):
            self.calls.append(f.candidate.label)
            return _screened(
                m, f.candidate.label, min(f.bic, refined.get(f.candidate.label, f.bic))
            )

    screen = Refiner()
    fits = [_screened(m, label, bic) for label, bic in first_pass.items()]
    first, second = _shortlist(screen, fits, Evidence([]), 2, 0.0)
    labels = [f.candidate.label for f in first]
    assert labels == [
        "hertz_contact (above) at point 6",
        "hertz_contact (above) at point 7",
        "cubic_spring at springs k_mount",
        "cubic_spring at point 5",
    ]
    # every candidate at an unmeasured location is refined, not only the first pass's best
    assert set(screen.calls) == {label for label in first_pass if "at point" not in label}
    # the joint's candidate explains nothing: not picked as an unmeasured location's law
    assert all("joint" not in f.candidate.label for f in first)


def _verified(cand, rms: float, message: str = "", history=(), parameters=None):
    """A verification whose residual is ``rms`` x noise on every step."""
    import numpy as np

    from analysis.diagnosis.verify import Verified

    return Verified(
        cand,
        dict(parameters or {}),
        np.full(10, 2.0 * rms**2),
        2,
        "",
        history=list(history),
        message=message,
    )


def test_a_law_in_a_joint_has_no_neighbouring_point(reference_model) -> None:
    """The clamp friction's screen: the leading law sits in the clamp; the same law at a
    measured point (the bottom member) is another place, not a neighbour, and is not verified
    in the first stage (on the benchmark's run it converged at none of the fitted steps)."""

    m = reference_model
    bics = {
        "gap_spring (above) with a joint spring at joint clamp rz": -24535.0,
        "coulomb_friction with a joint spring at joint clamp rz": -23275.0,
        "gap_spring (above) at point 10": -20000.0,
        "cubic_spring at point 5": -15000.0,
    }
    fits = [_screened(m, label, bic) for label, bic in bics.items()]

    class Screen:
        def refined(self, f):
            return f

    first, _ = _shortlist(Screen(), fits, Evidence([]), 2, 0.0)
    labels = [f.candidate.label for f in first]
    assert labels[0] == "gap_spring (above) with a joint spring at joint clamp rz"
    assert "gap_spring (above) at point 10" not in labels
    assert "coulomb_friction with a joint spring at joint clamp rz" in labels


def test_the_best_law_walks_to_the_next_points_from_its_fit(reference_model) -> None:
    """The second stop of the benchmark: the screen ranks the contact above points 5, 6, 4
    and only then 7 (the truth); the first two verified, the law goes on at 4 and 7, each
    started from the best fit's values, not from the screen's."""

    m = reference_model
    points = (5, 6, 4, 7, 11)
    fits = [
        _screened(
            m,
            f"hertz_contact (above) at point {p}",
            -1e4 + i,
            values={"k_c": 1e5, "v": 1.0, "gap": 5e-4},
        )
        for i, p in enumerate(points)
    ]
    fits.insert(2, _screened(m, "cubic_spring at point 4"))
    best_cand = fits[0].candidate
    names = best_cand.parameter_names()
    fitted = {
        names["k_c"]: 9.2e5,
        names["v"]: 52.5,
        names["gap"]: 8.4e-4,
        "k_c": 4.69e5,
        "gap": 6.06e-4,
        "v_c": 27.1,
    }
    best = _verified(best_cand, 3.76, parameters=fitted)
    walk = _walk_jobs(best, fits, [fits[0].candidate, fits[1].candidate], 2)
    assert [f.candidate.label for f, _, _ in walk] == [
        "hertz_contact (above) at point 4",
        "hertz_contact (above) at point 7",
    ]
    for _, values, known in walk:
        assert values == {"k_c": 9.2e5, "v": 52.5, "gap": 8.4e-4}
        assert known == {"k_c": 4.69e5, "gap": 6.06e-4, "v_c": 27.1}


def test_a_fit_that_went_most_of_the_way_goes_on_as_soon_as_it_finishes(
    reference_model, monkeypatch
) -> None:
    """The clamp's friction stopped for time at 2.8 x noise (the model recalibrated: 100) as
    the third of four verifications on two processes: its continuation starts on the process
    it frees, ahead of the jobs not yet started, not after the stage's last job. A fit at the
    explained level or one that explains little does not go on at once."""
    import importlib
    from concurrent.futures import ThreadPoolExecutor

    dg = importlib.import_module("analysis.diagnosis.diagnose")
    st = DiagnosisSettings()
    c = _candidate(reference_model, "cubic_spring at point 5")
    policy = Policy(st, FitSummary.of(_verified(None, 100.0)))

    def at_once(v) -> bool:
        return policy.goes_on_at_once(FitSummary.of(v))

    order: list[str] = []
    rms = {"a": 50.0, "b": 2.8, "c": 70.0, "d": 60.0, "b+": 1.1}

    def fake_verify(job):
        order.append(job.source)
        return _verified(c, rms[job.source])

    def job(name: str) -> VerifyJob:
        return VerifyJob("", name, "x.h5", None, c, {}, {})

    def follow(i, v):
        return job("abcd"[i] + "+") if at_once(v) else None

    monkeypatch.setattr(dg, "run_verify", fake_verify)
    with ThreadPoolExecutor(1) as ex:
        ran, further = dg._run_verifications(
            ex, [job(n) for n in "abcd"], 4, lambda vs: False, 1, follow
        )
    assert order == ["a", "b", "b+", "c", "d"]
    assert sorted(ran) == [0, 1, 2, 3] and list(further) == [1]
    assert further[1].rms_over_noise() == pytest.approx(1.1)
    # in this process the same order; once a continuation is at the noise the jobs beyond
    # the essential ones are dropped
    order.clear()
    at_noise = lambda vs: any(v.rms_over_noise() <= 1.5 for v in vs)  # noqa: E731
    ran, further = dg._run_verifications(None, [job(n) for n in "abcd"], 2, at_noise, 1, follow)
    assert order == ["a", "b", "b+"] and sorted(ran) == [0, 1]
    # on two processes the jobs beyond the essential ones wait for those (not for their
    # continuations), then are dropped once a result (here the continuation) is at the noise
    order.clear()
    with ThreadPoolExecutor(1) as ex:
        ran, further = dg._run_verifications(ex, [job(n) for n in "abcd"], 2, at_noise, 2, follow)
    assert order == ["a", "b", "b+", "c"] and sorted(ran) == [0, 1, 2]
    rms["b+"] = 2.5
    order.clear()
    with ThreadPoolExecutor(1) as ex:
        ran, further = dg._run_verifications(ex, [job(n) for n in "abcd"], 2, at_noise, 2, follow)
    assert order == ["a", "b", "b+", "c", "d"] and sorted(ran) == [0, 1, 2, 3]


def test_at_an_unmeasured_location_the_simplest_of_the_next_laws_go_on(reference_model) -> None:
    """The mounts' hardening on a 96-period run: the contact at the mounts verified best but
    short of the noise; the next laws there by the refined screen are a two-sided gap, a gap
    spring and the (true) cubic spring; the two simplest of those three are verified next."""

    m = reference_model
    refined = {
        "hertz_contact (above) at springs k_mount": -22123.0,
        "two_sided_gap at springs k_mount": -19043.0,
        "gap_spring (above) at springs k_mount": -18942.0,
        "cubic_spring at springs k_mount": -15960.0,
        "coulomb_friction at springs k_mount": -10099.0,
        "hertz_contact (above) at point 7": -30000.0,
    }

    class Screen:
        def refined(self, f):
            return _screened(m, f.candidate.label, refined[f.candidate.label], refined=True)

    fits = [_screened(m, label) for label in refined]
    lead = fits[0].candidate
    laws = _other_laws(Screen(), fits, lead, [lead, fits[-1].candidate], 2)
    assert [f.candidate.label for f in laws] == [
        "cubic_spring at springs k_mount",
        "two_sided_gap at springs k_mount",
    ]
    assert all(f.refined for f in laws)
