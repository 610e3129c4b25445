"""Linear calibration from a random-excitation run with damping equalization.

The underlying linear structure is calibrated first (the paper's section 3.2): the test's modes
are identified from the H1 FRFs of a low-level random run, the test and the model FRFs are both
given one modal damping ``zeta0`` (damping equalization, Abrahamsson & Kammer) and compared on
log10 magnitude within the modes' half-power bands, and the mass and stiffness parameters are
fitted by Levenberg-Marquardt with analytic sensitivities. The identified modal damping goes to
the calibrated model's ``DampingSpec.per_mode`` for the nonlinear stage.

Modules
-------
run_frfs
    The run in model coordinates: receptances, channel DOFs, sensor masses.
lscf
    Starting poles: sub-band LSCF with an automatic stabilisation diagram.
modal_id
    Pole-residue fit with residual terms (variable projection): :func:`identify_modes`.
damping_equalization
    Metric frequencies and the equalized test FRFs.
objective
    The log-magnitude deviation and its analytic Jacobian.
mode_matching
    Test-model mode pairs by MAC and frequency.
calibrate
    :func:`calibrate_linear` and its settings.
result
    :class:`LinearCalibration`.
cli
    The ``calibrate-linear`` command.
"""

from analysis.calibration.linear.calibrate import (
    DEFAULT_CALIBRATION_POINTS,
    METHODS,
    LinearCalibrationSettings,
    calibrate_linear,
)
from analysis.calibration.linear.damping_equalization import (
    EqualizedTest,
    equalize,
    metric_frequencies,
)
from analysis.calibration.linear.modal_id import ModalFit, fit_poles, identify_modes
from analysis.calibration.linear.mode_matching import ModePair, match_modes
from analysis.calibration.linear.objective import EqualizedFRFObjective, receptance
from analysis.calibration.linear.result import LinearCalibration
from analysis.calibration.linear.run_frfs import (
    CalibrationError,
    RunFRFs,
    load_random_run,
    sensor_masses,
)

__all__ = [
    "DEFAULT_CALIBRATION_POINTS",
    "METHODS",
    "CalibrationError",
    "EqualizedFRFObjective",
    "EqualizedTest",
    "LinearCalibration",
    "LinearCalibrationSettings",
    "ModalFit",
    "ModePair",
    "RunFRFs",
    "calibrate_linear",
    "equalize",
    "fit_poles",
    "identify_modes",
    "load_random_run",
    "match_modes",
    "metric_frequencies",
    "receptance",
    "sensor_masses",
]
