"""The time engine: against a direct ODE solution, against the balance, and on random drives."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sim_backend.daq import SimulatedDaq
from sim_backend.integrator import TimeStepper
from sim_backend.rig_model import RigModel, SensorSpec
from sim_backend.truth import load_truth
from tests.sim_backend.rig_setup import FS, multisine, paper_config, settle_and_estimate


@pytest.mark.slow
def test_stepper_matches_a_direct_integration_through_contact() -> None:
    rig = RigModel(load_truth("reference"), (SensorSpec("force", 3, "y", 0.01),), 3)
    sp, problem = rig.space, rig.problem
    fs, T = 2048.0, 0.25
    t = np.arange(int(T * fs) + 1) / fs
    u = 1.5 * np.sin(2 * np.pi * 25.6 * t)  # gain times DAQ volts: the tip hits the stop
    stepper = TimeStepper(sp, problem, fs, substeps=4)
    eta0 = np.zeros(sp.size, dtype=complex)
    res = stepper.run(eta0, stepper.forces_at(eta0), u)
    L = problem.L
    Tn = sp.displacement_rows(problem.nl_dofs)
    Vn = sp.velocity_rows(problem.nl_dofs)
    elements = [a.element for a in problem.attachments]

    def rhs(time: float, s: np.ndarray) -> np.ndarray:
        uu = np.interp(time, t, u)
        ue, ve = L @ (Tn @ s), L @ (Vn @ s)
        f = np.array([el.force(ue[i : i + 1], ve[i : i + 1])[0] for i, el in enumerate(elements)])
        return sp.A @ s + sp.b * uu + sp.Bn @ (L.T @ f)

    ref = solve_ivp(
        rhs,
        (0, T),
        np.zeros(sp.size),
        method="Radau",
        t_eval=t[1:],
        # within 3e-5 of the largest of an integration at rtol 1e-7, atol 1e-12 (three times
        # as long): 300 times inside the tolerance below
        rtol=1e-5,
        atol=1e-10,
        jac=sp.A,
    )
    assert ref.success
    tip = L @ Tn
    x_ref = (tip @ ref.y)[0]
    x_sim = (tip @ (sp.W @ res.eta.T)).real[0]
    assert x_ref.min() < -0.8e-3  # contact: the gap is 0.6 mm
    np.testing.assert_allclose(x_sim, x_ref, rtol=0, atol=0.01 * np.abs(x_ref).max())


@pytest.mark.slow
def test_time_mode_matches_the_balance_on_steps_with_and_without_contact() -> None:
    steps = [(96, 0.05), (80, 0.1), (64, 0.05)]  # 21.3 Hz, 25.6 Hz (contact), 32 Hz
    results = {}
    for mode in ("mhb", "time"):
        daq = SimulatedDaq(mode=mode, noise=False, quantisation=False)
        daq.configure(paper_config())
        daq.start()
        out = []
        for n, amplitude in steps:
            index = daq.write_periodic(multisine(n, amplitude), 0.1)
            est, _, _ = settle_and_estimate(daq, index, n, settle_s=6.0, periods=10)
            out.append(est.phasors)
        results[mode] = out
        daq.close()
    ratios = []
    for (n, _amplitude), mhb, time_ in zip(steps, results["mhb"], results["time"], strict=True):
        scale = np.abs(mhb[:4, 0])[:, None]
        assert np.all(np.abs(time_[:4] - mhb[:4]) <= 0.01 * scale), (n, time_[:4], mhb[:4])
        ratios.append(abs(time_[0, 0]) / abs(time_[4, 0]))  # force per drive volt
    tip_mm = abs(results["time"][1][3, 0]) / (2 * np.pi * FS / 80) ** 2 * 1e3
    assert tip_mm > 0.6  # the contact is closed on the resonant step
    assert ratios[1] < 0.5 * min(ratios[0], ratios[2])  # force drop-out at resonance


def _suspension_peak(truth: str) -> float:
    from rig.estimation.frf import h1_frf
    from rig.signals.random import band_limited_random

    fs = 1024.0
    daq = SimulatedDaq(truth)
    daq.configure(paper_config(fs, extra_points=(10,)))
    n = int(32 * fs)
    daq.write_periodic(band_limited_random(n, fs, 5.0, 200.0, 0.03, seed=1), 0.0)
    daq.start()
    daq.read(int(4 * fs), 5.0)
    data, _ = daq.read(n, 5.0)
    daq.close()
    f, h1, _, _ = h1_frf(data[:, 0], data[:, 4], fs, 4096)
    band = (f > 8) & (f < 18)
    return float(f[band][np.argmax(np.abs(h1[band, 0]))])


@pytest.mark.slow
def test_hardening_mounts_leave_the_low_level_random_test_linear() -> None:
    reference = _suspension_peak("reference")
    hardened = _suspension_peak("hardening_mounts")
    assert reference == pytest.approx(11.0, abs=0.5)  # the frame bouncing on its mounts
    # the mounts' cubic term acts at the stepped sine's amplitudes, not at the random test's
    assert abs(hardened - reference) <= 0.25  # one frequency line


def test_paper_style_run_is_far_faster_than_real_time() -> None:
    from tests.sim_backend.paper_run import run_stepped_sine

    daq = SimulatedDaq()
    daq.configure(paper_config())
    run = run_stepped_sine(daq, (2.0,), np.arange(24.0, 28.1, 0.5))
    daq.close()
    assert len(run.steps) == 9 and run.simulated_s > 40.0
    # not paced by the clock (a paced run is 1x); about 90x on an idle machine, the bound
    # leaves room for a loaded one (the speed itself is a benchmark's figure)
    assert run.simulated_s / run.wall_s > 10.0
    # away from the resonance the force controller reaches its targets on the simulated rig
    assert all(s.converged for s in run.steps if s.frequency_hz > 27.0)


@pytest.mark.parametrize(
    "truth", ["reference", "hysteretic_joint", "clamp_friction", "hardening_mounts"]
)
def test_the_compiled_engine_is_the_python_engine(truth: str) -> None:
    """The compiled loop (contact law; contact and Jenkins slider with its memory; contact
    and friction; contact and cubic springs on the mounts) gives the
    Python loop's states and forces to rounding (1e-9 of their largest value) on a drive that
    closes the contact and slips the slider, and leaves the sliders where the Python loop
    leaves them."""
    fs, T = 2048.0, 0.3
    t = np.arange(int(T * fs) + 1) / fs
    u = 1.5 * np.sin(2 * np.pi * 25.6 * t) + 0.3 * np.sin(2 * np.pi * 51.2 * t)
    out = {}
    for compiled in (False, True):
        rig = RigModel(load_truth(truth), (SensorSpec("force", 3, "y", 0.01),), 3)
        stepper = TimeStepper(rig.space, rig.problem, fs, substeps=2, compiled=compiled)
        assert (stepper.elements.compiled() is not None) or not compiled
        eta0 = np.zeros(rig.space.size, dtype=complex)
        res = stepper.run(eta0, stepper.forces_at(eta0), u)
        memory = [getattr(a.element, "_z", np.zeros(0)).copy() for a in rig.problem.attachments]
        out[compiled] = res, memory
    (py, py_mem), (nb, nb_mem) = out[False], out[True]
    assert np.abs(py.forces).max() > 0  # the elements act
    np.testing.assert_allclose(nb.eta, py.eta, rtol=0, atol=1e-9 * np.abs(py.eta).max())
    np.testing.assert_allclose(nb.forces, py.forces, rtol=0, atol=1e-9 * np.abs(py.forces).max())
    for a, b in zip(nb_mem, py_mem, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    if truth == "hysteretic_joint":
        assert any(m.size and np.abs(m).max() > 0 for m in py_mem)  # the slider slipped
