"""The simulator's hysteretic element (outside the analysis library)."""

from __future__ import annotations

import numpy as np

from sim_backend.hysteresis import JenkinsElement


def test_a_periodic_loop_dissipates_coulomb_energy() -> None:
    el = JenkinsElement(k_t=1e5, f_s=2.0)
    t = np.linspace(0, 2 * np.pi, 512, endpoint=False)
    amp = 1e-4  # five times the stick limit f_s / k_t = 2e-5
    u, v = amp * np.cos(t), -amp * np.sin(t)
    ev = el.evaluate(u, v)
    assert np.abs(ev.f).max() <= 2.0 + 1e-12
    # energy dissipated per cycle: 4 f_s (amp - f_s / k_t) for a Jenkins loop
    work = -np.sum(ev.f * v) * (2 * np.pi / t.size)
    assert abs(work / (4 * 2.0 * (amp - 2e-5)) - 1) < 0.02
    assert np.all(ev.df_du[np.abs(ev.f) < 1.999] == -1e5)


def test_the_periodic_march_is_the_time_engines_second_period() -> None:
    """The balance's periodic evaluation (the period marched twice, compiled) equals the
    time engine's return mapping advanced one sample at a time over two periods: the second
    period's forces and tangents, to rounding."""
    el = JenkinsElement(k_t=1e5, f_s=2.0)
    t = np.linspace(0, 2 * np.pi, 1024, endpoint=False)
    u = 6e-5 * np.cos(t) + 2e-5 * np.sin(3 * t + 0.4)  # two slips a half period
    periodic = el.evaluate(u, np.zeros_like(u))
    stepper = JenkinsElement(k_t=1e5, f_s=2.0)
    steps = [stepper.evaluate(np.array([x]), np.zeros(1)) for x in np.concatenate([u, u])]
    f = np.array([s.f[0] for s in steps[u.size :]])
    df = np.array([s.df_du[0] for s in steps[u.size :]])
    np.testing.assert_allclose(periodic.f, f, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(periodic.df_du, df)
    assert (df == 0).any() and (df == -1e5).any()  # it slips and sticks


def test_the_time_engine_advances_each_slider() -> None:
    el = JenkinsElement(k_t=1e5, f_s=1.0)
    f = [float(el.evaluate(np.array([x]), np.zeros(1)).f[0]) for x in (0.0, 5e-6, 2e-5, 1e-5)]
    assert f[:2] == [0.0, -0.5]
    assert f[2] == -1.0  # slipping
    assert abs(f[3] - (-1.0 + 1e5 * 1e-5)) < 1e-12  # unloading elastically from the slip


def test_the_element_is_no_candidate_of_the_analysis_library() -> None:
    import analysis.elements as lib
    from analysis.diagnosis.candidates import default_laws

    assert lib.ELEMENT_TYPES["jenkins"] is JenkinsElement  # registered for the simulator
    assert "jenkins" not in {law.kind for law in default_laws()}
