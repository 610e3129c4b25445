"""The FIM against an independent computation, and its additivity over blocks."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.mhb.sweep import solve_steps
from analysis.planning import (
    Candidates,
    FrequencyRange,
    NoiseModel,
    PlanSettings,
    jacobian_mac,
    plan_tests,
)
from analysis.planning.information import (
    correlation_indices,
    information_blocks,
    whitened_jacobian,
)
from analysis.planning.sweeps import SweepJob, run_sweep
from analysis.system import build_problem

from .conftest import REDUCED

PARAMS = ("k_c", "gap", "v_c")


def _frf(model, omega, force, sensors):
    problem = build_problem(model, drive_point=3, output_points=sensors)
    sweep = solve_steps(problem, omega, force)
    assert sweep.converged.all()
    return sweep.outputs() / force[None, :, None]  # (steps, orders, sensors) m/N


def test_fim_equals_the_direct_sum_with_a_finite_difference_jacobian(rig):
    """FIM = sum_n sigma_n^-2 dz_n dz_n^T with dz from central differences of whole stepped
    sweeps (relative step 1e-4) and sigma_n from the noise model written out here: agreement
    to 2e-4 of sqrt(F_ii F_jj) (the sensitivities' validated accuracy)."""
    frange = FrequencyRange(24.0, 28.0, 1.0)  # 4 N at point 3: the tip hits the stop here
    cand = Candidates(
        sensors=(5, 7),
        n_sensors=2,
        actuators=(3,),
        levels_n=(4.0,),
        n_levels=1,
        ranges=(frange,),
    )
    result = plan_tests(rig, cand, executor=None, settings=PlanSettings(refine_band_hz=None))

    force = np.array([4.0, 0.08, 0.08])
    omega = 2 * np.pi * frange.frequencies_hz()
    H0 = _frf(rig, omega, force, (5, 7))
    dH = []
    for name in PARAMS:
        v = rig.parameters[name].value
        h = 1e-4 * abs(v)
        plus = _frf(rig.with_values({name: v + h}), omega, force, (5, 7))
        minus = _frf(rig.with_values({name: v - h}), omega, force, (5, 7))
        dH.append((plus - minus) / (2 * h))
    dH = np.stack(dH, axis=-1)  # (steps, orders, sensors, params)
    # noise: 2 % of the acceleration phasor, floor 0.01 m/s^2, mapped onto the FRF
    w2 = (omega[:, None] * np.array([1.0, 2.0, 3.0])[None, :]) ** 2
    acc = w2[:, :, None] * np.abs(H0) * force[None, :, None]
    sigma_acc = np.sqrt((0.02 * acc) ** 2 + 0.01**2)
    sigma_frf = sigma_acc / (w2[:, :, None] * force[None, :, None])
    z = (dH / sigma_frf[..., None]).reshape(-1, len(PARAMS))
    direct = sum(np.outer(row, row) for row in np.concatenate([z.real, z.imag]))

    d = np.sqrt(np.diag(direct))
    assert np.all(d > 0)
    assert np.abs((result.fim - direct) / np.outer(d, d)).max() < 2e-4
    # the ranked (block-sum) FIM of the one configuration is the same matrix
    ranked = result.ranking.log10_det[0] + result.log10_det_offset
    assert ranked == pytest.approx(np.log10(np.linalg.det(direct)), abs=1e-3)


def test_configuration_fim_is_the_sum_of_its_blocks(rig, reduced_plan):
    """A configuration's FIM = the sum of its (level, sensor) blocks = J^T J of its explicit
    whitened Jacobian = what the ranking used (1e-10 relative)."""
    sensors = REDUCED.sensors
    noise = NoiseModel()
    scales = reduced_plan.scales
    frange = REDUCED.ranges[0]
    sweeps = [
        run_sweep(
            SweepJob(
                model_toml=rig.to_toml(),
                actuator=3,
                force=tuple(REDUCED.force(level)),
                frequencies_hz=tuple(frange.frequencies_hz()),
                sensors=sensors,
                parameters=PARAMS,
            )
        )
        for level in REDUCED.levels_n
    ]
    blocks = np.stack([information_blocks(sw, sensors, noise, scales) for sw in sweeps])
    levels, use = (1, 2), (5, 7)  # 4 and 6 N; sensors 5 and 7
    by_blocks = sum(blocks[i, sensors.index(s)] for i in levels for s in use)
    J = whitened_jacobian([sweeps[i] for i in levels], sensors, use, noise, scales)
    assert J.shape == (2 * 2 * 20 * 3 * 2, 3)
    np.testing.assert_allclose(J.T @ J, by_blocks, rtol=1e-10)
    # the same configuration in the ranking: actuator 3, range [21-40], levels (4, 6),
    # sensors (5, 7) -> indices (1, 0, 2, 4) in (act, range, level pair, sensor pair)
    flat = np.ravel_multi_index((1, 0, 2, 4), reduced_plan.ranking.shape)
    assert reduced_plan.ranking.log10_det[flat] == pytest.approx(
        np.log10(np.linalg.det(by_blocks)), abs=1e-10
    )
    # information adds up over levels (independent sweeps)
    j4, j6 = (whitened_jacobian([sweeps[i]], sensors, use, noise, scales) for i in levels)
    np.testing.assert_allclose(j4.T @ j4 + j6.T @ j6, by_blocks, rtol=1e-10)


def test_mac_is_scale_free_and_matches_the_fim_form():
    rng = np.random.default_rng(3)
    J = rng.standard_normal((40, 3))
    J[:, 1] += 0.8 * J[:, 0]
    mac = jacobian_mac(J)
    np.testing.assert_allclose(np.diag(mac), 1.0)
    a, b = J[:, 0], J[:, 1]
    assert mac[0, 1] == pytest.approx((a @ b) ** 2 / ((a @ a) * (b @ b)), rel=1e-12)
    np.testing.assert_allclose(jacobian_mac(J * np.array([1e6, 1e-3, 10.0])), mac, rtol=1e-10)
    np.testing.assert_allclose(correlation_indices(J.T @ J), mac, rtol=1e-12)
    assert NoiseModel().relative == 0.02
