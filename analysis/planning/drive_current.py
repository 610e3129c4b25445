"""The coil current a planned step asks of the shaker's amplifier.

An electrodynamic shaker pushes the drive point through a stiff stinger, so its armature (mass
``m``) moves with the drive point and the coil (force constant ``Bl``) must supply the force
into the structure and the armature's inertia: ``Bl I = F + m a`` per harmonic, with ``F`` the
drive force and ``a`` the drive point's acceleration (the suspension's stiffness and damping add
well under 1 % above about 20 Hz for a modal shaker). Near a resonance of the drive point the
inertia term dominates: on the reference rig 6 N at the beam's second bending mode (152 Hz)
moves point 3 at about 370 m/s^2, and the 0.2 kg armature then needs 74 N from the coil, 5 A at
15 N/A, where a modal amplifier's overload protection switches the output off. A plan that asks
for such a step cannot be run: :func:`analysis.diagnosis.discriminate.discriminate` leaves out
the configurations whose predicted current comes within :data:`CURRENT_MARGIN` of the limit.

The constants come from the lab setup the measurement file records (``[drive]
armature_mass_kg``, ``force_constant_n_per_a``, ``[amplifier] current_limit_a``); a setup
without them leaves the current unchecked.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["CURRENT_MARGIN", "ShakerDrive"]

# Share of the amplifier's current limit a planned step may use: the force controller's first
# drive at a new frequency overshoots by several per cent where the force per volt changes fast,
# the structure's nonlinearity and the noise add to the prediction's peak.
CURRENT_MARGIN = 0.8


@dataclass(frozen=True)
class ShakerDrive:
    """Armature mass, force constant and amplifier current limit of a rig's drive chain.

    Attributes
    ----------
    armature_mass_kg : float
    force_constant_n_per_a : float
    current_limit_a : float
        Peak current at which the amplifier's overload protection trips.
    """

    armature_mass_kg: float
    force_constant_n_per_a: float
    current_limit_a: float

    def __post_init__(self) -> None:
        for name in ("armature_mass_kg", "force_constant_n_per_a", "current_limit_a"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"ShakerDrive.{name}: must be a finite number > 0, got {value!r}")

    @classmethod
    def from_setup(cls, setup: Mapping[str, Any] | None) -> ShakerDrive | None:
        """The drive chain of a measurement file's lab setup (``RunData.setup``), or None when
        the setup does not give all three constants."""
        if not isinstance(setup, Mapping):
            return None
        drive, amp = setup.get("drive", {}), setup.get("amplifier", {})
        if not isinstance(drive, Mapping) or not isinstance(amp, Mapping):
            return None
        values = (
            drive.get("armature_mass_kg"),
            drive.get("force_constant_n_per_a"),
            amp.get("current_limit_a"),
        )
        if not all(
            isinstance(v, int | float) and not isinstance(v, bool) and v > 0 for v in values
        ):
            return None
        return cls(*(float(v) for v in values))  # type: ignore[arg-type]

    @property
    def usable_current_a(self) -> float:
        """The peak current a planned step may need [A]."""
        return CURRENT_MARGIN * self.current_limit_a

    def peak_current_a(
        self, force_n: np.ndarray, displacement_m: np.ndarray, omega_rad_s: np.ndarray
    ) -> np.ndarray:
        """Bound on the peak coil current of each step [A]: the sum over orders of
        ``|F_k + m a_k| / Bl`` (the peak when every order's crest meets).

        Parameters
        ----------
        force_n : ndarray, shape (H,) or (n, H), complex, N
            Drive-force phasors.
        displacement_m : ndarray, shape (n, H), complex, m
            The drive point's displacement phasors.
        omega_rad_s : ndarray, shape (n, H), rad/s
            Angular frequency of each order.
        """
        accel = -(np.asarray(omega_rad_s) ** 2) * np.asarray(displacement_m)
        coil = np.asarray(force_n) + self.armature_mass_kg * accel
        return np.abs(coil).sum(axis=-1) / self.force_constant_n_per_a
