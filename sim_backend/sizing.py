"""How visible a hidden effect is in the paper's stepped-sine test, in units of the noise.

The paper's test (``docs/rig.md``): drive at point 3, accelerometers at 3, 6 and 7, fundamental
force 2, 4, 6 and 8 N with 2 % second and third harmonics, 21-40 Hz in 1 Hz steps refined to
0.1 Hz in 24-28 Hz. :func:`truth_misfit` sweeps a truth and the reference truth at those
prescribed forces with the multi-harmonic balance of the structure (20 harmonics, 1024 AFT
samples, the sensor masses of that setup) and compares the acceleration phasors at orders
1-3. Each difference is divided by the standard error of that FRF value that the truth's noise
floors give for ``averaged_periods`` periods (phasor error ``asd * sqrt(2 / T)`` for the
acceleration and the force, combined as for a ratio).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from analysis.mhb.sweep import solve_steps
from analysis.paper import paper_frequencies_hz
from analysis.system import build_problem
from sim_backend.truth import Truth, load_truth

__all__ = [
    "Misfit",
    "PaperTest",
    "response_sweep",
    "second_mode_frequencies",
    "truth_misfit",
]

logger = logging.getLogger(__name__)


def second_mode_frequencies() -> np.ndarray:
    """A band around the beam's second bending mode (about 152 Hz) [Hz], 140-165 Hz in 0.5 Hz
    steps, shape (51,): the paper's band holds the first bending mode only, so effects whose
    first-mode work is alike (a damper at neighbouring points) differ here."""
    return np.round(np.arange(140.0, 165.01, 0.5), 6)


@dataclass(frozen=True)
class PaperTest:
    """The stepped-sine test used for sizing.

    Parameters
    ----------
    levels_n : tuple of float
        Fundamental force amplitudes [N].
    drive_point : int
    sensor_points : tuple of int
        Accelerometers (the one at the drive point is the impedance head's).
    side_amplitude : float
        Second and third harmonic force relative to the fundamental.
    averaged_periods : int
        Periods averaged per step (sets the phasor standard error).
    """

    levels_n: tuple[float, ...] = (2.0, 4.0, 6.0, 8.0)
    drive_point: int = 3
    sensor_points: tuple[int, ...] = (3, 6, 7)
    side_amplitude: float = 0.02
    averaged_periods: int = 10

    def __post_init__(self) -> None:
        if not self.levels_n or min(self.levels_n) <= 0:
            raise ValueError(f"PaperTest.levels_n: need positive levels, got {self.levels_n}")
        if self.averaged_periods < 1:
            raise ValueError("PaperTest.averaged_periods: must be >= 1")


@dataclass(frozen=True)
class Misfit:
    """Difference between a truth and the reference in noise units.

    Attributes
    ----------
    rms_sigma : float
        RMS over all levels, frequencies, orders 1-3 and sensors of ``|dA| / sigma``, with
        ``sigma`` the FRF value's standard error times the force.
    max_sigma : float
        Largest ``|dA| / sigma``.
    by_level : ndarray, shape (n_levels,)
        RMS per level.
    fundamental_rms_sigma : float
        RMS over the fundamental (order 1) only.
    """

    rms_sigma: float
    max_sigma: float
    by_level: np.ndarray
    fundamental_rms_sigma: float


def _masses(truth: Truth, test: PaperTest) -> dict[int, float]:
    s = truth.sensors
    masses = {test.drive_point: s.impedance_head_mass_kg}
    for p in test.sensor_points:
        if p != test.drive_point:
            masses[p] = masses.get(p, 0.0) + s.accelerometer_mass_kg
    return masses


def response_sweep(
    truth: Truth, test: PaperTest | None = None, frequencies_hz: np.ndarray | None = None
) -> np.ndarray:
    """Acceleration phasors of a truth at the test's prescribed forces.

    Parameters
    ----------
    truth : Truth
    test : PaperTest, optional
    frequencies_hz : ndarray, shape (n_f,), optional
        Default :func:`analysis.paper.paper_frequencies_hz`; each level is swept upwards.

    Returns
    -------
    ndarray, shape (n_levels, n_f, 3, n_sensors), complex, m/s^2
        Orders 1, 2, 3.
    """
    test = test or PaperTest()
    f = paper_frequencies_hz() if frequencies_hz is None else np.asarray(frequencies_hz, float)
    model = truth.model.add_masses(_masses(truth, test))
    problem = build_problem(
        model,
        drive_point=test.drive_point,
        output_points=test.sensor_points,
        n_harmonics=20,
        n_time=1024,
    )
    omega = 2 * np.pi * f
    k = np.arange(1, 4)
    out = np.empty((len(test.levels_n), f.size, 3, len(test.sensor_points)), dtype=complex)
    for i, level in enumerate(test.levels_n):
        force = level * np.array([1.0, test.side_amplitude, test.side_amplitude])[:, None]
        result = solve_steps(problem, omega, force)
        if not result.converged.all():
            logger.warning("%s at %g N: %s", truth.name, level, result.failures())
        q = result.outputs()  # (n_f, 3, n_out) displacement
        out[i] = -((k[None, :, None] * omega[:, None, None]) ** 2) * q
    return out


def truth_misfit(
    truth: str | Truth,
    reference: str | Truth = "reference",
    test: PaperTest | None = None,
    frequencies_hz: np.ndarray | None = None,
) -> Misfit:
    """Misfit of a truth against the reference in units of the phasor noise.

    Parameters
    ----------
    truth, reference : str or Truth
        Truth names or loaded truths; the noise floor is ``truth``'s.
    test : PaperTest, optional
    frequencies_hz : ndarray, shape (n_f,), optional
        Fundamental frequencies of the steps, default :func:`paper_frequencies` (for example
        :func:`second_mode_frequencies` for a test in another band).

    Returns
    -------
    Misfit
    """
    test = test or PaperTest()
    truth = truth if isinstance(truth, Truth) else load_truth(truth)
    reference = reference if isinstance(reference, Truth) else load_truth(reference)
    f = paper_frequencies_hz() if frequencies_hz is None else np.asarray(frequencies_hz, float)
    a = response_sweep(truth, test, f)
    b = response_sweep(reference, test, f)
    root = np.sqrt(2.0 * f / test.averaged_periods)  # sqrt(2 / T), shape (n_f,)
    sigma_a = truth.noise.acceleration_ms2_per_rthz * root[None, :, None, None]
    levels = np.asarray(test.levels_n)[:, None, None, None]
    sigma_f = truth.noise.force_n_per_rthz * root[None, :, None, None] / levels
    sigma = np.sqrt(sigma_a**2 + (np.abs(b) * sigma_f) ** 2)
    ratio = np.abs(a - b) / sigma
    return Misfit(
        rms_sigma=float(np.sqrt(np.mean(ratio**2))),
        max_sigma=float(ratio.max()),
        by_level=np.sqrt(np.mean(ratio**2, axis=(1, 2, 3))),
        fundamental_rms_sigma=float(np.sqrt(np.mean(ratio[:, :, 0] ** 2))),
    )
