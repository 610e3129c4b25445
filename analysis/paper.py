"""The reference paper's published values, in one place (docs/rig.md).

Chen, Linderholt, Abrahamsson, Xia, Friswell, "Validation of a model calibration method through
vibrational testing of a mechanical system with local clearance", ISMA 2016: Table 2 (linear
calibration), Table 4 (the best pretest configuration), Table 5 (nonlinear calibration) and the
stepped sine's fundamental frequencies. The gap the paper *measured* (0.60 mm) differs from the
one it *calibrated* (0.61 mm): both are kept, by name.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "MEASURED_GAP_M",
    "PAPER_CALIBRATED",
    "PAPER_LINEAR",
    "PAPER_NONLINEAR",
    "TABLE4_BEST",
    "paper_frequencies_hz",
]

#: Table 2: the calibrated linear values.
PAPER_LINEAR = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
}
#: Table 5: the calibrated contact (k_c [N/m^1.5], gap [m], v_c [N s^2/m^2]).
PAPER_NONLINEAR = {"k_c": 4.51e5, "gap": 0.61e-3, "v_c": 25.21}
#: The gap between the beam tip at rest and the stop as the paper measured it [m].
MEASURED_GAP_M = 0.60e-3
#: The published calibrated model, Tables 2 and 5.
PAPER_CALIBRATED = {**PAPER_LINEAR, **PAPER_NONLINEAR}
#: Table 4's best configuration.
TABLE4_BEST = "actuator 3, levels [2, 4, 6] N, range [21-40] Hz, sensors [4, 6, 7]"


def paper_frequencies_hz() -> np.ndarray:
    """The stepped sine's fundamentals [Hz]: 21-40 Hz in 1 Hz plus 24-28 Hz in 0.1 Hz, overlaps
    removed, ascending (56 frequencies)."""
    f = np.concatenate([np.arange(21, 41, 1.0), np.arange(240, 281) / 10.0])
    return np.unique(np.round(f, 6))
