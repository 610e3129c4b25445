"""The plan on the reference rig: the paper's findings, executors, the refinement study."""

from __future__ import annotations

import sys
import types
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

from analysis.planning import (
    Candidates,
    Configuration,
    FrequencyRange,
    PlanSettings,
    open_executor,
    paper_candidates,
    plan_tests,
)

from .conftest import REDUCED

CONTACT_RANGE = paper_candidates().ranges[0]  # [21-40] Hz


def test_contact_range_dominates_and_the_tip_sensor_is_in_the_top(reduced_plan):
    """The paper's Table 4: all of the best configurations use the [21-40] Hz range (the
    contact resonance), actuator 3, and the tip sensor 7 is among their sensors."""
    res = reduced_plan
    assert len(res.top) == 5
    assert all(t.configuration.frequency_range == CONTACT_RANGE for t in res.top)
    assert all(t.configuration.actuator == 3 for t in res.top)
    assert 7 in res.top[0].configuration.sensors
    assert sum(7 in t.configuration.sensors for t in res.top) >= 3
    # the nominal gap (1 mm) is not reached near the second resonance: no information there
    assert np.isfinite(res.best_by_range["[21-40]"])
    assert res.best_by_range["[141-160]"] == -np.inf
    # the ranking is ordered and the table lists the best ones first
    ld = res.ranking.log10_det[res.ranking.order]
    assert np.all(np.diff(ld[np.isfinite(ld)]) <= 0)
    assert [t.rank for t in res.top] == [1, 2, 3, 4, 5]
    assert res.top[0].log10_det == pytest.approx(ld[0] + res.log10_det_offset)
    third = res.configuration(3)
    assert third == res.top[2]
    assert res.rank_of(third.configuration) == third
    linear = Configuration(3, (5, 7), (4.0, 6.0), REDUCED.ranges[-1])  # no contact there
    assert res.rank_of(linear).log10_det == -np.inf
    assert res.rank_of(Configuration(3, (1, 7), (2.0, 4.0), CONTACT_RANGE)) is None
    # FIM^-1 of the chosen one is a covariance: symmetric positive definite
    inv = res.fim_inverse
    np.testing.assert_allclose(inv, inv.T, rtol=1e-10)
    assert np.all(np.linalg.eigvalsh(inv) > 0)
    ss = np.outer(res.scales, res.scales)  # compare in scaled units (entries of order 1)
    np.testing.assert_allclose((inv / ss) @ (res.fim * ss), np.eye(3), atol=1e-8)


def test_process_pool_gives_the_serial_result(rig, reduced_plan):
    with ProcessPoolExecutor(max_workers=2) as pool:
        par = plan_tests(rig, REDUCED, executor=pool, settings=PlanSettings(refine_band_hz=None))
    np.testing.assert_allclose(
        par.ranking.log10_det, reduced_plan.ranking.log10_det, rtol=1e-12, atol=0
    )
    assert np.array_equal(par.ranking.order, reduced_plan.ranking.order)
    np.testing.assert_allclose(par.fim, reduced_plan.fim, rtol=1e-12)
    assert par.top == reduced_plan.top


def test_refining_the_steps_lowers_the_kc_gap_correlation(rig):
    """The paper's Fig. 7: adding 0.1 Hz steps in 24-28 Hz to the 1 Hz plan lowers the
    correlation index of k_c and gap (0.56 -> 0.45 in the paper); here for the best
    configuration of the full plan (actuator 3, levels 3/5/6 N, sensors 5/6/7), by more
    than 0.1 in the whitened MAC and 0.02 in the plain FRF MAC."""
    best = Candidates(
        sensors=(5, 6, 7), actuators=(3,), levels_n=(3.0, 5.0, 6.0), ranges=(CONTACT_RANGE,)
    )
    res = plan_tests(rig, best, executor=None)
    assert res.n_configurations == 1
    assert res.refined is not None and res.refined.n_steps == 56
    before, after = res.correlations, res.refined
    assert after.mac[0, 1] < before.mac[0, 1] - 0.1
    assert after.mac_frf[0, 1] < before.mac_frf[0, 1] - 0.02
    for c in (before, after):
        np.testing.assert_allclose(np.diag(c.mac), 1.0)
        assert np.all((c.mac >= 0) & (c.mac <= 1 + 1e-12))


def test_a_configuration_outside_the_candidates_can_be_studied(rig):
    cand = Candidates(
        sensors=(6, 7),
        n_sensors=2,
        actuators=(3,),
        levels_n=(4.0,),
        n_levels=1,
        ranges=(CONTACT_RANGE,),
    )
    other = Configuration(3, (3, 7), (2.0, 6.0), FrequencyRange(24.0, 30.0, 1.0))
    res = plan_tests(
        rig, cand, executor=None, chosen=other, settings=PlanSettings(refine_band_hz=None)
    )
    assert res.chosen.rank is None and res.chosen.configuration == other
    assert res.chosen.log10_det == pytest.approx(np.log10(np.linalg.det(res.fim)), abs=1e-9)


def test_dask_scheduler_address_uses_the_clients_executor(monkeypatch):
    """With a scheduler address the executor comes from ``distributed.Client(address)``
    (imported only then) and the client is closed afterwards."""
    calls = []

    class Client:
        def __init__(self, address):
            calls.append(("open", address))
            self._pool = ThreadPoolExecutor(1)

        def get_executor(self):
            return self._pool

        def close(self):
            calls.append(("close",))
            self._pool.shutdown()

    monkeypatch.setitem(sys.modules, "distributed", types.SimpleNamespace(Client=Client))
    with open_executor(scheduler="tcp://lab-cluster:8786") as ex:
        assert ex.submit(pow, 2, 10).result() == 1024
    assert calls == [("open", "tcp://lab-cluster:8786"), ("close",)]
    with open_executor(workers=1) as ex:
        assert ex is None
    with pytest.raises(ValueError, match="workers"):
        with open_executor(workers=0):
            pass


def test_plan_rejects_unknown_points_and_parameters(rig):
    with pytest.raises(ValueError, match="Candidates.sensors: unknown measurement point"):
        plan_tests(rig, Candidates(sensors=(1, 2, 99)), executor=None)
    with pytest.raises(ValueError, match="Candidates.parameters: unknown parameter"):
        plan_tests(rig, Candidates(parameters=("k_c", "stiffness")), executor=None)
    with pytest.raises(ValueError, match="executor"):
        plan_tests(rig, REDUCED, executor="threads")
