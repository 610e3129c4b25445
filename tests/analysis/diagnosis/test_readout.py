"""The read-out of a missing law: describing functions against closed forms, the reading of
the standard laws, and the read-out on screens of reduced runs of the truths."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from analysis.diagnosis import Screen, default_candidates, read_missing_force
from analysis.diagnosis.candidates import default_locations
from analysis.diagnosis.readout import describing_function, read_law
from analysis.report.diagnosis_figures import plot_force_readout

# one period sampled at the midpoints: a switch at v = 0 falls between samples
N_SAMPLES = 1 << 14
THETA = 2 * np.pi * (np.arange(N_SAMPLES) + 0.5) / N_SAMPLES
OMEGA = 2 * np.pi * 25.0  # rad/s
AMPLITUDES = np.geomspace(1e-4, 1e-2, 12)  # m
DF_RTOL = 1e-3  # describing function against its closed form
SLOPE_TOL = 0.05


def first_harmonic(law, amplitudes, omega=OMEGA) -> np.ndarray:
    """First-harmonic phasor of the restoring force ``law(x, v)`` under ``x = A cos(wt)``,
    integrated over one period in the time domain."""
    out = []
    for a in amplitudes:
        x, v = a * np.cos(THETA), -a * omega * np.sin(THETA)
        out.append(2 / N_SAMPLES * np.sum(law(x, v) * np.exp(-1j * THETA)))
    return np.array(out)


def read(law, amplitudes=AMPLITUDES):
    omega = np.full(amplitudes.size, OMEGA)
    k_eq, c_eq = describing_function(amplitudes, first_harmonic(law, amplitudes), omega)
    return k_eq, c_eq, read_law(amplitudes, omega, k_eq, c_eq)


def test_a_cubic_spring_reads_as_cubic_hardening() -> None:
    k, k3 = 2.0e3, 1.0e8  # N/m, N/m^3
    k_eq, c_eq, r = read(lambda x, v: k * x + k3 * x**3)
    exact = k + 0.75 * k3 * AMPLITUDES**2
    np.testing.assert_allclose(k_eq, exact, rtol=DF_RTOL)
    assert np.max(np.abs(c_eq * OMEGA)) < DF_RTOL * exact.min()
    assert abs(r.stiffness.p - 2.0) < SLOPE_TOL and r.stiffness.resolved
    assert abs(r.stiffness.y0 / k - 1) < DF_RTOL
    assert not r.damping.changes
    assert r.kind == "cubic_hardening"


def test_a_softening_cubic_spring_reads_as_softening() -> None:
    k, k3 = 2.0e5, -1.0e8
    _, _, r = read(lambda x, v: k * x + k3 * x**3, np.geomspace(1e-4, 1e-2, 10))
    assert r.stiffness_change < 0 and abs(r.stiffness.p - 2.0) < SLOPE_TOL
    assert r.kind == "cubic_softening"


def test_a_quadratic_damper_reads_as_a_quadratic_damper() -> None:
    c2 = 3.0  # N s^2/m^2
    k_eq, c_eq, r = read(lambda x, v: c2 * v * np.abs(v))
    exact = 8 / (3 * np.pi) * c2 * OMEGA * AMPLITUDES
    np.testing.assert_allclose(c_eq, exact, rtol=DF_RTOL)
    assert np.max(np.abs(k_eq)) < DF_RTOL * np.min(exact * OMEGA)
    assert abs(r.damping.p - 1.0) < SLOPE_TOL and r.damping.resolved
    assert not r.stiffness.changes
    assert r.kind == "quadratic_damper"


def test_coulomb_friction_reads_as_friction() -> None:
    f_s = 2.0  # N
    k_eq, c_eq, r = read(lambda x, v: f_s * np.sign(v))
    exact = 4 * f_s / (np.pi * OMEGA * AMPLITUDES)
    np.testing.assert_allclose(c_eq, exact, rtol=DF_RTOL)
    assert np.max(np.abs(k_eq)) < DF_RTOL * np.min(exact * OMEGA)
    assert abs(r.damping.p + 1.0) < SLOPE_TOL and r.damping.resolved
    assert r.kind == "coulomb_friction"


def jenkins(k_t: float, f_s: float):
    """A spring ``k_t`` in series with a slider ``f_s``, on one period after a period of
    settling (its loop is then periodic)."""

    def law(x, v):
        z = 0.0
        out = np.empty_like(x)
        for _ in range(2):
            for i, xi in enumerate(x):
                f = k_t * (xi - z)
                if abs(f) > f_s:
                    z = xi - math.copysign(f_s / k_t, f)
                    f = math.copysign(f_s, f)
                out[i] = f
        return out

    return law


def test_a_jenkins_joint_reads_as_stick_slip_with_its_dissipation_peak() -> None:
    k_t, f_s = 1.0e5, 1.5  # N m/rad, N m: slip from a = 1.5e-5 rad
    a = f_s / k_t
    amplitudes = np.geomspace(0.3 * a, 30 * a, 24)
    k_eq, c_eq, r = read(jenkins(k_t, f_s), amplitudes)
    slipping = amplitudes > a
    # energy per cycle 4 F_s (A - a) (Gelb and Vander Velde, hysteresis): omega c_eq pi A^2
    exact = 4 * f_s * (amplitudes - a) / (np.pi * amplitudes**2)
    np.testing.assert_allclose((c_eq * OMEGA)[slipping], exact[slipping], rtol=1e-2)
    np.testing.assert_allclose(k_eq[~slipping], k_t, rtol=DF_RTOL)
    assert r.kind == "stick_slip"
    assert r.peak is not None and 2 * a / 1.5 < r.peak < 2 * a * 1.5  # peak at 2a, binned
    # above the peak the local slope A/(A - a) - 2 of c_eq runs from 0 (at 2a) to Coulomb's -1
    assert -1.0 < r.damping.p < 0.0


def test_noise_alone_is_not_read_as_a_law() -> None:
    rng = np.random.default_rng(1)
    n = 40
    A = np.geomspace(1e-4, 1e-2, n)
    omega = np.full(n, OMEGA)
    sigma_k = np.full(n, 50.0)  # N/m
    sigma_c = sigma_k / OMEGA
    k_eq = 1e3 + sigma_k * rng.standard_normal(n)
    c_eq = 2.0 + sigma_c * rng.standard_normal(n)
    r = read_law(A, omega, k_eq, c_eq, sigma_k, sigma_c)
    assert not r.stiffness.changes and not r.damping.changes
    assert r.kind == "no_change"


def test_a_noisy_friction_slope_has_an_uncertainty_that_covers_it() -> None:
    rng = np.random.default_rng(2)
    n = 60
    A = np.geomspace(1e-4, 1e-2, n)
    omega = np.full(n, OMEGA)
    c_exact = 4 * 2.0 / (np.pi * OMEGA * A)
    sigma_c = 0.05 * c_exact  # 5 % per step
    c_eq = c_exact + sigma_c * rng.standard_normal(n)
    r = read_law(A, omega, np.zeros(n), c_eq, sigma_c * OMEGA, sigma_c)
    assert r.damping.resolved and 0 < r.damping.sigma_p < 0.1
    assert abs(r.damping.p + 1.0) < 3 * r.damping.sigma_p
    assert r.kind == "coulomb_friction"


# -- on the screens of reduced runs ------------------------------------------------------------
def _location(model, name: str):
    return next(loc for loc in default_locations(model, "structure") if loc.name == name)


def test_a_stop_above_the_tip_reads_as_a_one_sided_stop_and_leaves_the_screen_alone(
    runs, reference_model, tmp_path
) -> None:
    data = runs("two_sided_stop")
    loc = _location(reference_model, "point 7")
    cand = next(
        c
        for c in default_candidates(reference_model)
        if c.location == loc and c.law.kind == "cubic_spring"
    )
    screen = Screen(reference_model, data)
    ro = read_missing_force(screen, loc)
    r = ro.reading
    assert r is not None and ro.kind == "one_sided_stop", ro.text
    assert r.stiffness_change > 0 and r.even_seen  # stiffens; even orders: one side only
    assert ro.seen.sum() == ro.seen.size  # the tip's sensor sees every step
    # the exposed forces are those the states were built from: U = R_d F + R_L g
    fr = screen.frame(None)
    st = screen.states(fr, screen._incidence(fr, loc), (id(fr), loc))
    rows, k = screen.rows, 0
    R = fr.R[:, screen._basis.order_k[k]]
    lam = np.vstack([screen._known_incidence(fr), screen._incidence(fr, loc)])
    U = R[:, :, 0] * screen._F[rows, k][:, None] + np.einsum(
        "nij,lj,nl->ni", R[:, :, 1:], lam, st.g[:, k]
    )
    np.testing.assert_allclose(U, st.U[:, k], rtol=1e-10, atol=1e-12 * np.abs(U).max())
    # reading first shares the screen's states and changes no fit
    after = screen.fit(cand, n_iterations=0)
    fresh = Screen(reference_model, data).fit(cand, n_iterations=0)
    assert after.bic == fresh.bic and after.values == fresh.values
    # the numbers and the figure
    js = json.loads(json.dumps(ro.to_json()))
    assert js["kind"] == "one_sided_stop" and len(js["steps"]["k_eq_N_per_m"]) == ro.seen.size
    png = plot_force_readout(ro, tmp_path / "missing_force.png")
    assert png.stat().st_size > 10_000


def test_the_hysteretic_joint_reads_as_stick_slip_in_the_clamp(runs, reference_model) -> None:
    data = runs("hysteretic_joint")
    loc = _location(reference_model, "joint clamp rz")
    ro = read_missing_force(Screen(reference_model, data, locations=(loc,)), loc)
    r = ro.reading
    assert r is not None and ro.kind == "stick_slip", ro.text
    assert ro.rotation and ro.units["k"] == "N m/rad"
    # the truth: 1.3e5 N m/rad stuck (spring and Jenkins element), 3e4 slipping; the binned
    # ends within 15 %
    assert abs(r.k_bins.y.max() / 1.3e5 - 1) < 0.15
    assert abs(r.k_bins.y[-1] / 3.0e4 - 1) < 0.15
    assert "joint clamp rz" in ro.text and "Jenkins" in ro.text


def test_a_group_is_read_at_the_member_seen_most(runs, reference_model) -> None:
    data = runs("hardening_mounts")
    loc = _location(reference_model, "springs k_mount")
    ro = read_missing_force(Screen(reference_model, data), loc)
    assert ro.read_at.startswith("spring mount_") and "springs k_mount" in ro.note
    assert ro.read_at in ro.text


def test_a_linear_parameter_cannot_be_read() -> None:
    from analysis.diagnosis.candidates import Location

    with pytest.raises(ValueError, match="structure.*no place in the structure"):
        read_missing_force(None, Location("structure"))
