"""Checks of what the simulated DAQ is asked to do: drive waveforms and input channels."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from sim_backend.errors import backend_error
from sim_backend.rig_model import SensorSpec
from sim_backend.truth import Truth

__all__ = ["checked_wave", "sensor_specs"]

_SENSITIVITY_UNITS = {"force": "mV/N", "acceleration": "mV/g", "voltage": "V/V"}


def checked_wave(period_v: np.ndarray, ao) -> np.ndarray:
    """``period_v`` as a read-only float array, or a backend error naming the problem."""
    try:
        wave = np.array(period_v, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise backend_error(f"write_periodic: period_v is not numeric: {exc}") from exc
    if wave.ndim != 1 or wave.size == 0:
        raise backend_error(
            f"write_periodic: period_v must be a non-empty 1-D array, got shape {wave.shape}"
        )
    if not np.all(np.isfinite(wave)):
        raise backend_error("write_periodic: period_v contains NaN or infinite samples")
    limit = ao.limit_v
    peak = float(np.max(np.abs(wave)))
    if peak > limit:
        raise backend_error(
            f"write_periodic: peak {peak:.6g} V exceeds the output limit {limit:g} V of "
            f"{ao.physical}; nothing was written"
        )
    wave.setflags(write=False)
    return wave


def sensor_specs(config, truth: Truth, masses: Mapping[str, float]) -> list[SensorSpec]:
    """Sensors of a configuration with their masses; a backend error on a bad channel."""
    if not (math.isfinite(config.buffer_s) and config.buffer_s > 0):
        raise backend_error(f"configure: buffer_s must be > 0, got {config.buffer_s}")
    points = truth.model.points
    force_points = {c.point for c in config.ai if c.quantity == "force"}
    if len(force_points) > 1:
        raise backend_error(
            f"configure: force channels at points {sorted(force_points)}: the rig has one "
            "shaker (one drive point)"
        )
    defaults = truth.sensors
    specs = []
    for c in config.ai:
        expected = _SENSITIVITY_UNITS[c.quantity]
        if c.sensitivity_unit != expected:
            raise backend_error(
                f"configure: AI channel {c.name!r}: sensitivity_unit must be {expected!r} "
                f"for a {c.quantity} channel, got {c.sensitivity_unit!r}"
            )
        if c.quantity == "voltage":
            specs.append(SensorSpec("voltage"))
            continue
        if c.point not in points:
            raise backend_error(
                f"configure: AI channel {c.name!r}: point {c.point} is not a measurement "
                f"point of {truth.name} (known: {sorted(points)})"
            )
        if c.direction.lstrip("-") not in ("x", "y"):
            raise backend_error(
                f"configure: AI channel {c.name!r}: direction {c.direction!r} is not x or y"
            )
        if c.quantity == "force":
            mass = defaults.impedance_head_mass_kg
        elif c.point in force_points:
            mass = 0.0  # the impedance head's own accelerometer
        else:
            mass = defaults.accelerometer_mass_kg
        mass = float(masses.get(c.name, mass))
        specs.append(SensorSpec(c.quantity, c.point, c.direction, mass))
    return specs
