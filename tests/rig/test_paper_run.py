"""Acceptance: the paper's whole run (224 steps) on the simulated rig with the reference truth.

The reference setup samples at 25.6 kHz; this test runs at 10.24 kHz (realised fundamentals
within 2e-3 of the plan) to stay within the test budget: about 40 s in fast mode.
"""

import numpy as np
import pytest

from analysis.measurement_file import read_measurement
from rig.config.plans import load_plan
from tests.rig.rig_helpers import run_on_sim, setup_at


@pytest.mark.slow
def test_paper_run_on_the_reference_truth(tmp_path):
    plan = load_plan("paper")
    summary, run, daq = run_on_sim(plan, tmp_path / "paper.h5", setup=setup_at(10240.0))
    assert summary.status == "success", summary.message
    data = read_measurement(tmp_path / "paper.h5")
    assert data.complete and data.n_steps == 224
    assert sorted(data.plan_index) == list(range(224))
    # the force controller reaches its (default) tolerances at >= 99 % of the steps, with a
    # median of <= 3 measurements per step
    assert np.mean(data.control_converged) >= 0.99
    assert np.median(data.control_iterations) <= 3
    converged = data.control_converged
    target = data.force_targets[data.level_index, 0]
    assert np.all(np.abs(np.abs(data.force[converged, 0]) / np.abs(target[converged]) - 1) < 0.02)
    # realised frequencies follow the plan: 21-40 Hz, refined to 0.1 Hz in 24-28 Hz
    rel = np.abs(data.frequency_hz / data.frequency_target_hz - 1)
    assert np.all(rel < 2e-3)
    # fast mode: not paced by the clock (a paced run is 1x; about 25x on an idle machine, the
    # bound leaves room for a loaded one)
    assert summary.rig_time_s > 3 * summary.wall_s
    # the force is recorded at orders 4-8 too (not controlled): at the noise away from the
    # contact, and where the tip strikes the stop several per cent of the fundamental
    assert data.extra_orders == (4, 5, 6, 7, 8)
    push = np.abs(data.extra_force).max(axis=1) / np.abs(data.force[:, 0])
    snr = (np.abs(data.extra_force) / np.maximum(data.extra_force_std, 1e-300)).max(axis=1)
    free = data.frequency_hz < 21.5  # 21 Hz: the tip stays off the stop at every level
    assert push[free].max() < 2e-3 and np.median(snr[free]) < 5
    assert push.max() > 0.03 and snr.max() > 100
