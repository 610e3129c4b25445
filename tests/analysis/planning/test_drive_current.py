"""The coil current a planned step asks of the amplifier: (F + m a) / Bl, summed over orders."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.planning.drive_current import CURRENT_MARGIN, ShakerDrive

SETUP = {
    "drive": {"armature_mass_kg": 0.2, "force_constant_n_per_a": 15.0},
    "amplifier": {"current_limit_a": 5.0},
}


def test_the_drive_is_read_from_the_files_setup_only_when_complete() -> None:
    drive = ShakerDrive.from_setup(SETUP)
    assert drive == ShakerDrive(0.2, 15.0, 5.0)
    assert drive.usable_current_a == pytest.approx(CURRENT_MARGIN * 5.0)
    for missing in ("armature_mass_kg", "force_constant_n_per_a"):
        partial = {"drive": {k: v for k, v in SETUP["drive"].items() if k != missing}}
        assert ShakerDrive.from_setup(partial | {"amplifier": SETUP["amplifier"]}) is None
    zero = {"drive": SETUP["drive"], "amplifier": {"current_limit_a": 0.0}}  # 0: unknown
    assert ShakerDrive.from_setup(zero) is None
    assert ShakerDrive.from_setup(None) is None


def test_the_armatures_inertia_adds_to_the_force_at_a_resonance() -> None:
    drive = ShakerDrive(0.2, 15.0, 5.0)
    omega = np.array([[2 * np.pi * 152.0]])
    # 6 N and a displacement in phase with it, whose acceleration (a = -w^2 x, 370 m/s^2)
    # opposes the force: |6 + 0.2 (-370)| = 68 N from the coil, 4.53 A
    x = np.array([[370.0 / omega[0, 0] ** 2]])
    assert drive.peak_current_a(np.array([6.0]), x, omega)[0] == pytest.approx(68.0 / 15.0)
    # a held drive point: the force alone
    assert drive.peak_current_a(np.array([6.0]), 0 * x, omega)[0] == pytest.approx(0.4)
