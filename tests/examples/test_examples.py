"""The example problems under examples/: each curve against a closed form or time integration."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve

from analysis.mhb.time_integration import integrate_steady_state, state_from_balance

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# -- Duffing ---------------------------------------------------------------------------------
K3, C = 0.5, 0.05  # duffing.toml: m = k = 1


def _duffing_fold(a0, w0, F):
    """A fold of the single-harmonic relation ((1 - w^2 + 3/4 k3 a^2)^2 + (c w)^2) a^2 = F^2:
    R = 0 and dR/da = 0."""

    def eqs(x):
        a, w = x
        b = 1 - w * w + 0.75 * K3 * a * a
        R = (b * b + (C * w) ** 2) * a * a - F * F
        dRda = 2 * a * (b * b + (C * w) ** 2) + 3 * K3 * a**3 * b
        return [R / F**2, dRda / F**2]

    return fsolve(eqs, [a0, w0], xtol=1e-12)


def test_duffing_linear_limit_is_the_closed_form_receptance():
    pb, branch = _example("duffing").curve(values={"k3": 0.0})
    w = branch.omega
    exact = 0.1 / np.abs(1 - w**2 + 1j * C * w)
    assert np.abs(np.abs(branch.outputs()[:, 0, 0]) / exact - 1).max() < 1e-12
    assert branch.turning_points() == []


def test_duffing_folds_against_the_single_harmonic_relation():
    ex = _example("duffing")
    # one harmonic: the balance is the closed-form relation, to the Newton tolerance
    _, one = ex.curve(n_harmonics=1)
    folds = one.turning_points()
    assert len(folds) == 2 and one.message == "reached the end frequency"
    for f in folds:
        a, w = _duffing_fold(f.amplitude, f.omega, ex.FORCE_N)
        assert abs(f.omega / w - 1) < 1e-9 and abs(f.amplitude / a - 1) < 1e-8
    # five harmonics at this nonlinearity (3/4 k3 a^2 about 0.8 at the upper fold) move the
    # folds by what the third harmonic carries: 2.1e-3 of the frequency at the upper fold
    _, five = ex.curve()
    for f, g in zip(five.turning_points(), folds, strict=True):
        assert abs(f.omega / g.omega - 1) < 3e-3


# -- 2-DOF chain with a Hertz stop -----------------------------------------------------------
@pytest.fixture(scope="module")
def hertz():
    return _example("two_dof_hertz").curve()


@pytest.mark.slow
def test_two_dof_hertz_curve_folds_at_the_stop(hertz):
    pb, branch = hertz
    assert branch.message == "reached the end frequency"
    folds = [f.omega / (2 * np.pi) for f in branch.turning_points()]
    # the stop's resonance bends over between the linear one (22.5 Hz) and the range's end
    assert len(folds) >= 2 and any(31 < f < 33 for f in folds)
    peak = max(branch.peaks(), key=lambda p: p.amplitude)
    assert 31 < peak.omega / (2 * np.pi) < 32 and peak.amplitude > 3e-3
    # between the two folds of the bent resonance the branch is unstable
    upper, lower = sorted(
        (f for f in branch.turning_points() if 31 < f.omega / 2 / np.pi < 33), key=lambda f: f.after
    )[:2]
    assert not branch.stable[upper.after + 2 : lower.after - 1].any()


@pytest.mark.parametrize("f_hz", [18.0, 28.0, 31.4, 33.0])
def test_two_dof_hertz_against_time_integration(hertz, f_hz):
    """Stable points of the curve against DOP853 integrated to a periodic steady state from
    the balanced state, each order of both masses: 2e-3 of the fundamental (measured 6e-6,
    7e-5, 3.5e-4 and 2e-6; the contact's jumps converge slowly in H)."""
    pb, branch = hertz
    i = int(np.argmin(np.abs(branch.omega - 2 * np.pi * f_hz)))
    p = branch.points[i]
    assert branch.stable[i]
    ref = integrate_steady_state(pb, p.omega, p.force[pb.order_k], state_from_balance(pb, p))
    assert ref.converged
    hb, ti = p.outputs(), ref.outputs()
    assert np.abs(hb - ti).max() < 2e-3 * np.abs(ti[0]).max()


# -- Cantilever with a tip contact -----------------------------------------------------------
L, B, H, E, RHO = 0.5, 0.030, 0.012, 210e9, 7800.0  # cantilever_tip_contact.toml
BETA_L = (1.8751040687, 4.6940911330, 7.8547574382)  # roots of cos x cosh x = -1


def test_cantilever_modes_against_euler_bernoulli():
    from analysis.model import load_model

    f, _ = load_model(EXAMPLES / "cantilever_tip_contact.toml").assemble().normal_modes(3)
    EI, rhoA = E * B * H**3 / 12, RHO * B * H
    exact = np.array(BETA_L) ** 2 / (2 * np.pi * L**2) * np.sqrt(EI / rhoA)
    # 8 cubic (Hermite) elements with consistent mass: upper bounds (Rayleigh-Ritz), the
    # error falling as h^4 and growing with the mode number (measured 2.1e-6, 8.0e-5, 6.1e-4)
    assert np.all(f >= exact)
    assert np.all(f / exact - 1 < [1e-5, 2e-4, 1e-3])


@pytest.mark.slow
def test_cantilever_linear_limit_is_the_direct_receptance():
    ex = _example("cantilever_tip_contact")
    pb, branch = ex.curve(values={"gap": 1.0})  # the stop never reached
    lin = pb.linear
    tip = pb.force_dofs[0]
    Z = lin.K - branch.omega[:, None, None] ** 2 * lin.M + 1j * branch.omega[:, None, None] * lin.C
    e = np.zeros(lin.n_dof)
    e[tip] = ex.FORCE_N
    exact = np.abs(
        np.linalg.solve(Z, np.broadcast_to(e, (len(Z), lin.n_dof))[..., None])[:, tip, 0]
    )
    assert np.abs(np.abs(branch.outputs()[:, 0, 0]) / exact - 1).max() < 1e-10
    assert branch.turning_points() == []


@pytest.mark.slow
def test_cantilever_contact_point_against_time_integration():
    """One point on the bent resonance (stable, above the linear resonance, in contact)
    against DOP853 integrated to a periodic steady state over the 24 DOFs: 1e-3 of the
    fundamental at the tip, every harmonic (measured 7e-5)."""
    ex = _example("cantilever_tip_contact")
    pb, branch = ex.curve(range_hz=(38.0, 42.0))
    from analysis.mhb.stability import floquet_exponents

    p = branch.points[-1]
    assert p.omega > 2 * np.pi * 41.9 and np.abs(p.outputs()[0, 0]) > 0.5e-3  # in contact
    assert floquet_exponents(pb, p).stable
    ref = integrate_steady_state(pb, p.omega, p.force[pb.order_k], state_from_balance(pb, p))
    assert ref.converged
    assert np.abs(p.q_out - ref.q_out).max() < 1e-3 * np.abs(ref.outputs()[0]).max()


def test_duffing_script_writes_the_curve_its_folds_and_a_figure(tmp_path, capsys):
    assert _example("duffing").main([str(tmp_path)]) == 0
    assert "fold  at 1.353" in capsys.readouterr().out
    located = (tmp_path / "duffing.located.csv").read_text().splitlines()
    assert [row.split(",")[0] for row in located[1:]] == ["fold", "fold", "peak"]
    assert (tmp_path / "duffing.png").stat().st_size > 10_000
