"""The shaker-structure coupling: receptance blocks against direct solves and the state space."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.linear.receptance import ModalLinearModel
from sim_backend.coupled import CoupledLinearModel
from sim_backend.rig_model import RigModel, SensorSpec
from sim_backend.shaker import ShakerConstants, shaker_terms
from sim_backend.truth import load_truth

SENSORS = (
    SensorSpec("force", 3, "y", 0.01),
    SensorSpec("acceleration", 3, "y", 0.0),
    SensorSpec("acceleration", 6, "y", 0.0055),
    SensorSpec("acceleration", 7, "y", 0.0055),
)


@pytest.fixture(scope="module")
def rig() -> RigModel:
    return RigModel(load_truth("reference"), SENSORS, drive_point=3)


def test_coupled_blocks_equal_a_direct_solve_of_the_assembled_coupled_system() -> None:
    model = load_truth("reference").model
    asm = model.assemble()
    zeta = model.damping.zeta(asm.n_dofs)
    modal = ModalLinearModel(asm.M, asm.K, np.array(zeta), f_max_hz=1e12)  # every mode
    phi, wr = modal.modes.phi, modal.modes.omega
    C = asm.M @ phi @ np.diag(2 * modal.modes.zeta * wr) @ phi.T @ asm.M
    shaker = ShakerConstants()
    d = asm.point_dof(3)
    coupled = CoupledLinearModel(modal, d, shaker, output_resistance_ohm=0.05)
    rows = [asm.point_dof(7), asm.point_dof(6), d, coupled.force, coupled.current]
    cols = [asm.point_dof(7), coupled.voltage]
    omega = 2 * np.pi * np.array([0.0, 11.0, 24.9, 25.3, 150.0, 790.0])
    H = coupled.block(rows, cols)(omega)
    n = asm.n_dofs
    s = shaker
    Bl, kst = s.force_constant_n_per_a, s.stinger_stiffness_n_per_m
    for i, w in enumerate(omega):
        # unknowns: structure x (n), armature x_a, coil current I
        Z = np.zeros((n + 2, n + 2), dtype=complex)
        Z[:n, :n] = asm.K - w**2 * asm.M + 1j * w * C
        Z[d, d] += kst
        Z[d, n] = Z[n, d] = -kst
        Z[n, n] = s.suspension_stiffness_n_per_m + kst - w**2 * s.armature_mass_kg
        Z[n, n] += 1j * w * s.suspension_damping_ns_per_m
        Z[n, n + 1] = -Bl
        Z[n + 1, n] = Bl * 1j * w
        Z[n + 1, n + 1] = s.coil_resistance_ohm + 0.05 + 1j * w * s.coil_inductance_h
        rhs = np.zeros((n + 2, 2), dtype=complex)
        rhs[asm.point_dof(7), 0] = 1.0  # unit force at the tip
        rhs[n + 1, 1] = 1.0  # unit voltage
        sol = np.linalg.solve(Z, rhs)
        force = kst * (sol[n] - sol[d])
        expected = np.vstack(
            [sol[asm.point_dof(7)], sol[asm.point_dof(6)], sol[d], force, sol[n + 1]]
        )
        np.testing.assert_allclose(H[i], expected, rtol=1e-5)


def test_state_space_transfer_equals_the_coupled_receptance(rig: RigModel) -> None:
    sp = rig.space
    # test band; higher up the residual flexibility as stiff modes differs (2 % at 600 Hz)
    omega = 2 * np.pi * np.array([5.0, 25.0, 25.3, 140.0])
    block = rig.coupled.block(rig.output_dofs, [rig.coupled.voltage])(omega)[:, :, 0]
    block = block * rig.amplifier_response(omega)[:, None]
    rows = np.vstack(
        [
            sp.displacement_rows(rig.structural_outputs),
            sp.force_row(rig.drive_dof),
            sp.current_row(),
        ]
    )
    for i, w in enumerate(omega):
        via_modes = rows @ sp.W @ (sp.g / (1j * w - sp.lam))
        np.testing.assert_allclose(via_modes, block[i], rtol=1e-4)


def test_force_drops_out_at_the_structures_resonance(rig: RigModel) -> None:
    f = np.linspace(20.0, 32.0, 241)
    omega = 2 * np.pi * f
    t = rig.coupled.block([rig.coupled.force], [rig.coupled.voltage])(omega)[:, 0, 0]
    ratio = np.abs(t)
    f_res = load_truth("reference").model.add_masses({3: 0.01, 6: 0.0055, 7: 0.0055})
    fr = f_res.assemble().normal_modes(5)[0][3]
    assert abs(f[np.argmin(ratio)] - fr) < 0.3
    assert ratio.min() < 0.2 * ratio.max()


def test_shaker_terms_are_real_at_zero_frequency() -> None:
    terms = shaker_terms(ShakerConstants(), np.array([0.0]))
    assert terms.T.imag[0] == 0 and terms.z.imag[0] == 0
    k_s, k_st = 2000.0, 5.0e6
    assert terms.z.real[0] == pytest.approx(k_st * k_s / (k_s + k_st))


@pytest.mark.parametrize(
    "field", ["armature_mass_kg", "coil_resistance_ohm", "stinger_stiffness_n_per_m"]
)
def test_shaker_constants_name_a_bad_field(field: str) -> None:
    with pytest.raises(ValueError, match=f"ShakerConstants.{field}"):
        ShakerConstants(**{field: 0.0})
