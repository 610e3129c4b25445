"""Electrodynamic modal shaker on a stinger: constants and frequency-domain coupling terms.

The shaker is an armature of mass ``m_a`` on a suspension (stiffness ``k_s``, damping
``c_s``), driven by a coil (resistance ``R``, inductance ``L``, force constant ``Bl``) from the
power amplifier, and pushes the structure's drive point through a stinger of axial stiffness
``k_st``. With ``x_a`` the armature and ``x_d`` the drive-point displacement, the amplifier's
open-circuit voltage ``V`` (output resistance ``R_o``) and the coil current ``I``::

    m_a x_a'' + c_s x_a' + k_s x_a + k_st (x_a - x_d) = Bl I
    L I' + (R + R_o) I + Bl x_a' = V
    F_st = k_st (x_a - x_d)          (force of the stinger on the structure)

In the frequency domain (``exp(+i w t)``) with ``Z_e = R + R_o + i w L`` and the armature's
dynamic stiffness including the back-EMF damping
``Z_a = k_s + k_st - w^2 m_a + i w c_s + (Bl)^2 i w / Z_e``::

    F_st = T(w) V - z(w) x_d,    T = k_st Bl / (Z_e Z_a),    z = k_st - k_st^2 / Z_a.

The stinger force therefore drops where the structure's drive point moves freely (at its
resonances): the back-EMF of a voltage-driven coil is a damper in series with the structure.

References
----------
D. J. Ewins, *Modal Testing: Theory, Practice and Application*, 2nd ed., Research Studies
Press 2000, sec. 3.4 (shaker-structure interaction, force drop-out at resonance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.settings import NonNegative, Positive, declare, settings

__all__ = ["ShakerConstants", "ShakerTerms", "shaker_terms"]


@settings()
class ShakerConstants:
    """Mechanical and electrical constants of a modal shaker and its stinger.

    Defaults describe a small modal shaker of the 2025E class on a steel stinger.
    """

    armature_mass_kg: Positive = declare("Moving mass of armature and coil [kg].", 0.2)
    suspension_stiffness_n_per_m: NonNegative = declare(
        "Flexure suspension stiffness [N/m].", 2000.0
    )
    suspension_damping_ns_per_m: NonNegative = declare(
        "Mechanical damping of the suspension [N s/m].", 2.0
    )
    coil_resistance_ohm: Positive = declare("DC resistance of the coil [ohm].", 1.5)
    coil_inductance_h: Positive = declare("Coil inductance [H].", 3.0e-4)
    force_constant_n_per_a: Positive = declare(
        "Force constant Bl [N/A] (equal to the back-EMF constant in V s/m).", 15.0
    )
    stinger_stiffness_n_per_m: Positive = declare("Axial stiffness of the stinger [N/m].", 5.0e6)


@dataclass(frozen=True)
class ShakerTerms:
    """Frequency-domain coupling terms at a set of angular frequencies.

    Attributes
    ----------
    Ze : ndarray, shape (n,), complex, ohm
        Electrical impedance of the coil plus amplifier output resistance.
    Za : ndarray, shape (n,), complex, N/m
        Armature dynamic stiffness with the stinger held and back-EMF damping included.
    T : ndarray, shape (n,), complex, N/V
        Stinger force per volt with the drive point held.
    z : ndarray, shape (n,), complex, N/m
        Dynamic stiffness the shaker adds at the drive point.
    """

    Ze: np.ndarray
    Za: np.ndarray
    T: np.ndarray
    z: np.ndarray


def shaker_terms(
    shaker: ShakerConstants, omega: np.ndarray, output_resistance_ohm: float = 0.0
) -> ShakerTerms:
    """Coupling terms ``T`` and ``z`` of the module notes.

    Parameters
    ----------
    shaker : ShakerConstants
    omega : ndarray, shape (n,), rad/s
        Angular frequencies, >= 0.
    output_resistance_ohm : float
        Source resistance of the amplifier in series with the coil [ohm].

    Returns
    -------
    ShakerTerms
    """
    w = np.asarray(omega, dtype=float)
    s = shaker
    Ze = s.coil_resistance_ohm + output_resistance_ohm + 1j * w * s.coil_inductance_h
    Bl, kst = s.force_constant_n_per_a, s.stinger_stiffness_n_per_m
    Za = (
        s.suspension_stiffness_n_per_m
        + kst
        - w**2 * s.armature_mass_kg
        + 1j * w * s.suspension_damping_ns_per_m
        + Bl**2 * 1j * w / Ze
    )
    return ShakerTerms(Ze=Ze, Za=Za, T=kst * Bl / (Ze * Za), z=kst - kst**2 / Za)
