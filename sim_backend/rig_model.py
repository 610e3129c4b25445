"""The simulated rig's physics for one set of sensors: coupled balance problem and state space.

:class:`RigModel` takes a truth structure and the sensors on it (their masses are added to the
structure at their points), couples the shaker at the drive point, and offers

* :meth:`RigModel.steady_state`: the periodic steady state for a periodic amplifier input by
  multi-harmonic balance of the coupled nonlinear system (:class:`HarmonicProblem` on
  :class:`~sim_backend.coupled.CoupledLinearModel`, by default 20 harmonics and 1024 AFT
  samples, above the analysis default of 9 and 128 so that truncation does not cancel between
  truth and model);
* :attr:`RigModel.space`: the diagonalised time-domain model of the same rig
  (:mod:`sim_backend.statespace`) for transients and time integration;
* output rows for every sensor in both forms.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from analysis.linear.reduced import reduced_model
from analysis.mhb.problem import Attachment, HarmonicProblem
from analysis.mhb.solver import MHBPoint, NewtonSettings
from analysis.mhb.sweep import solve_steps
from analysis.system import build_linear
from sim_backend.coupled import CoupledLinearModel
from sim_backend.statespace import ModalStateSpace, build_state_space
from sim_backend.truth import Truth

__all__ = ["MAX_DRIVE_ORDER", "RigModel", "SensorSpec", "SteadyState"]

logger = logging.getLogger(__name__)

MAX_DRIVE_ORDER = 8  # highest harmonic of the base a periodic drive may carry for the balance
_DIRECTIONS = ("x", "y", "rz")


@dataclass(frozen=True)
class SensorSpec:
    """A sensor on the structure.

    Parameters
    ----------
    quantity : {"force", "acceleration", "voltage"}
        ``force``: the impedance head's force gauge (stinger force); ``acceleration``: an
        accelerometer at ``point``; ``voltage``: the DAQ output looped back (no structure).
    point : int
        Measurement point (ignored for voltage).
    direction : str
        Axis: ``"x"``, ``"y"`` (``"-x"``, ``"-y"`` for a reversed sensor).
    mass_kg : float
        Mass added to the structure at ``point`` [kg].
    """

    quantity: str
    point: int = 0
    direction: str = "y"
    mass_kg: float = 0.0

    def __post_init__(self) -> None:
        if self.quantity not in ("force", "acceleration", "voltage"):
            raise ValueError(f"SensorSpec.quantity: unknown quantity {self.quantity!r}")
        if self.direction.lstrip("-") not in _DIRECTIONS:
            raise ValueError(f"SensorSpec.direction: unknown direction {self.direction!r}")
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0):
            raise ValueError(f"SensorSpec.mass_kg: must be >= 0, got {self.mass_kg!r}")

    @property
    def sign(self) -> float:
        """-1 for a reversed axis."""
        return -1.0 if self.direction.startswith("-") else 1.0


@dataclass
class SteadyState:
    """Periodic steady state of the coupled rig.

    Attributes
    ----------
    omega_base : float
        Base angular frequency [rad/s]; harmonic ``k`` is at ``k * omega_base``.
    u : ndarray, shape (H+1,), complex, V
        Amplifier input times gain (after the DAQ's zero-order hold) per harmonic.
    outputs : ndarray, shape (H+1, n_out), complex
        Phasors of :attr:`RigModel.output_dofs` (m for structural DOFs, N, A).
    f_nl : ndarray, shape (H+1, n_nl), complex, N
        Nonlinear forces on the nonlinear DOFs.
    converged : bool
    message : str
    """

    omega_base: float
    u: np.ndarray
    outputs: np.ndarray
    f_nl: np.ndarray
    converged: bool
    message: str
    point: MHBPoint | None = None

    @property
    def omegas(self) -> np.ndarray:
        """Harmonic angular frequencies, shape (H+1,), rad/s."""
        return np.arange(self.u.size) * self.omega_base


class RigModel:
    """Coupled truth structure, shaker and amplifier for a given set of sensors.

    Parameters
    ----------
    truth : Truth
    sensors : sequence of SensorSpec
    drive_point : int
        Measurement point of the shaker; it pushes in ``drive_direction``.
    drive_direction : str
    n_harmonics, n_time : int
        Harmonics and AFT samples of the balance.
    f_max_hz : float
        Highest retained structural mode (the rest as residual flexibility).
    """

    def __init__(
        self,
        truth: Truth,
        sensors: Sequence[SensorSpec],
        drive_point: int,
        drive_direction: str | None = None,
        *,
        n_harmonics: int = 20,
        n_time: int = 1024,
        f_max_hz: float = 2000.0,
    ) -> None:
        self.truth = truth
        self.sensors = tuple(sensors)
        masses: dict[int, float] = {}
        for s in self.sensors:
            if s.quantity != "voltage" and s.mass_kg > 0:
                masses[s.point] = masses.get(s.point, 0.0) + s.mass_kg
        model = truth.model.add_masses(masses) if masses else truth.model
        self.model = model
        asm = model.assemble()
        self.assembly = asm
        if drive_point not in model.points:
            raise ValueError(f"drive point {drive_point} is not a measurement point")
        self.drive_point = drive_point
        self.drive_dof = asm.point_dof(drive_point, (drive_direction or "").lstrip("-") or None)
        self.structure = build_linear(model, f_max_hz=f_max_hz)
        amp = truth.amplifier
        self.coupled = CoupledLinearModel(
            self.structure, self.drive_dof, truth.shaker, amp.output_resistance_ohm
        )
        attachments = []
        for spec, element in model.build_elements():
            a = self._dof(asm, spec.at)
            b = None if spec.to is None else self._dof(asm, spec.to)
            attachments.append(Attachment(element, a, b, spec.name))
        struct = []
        for s in self.sensors:
            if s.quantity == "acceleration":
                dof = asm.point_dof(s.point, s.direction.lstrip("-"))
                if dof not in struct:
                    struct.append(dof)
        self.structural_outputs = struct
        c = self.coupled
        self.output_dofs = [*struct, c.force, c.current]
        self.problem = HarmonicProblem(
            c,
            attachments,
            [c.voltage],
            self.output_dofs,
            orders=tuple(Fraction(k) for k in range(1, MAX_DRIVE_ORDER + 1)),
            n_harmonics=n_harmonics,
            n_time=n_time,
        )
        self.nl_dofs = list(self.problem.nl_dofs)
        reduced = reduced_model(self.structure, [*self.nl_dofs, self.drive_dof])
        self.space: ModalStateSpace = build_state_space(
            reduced,
            self.drive_dof,
            self.nl_dofs,
            truth.shaker,
            amp.output_resistance_ohm,
            amp.bandwidth_hz,
        )
        self.bandwidth_hz = amp.bandwidth_hz
        logger.info(
            "rig model %s: %d DOFs, %d nonlinear element(s), %d state modes, drive at point %d",
            truth.name,
            asm.n_dofs,
            len(attachments),
            self.space.size,
            drive_point,
        )

    @staticmethod
    def _dof(asm, ref) -> int:
        if ref.node is not None and ref.direction is not None:
            return asm.dof_index(ref.node, ref.direction)
        return asm.point_dof(ref.point, ref.direction)

    @property
    def n_harmonics(self) -> int:
        return self.problem.n_harmonics

    # -- outputs ------------------------------------------------------------------------------
    def sensor_output(self, sensor: SensorSpec) -> tuple[int, float]:
        """Column of ``SteadyState.outputs`` and sign for a force or acceleration sensor."""
        if sensor.quantity == "force":
            return self.output_dofs.index(self.coupled.force), 1.0
        dof = self.assembly.point_dof(sensor.point, sensor.direction.lstrip("-"))
        return self.structural_outputs.index(dof), sensor.sign

    def sensor_rows(self, sensor: SensorSpec) -> tuple[np.ndarray, np.ndarray]:
        """State-space output row (p,) and nonlinear-force feedthrough (n_nl,) of a sensor."""
        sp = self.space
        if sensor.quantity == "force":
            return sp.force_row(self.drive_dof), np.zeros(len(self.nl_dofs))
        dof = self.assembly.point_dof(sensor.point, sensor.direction.lstrip("-"))
        row, feed = sp.acceleration_rows([dof])
        return sensor.sign * row[0], sensor.sign * feed[0]

    # -- steady state -------------------------------------------------------------------------
    def amplifier_response(self, omega: np.ndarray) -> np.ndarray:
        """Amplifier open-circuit voltage per unit ``u`` (first-order low-pass), shape of omega."""
        return 1.0 / (1.0 + 1j * np.asarray(omega) / (2 * np.pi * self.bandwidth_hz))

    def steady_state(
        self,
        omega_base: float,
        u: np.ndarray,
        previous: SteadyState | None = None,
        settings: NewtonSettings | None = None,
    ) -> SteadyState:
        """Periodic steady state for an input with harmonics ``1..len(u)`` of ``omega_base``.

        Parameters
        ----------
        omega_base : float
            Base angular frequency [rad/s].
        u : ndarray, shape (K,), complex, V
            Gain times DAQ-voltage phasors of harmonics ``1..K`` (``K <= MAX_DRIVE_ORDER``),
            hold factor included.
        previous : SteadyState, optional
            The steady state the rig is in: the balance starts from it and steps over to the
            new drive, so a test that sweeps through a jump follows the branch a rig follows.
        settings : NewtonSettings, optional

        Returns
        -------
        SteadyState
            ``converged`` False if the balance failed from every start.
        """
        u = np.asarray(u, dtype=complex)
        if u.size > MAX_DRIVE_ORDER:
            raise ValueError(f"u: at most {MAX_DRIVE_ORDER} harmonics, got {u.size}")
        H = self.n_harmonics
        u_full = np.zeros(H + 1, dtype=complex)
        u_full[1 : u.size + 1] = u
        v = np.zeros((MAX_DRIVE_ORDER, 1), dtype=complex)
        k = np.arange(1, u.size + 1)
        v[: u.size, 0] = u * self.amplifier_response(k * omega_base)
        if not np.any(u):
            zeros = np.zeros((H + 1, len(self.output_dofs)), dtype=complex)
            return SteadyState(
                omega_base, u_full, zeros, np.zeros((H + 1, len(self.nl_dofs)), complex), True, ""
            )
        settings = settings or NewtonSettings(rtol=1e-11, max_iterations=60)
        last = previous
        if last is not None and last.point is not None and last.converged:
            omegas = np.array([last.omega_base, omega_base])
            force = np.stack([last.point.force[self.problem.order_k], v])
            result = solve_steps(self.problem, omegas, force, X0=last.point.X, settings=settings)
            point = result.points[-1]
        else:
            point = solve_steps(self.problem, np.array([omega_base]), v, settings=settings).points[
                0
            ]
        state = SteadyState(
            omega_base, u_full, point.q_out, point.f_nl, point.converged, point.message, point
        )
        if not point.converged:
            logger.warning(
                "balance of the coupled rig did not converge at %.4g Hz: %s",
                omega_base / (2 * np.pi),
                point.message,
            )
        return state
