"""A random-excitation run in the model's coordinates: receptances, channel DOFs, sensor masses.

The file stores H1 per unit drive force in each channel's unit (accelerance, mobility or
receptance) along the sensor axis. Here every motion channel becomes a receptance [m/N] along
the model's axis (a reversed sensor, direction ``"-y"``, changes sign), tied to the model DOF of
its measurement point, and the sensors' masses become point masses for
:meth:`analysis.model.Model.add_masses`.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from os import PathLike

import numpy as np

from analysis.measurement_file import RandomData, RunData, read_measurement
from analysis.model import Model

__all__ = ["CalibrationError", "RunFRFs", "load_random_run", "sensor_masses"]

MOTION = {"displacement": 0, "velocity": 1, "acceleration": 2}
"""Motion quantities and their power of ``i omega`` relative to displacement."""


class CalibrationError(ValueError):
    """The run or the settings do not allow a linear calibration (the message says why)."""


@dataclass(frozen=True)
class RunFRFs:
    """Motion FRFs of a random run as receptances along the model axes.

    Attributes
    ----------
    frequency_hz : ndarray, shape (nf,), Hz
        Positive frequencies of the file.
    H : ndarray, shape (nf, C), complex, m/N
        Receptance of each motion channel along the model's axis of its point.
    coherence : ndarray, shape (nf, C)
    channels : tuple of str, length C
        Channel names.
    points : tuple of int, length C
        Measurement point of each channel.
    directions : tuple of str, length C
        Model direction of each channel (sign removed).
    drive_point : int
    drive_direction : str
    source : str
        The file.
    n_averages : int
        Averages of the H1 estimate (0 if unknown).
    """

    frequency_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    channels: tuple[str, ...]
    points: tuple[int, ...]
    directions: tuple[str, ...]
    drive_point: int
    drive_direction: str
    source: str
    n_averages: int = 0

    def std(self) -> np.ndarray:
        """Standard error of ``H`` from the coherence, shape (nf, C), m/N.

        ``|H| sqrt((1 - gamma^2) / (2 n gamma^2))`` (Bendat and Piersol, *Random Data*, 4th
        ed., sec. 9.2.4), with gamma^2 kept within [1e-6, 1 - 1e-9] and one average if unknown.
        """
        g2 = np.clip(self.coherence, 1e-6, 1.0 - 1e-9)
        n = max(self.n_averages, 1)
        return np.abs(self.H) * np.sqrt((1.0 - g2) / (2.0 * n * g2))

    def dofs(self, model: Model) -> tuple[list[int], int]:
        """Row DOF indices of the channels and the drive DOF in ``model``'s assembly."""
        asm = model.assemble()
        rows = [asm.point_dof(p, d) for p, d in zip(self.points, self.directions, strict=True)]
        return rows, asm.point_dof(self.drive_point, self.drive_direction)


def sensor_masses(data: RandomData) -> dict[int, float]:
    """Sensor mass [kg] per measurement point from the channel table.

    Channels of one device (the same non-empty serial at the same point, e.g. the force and
    acceleration channels of an impedance head) count once, with their largest ``mass_kg``.
    """
    by_device: dict[tuple[int, str], float] = {}
    for i, ch in enumerate(data.channels):
        key = (ch.point, ch.serial or f"#channel{i}")
        by_device[key] = max(by_device.get(key, 0.0), float(ch.mass_kg))
    out: dict[int, float] = defaultdict(float)
    for (point, _), m in by_device.items():
        if m > 0:
            out[point] += m
    return dict(sorted(out.items()))


def load_random_run(run: RandomData | str | PathLike[str], model: Model) -> RunFRFs:
    """Read a random-excitation run and express its motion FRFs in ``model``'s coordinates.

    Parameters
    ----------
    run : RandomData or path
        Any other kind of run is refused.
    model : Model
        Must have every measured point and the drive point.

    Raises
    ------
    CalibrationError
        A stepped-sine file, no motion channel, or a channel or the drive at a point or
        direction the model lacks.
    """
    data = run if isinstance(run, RunData) else read_measurement(run)
    if not isinstance(data, RandomData):
        raise CalibrationError(
            f"{data.path}: kind {type(data).__name__} is not a random-excitation run; linear "
            "calibration needs kind = 'random' (H1 FRFs in /frf)"
        )
    asm = model.assemble()
    act = data.actuator
    _check_dof(
        asm,
        model,
        data,
        f"the actuator (point {act.point}, {act.direction})",
        act.point,
        act.direction.lstrip("-"),
    )
    keep = [
        i
        for i, ch in enumerate(data.channels)
        if ch.quantity in MOTION and ch.role in ("response", "drive-acceleration")
    ]
    if not keep:
        raise CalibrationError(f"{data.path}: no response channel measures motion")
    f = np.asarray(data.frequency_hz, dtype=float)
    pos = f > 0
    w = 2 * np.pi * f[pos]
    H = np.empty((w.size, len(keep)), dtype=complex)
    for j, i in enumerate(keep):
        ch = data.channels[i]
        _check_dof(
            asm,
            model,
            data,
            f"channel {ch.name!r} (point {ch.point}, {ch.direction})",
            ch.point,
            ch.direction.lstrip("-"),
        )
        sign = -1.0 if ch.direction.startswith("-") else 1.0
        H[:, j] = sign * data.h1[pos, i] / (1j * w) ** MOTION[ch.quantity]
    sign_act = -1.0 if act.direction.startswith("-") else 1.0
    chans = [data.channels[i] for i in keep]
    return RunFRFs(
        frequency_hz=f[pos],
        H=sign_act * H,
        coherence=np.asarray(data.coherence)[pos][:, keep],
        channels=tuple(ch.name for ch in chans),
        points=tuple(int(ch.point) for ch in chans),
        directions=tuple(ch.direction.lstrip("-") for ch in chans),
        drive_point=int(act.point),
        drive_direction=act.direction.lstrip("-"),
        source=str(data.path),
        n_averages=int(data.n_averages),
    )


def _check_dof(asm, model: Model, data: RandomData, what: str, point: int, direction: str):
    if point not in model.points:
        raise CalibrationError(
            f"{data.path}: {what}: the model ({model.source}) has no measurement point "
            f"{point}; its points: {sorted(model.points)}"
        )
    try:
        asm.point_dof(point, direction)
    except KeyError as exc:
        raise CalibrationError(f"{data.path}: {what}: {exc.args[0]}") from None
