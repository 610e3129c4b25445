"""The simulated DAQ backend: the rig's drive and sensors, backed by a truth structure.

:class:`SimulatedDaq` satisfies ``rig.backends.protocol.DaqBackend`` by shape (this package
does not import ``rig``). The chain it simulates::

    AO volts -> power amplifier (gain, bandwidth, current limit, latched overload)
             -> shaker (armature, suspension, coil, back-EMF) -> stinger
             -> truth structure (sensor masses added, nonlinear elements)
             -> sensors (sensitivity, noise floor) -> ADC (range, clipping, quantisation)

The output program, its cross-fades and the index :meth:`SimulatedDaq.write_periodic` returns
follow the NI driver: a fade starts at the first period boundary of the current waveform at
or after the generation point and lasts ``ramp_s`` rounded up to whole periods of the new
waveform; the returned index is the first sample of a whole period of it. The generation
point is the next sample to be read (fast mode), or in real-time mode the later of that and the
wall clock plus a 50 ms write margin.

Fast mode (default) computes samples on demand, far faster than real time; ``realtime=True``
paces :meth:`SimulatedDaq.read` to the wall clock (for the GUI). Physics and engines:
:mod:`sim_backend.simulation`. Voltage channels read the DAQ output looped back.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sim_backend.amplifier import AmplifierModel
from sim_backend.checks import checked_wave, sensor_specs
from sim_backend.drive import DriveProgram
from sim_backend.errors import SimulatorError, SimulatorTimeout, backend_error, timeout_error
from sim_backend.rig_model import RigModel
from sim_backend.sensors import ChannelChain, FaultSwitches
from sim_backend.simulation import MODES, RigSimulation
from sim_backend.truth import Truth, load_truth

__all__ = ["FaultSwitches", "SimulatedDaq", "SimulatorError", "SimulatorTimeout"]

logger = logging.getLogger(__name__)

_NEW, _CONFIGURED, _RUNNING, _CLOSED = "new", "configured", "running", "closed"
_WRITE_MARGIN_S = 0.05
_RIG_CACHE: dict[tuple, tuple[Truth, RigModel]] = {}
_RIG_CACHE_SIZE = 8


class SimulatedDaq:
    """Simulated DAQ backend of the clearance rig.

    Parameters
    ----------
    truth : str or Path or Truth
        Truth structure (name of a shipped one, a path, or a loaded :class:`Truth`).
    seed : int, optional
        Noise seed (default: the truth's).
    realtime : bool
        Pace reads to the wall clock.
    mode : {"mhb", "time"}
        ``"mhb"``: periodic drives from the balance of the coupled rig with modal transients;
        ``"time"``: time integration for every drive (slow, the reference).
    faults : FaultSwitches, optional
    amplifier : AmplifierModel, optional
        Shared amplifier model (e.g. behind a ``SimulatedAmplifierPort``). Default: one with
        the truth's constants, switched on.
    noise, quantisation : bool
        Sensor noise and ADC quantisation (clipping at the input range always applies).
    sensor_masses_kg : dict of str to float, optional
        Mass of the sensor of a channel (by name) [kg]; others take the truth's defaults (an
        impedance head at the drive point, an accelerometer elsewhere).
    record_output : bool
        Keep every drive sample generated (see :meth:`output_samples`).
    stop_ramp_s : float
        Ramp to 0 V in :meth:`stop` [s].
    time_substeps : int, optional
        Integration steps per sample in time segments (default 1 in mhb mode, 4 in time
        mode).
    """

    name = "sim"

    def __init__(
        self,
        truth: str | Path | Truth = "reference",
        seed: int | None = None,
        realtime: bool = False,
        mode: str = "mhb",
        faults: FaultSwitches | None = None,
        amplifier: AmplifierModel | None = None,
        *,
        noise: bool = True,
        quantisation: bool = True,
        sensor_masses_kg: Mapping[str, float] | None = None,
        record_output: bool = False,
        stop_ramp_s: float = 0.5,
        time_substeps: int | None = None,
    ) -> None:
        self._state = _CLOSED
        if mode not in MODES:
            raise backend_error(f"SimulatedDaq.mode: expected one of {MODES}, got {mode!r}")
        if not (math.isfinite(stop_ramp_s) and stop_ramp_s >= 0):
            raise backend_error(f"SimulatedDaq.stop_ramp_s: must be >= 0, got {stop_ramp_s}")
        try:
            self.truth = truth if isinstance(truth, Truth) else load_truth(truth)
        except (ValueError, OSError) as exc:
            raise backend_error(f"SimulatedDaq: cannot load the truth structure: {exc}") from exc
        self.seed = self.truth.seed if seed is None else int(seed)
        self.realtime = bool(realtime)
        self.mode = mode
        self._faults = faults or FaultSwitches()
        if amplifier is None:
            amplifier = AmplifierModel(self.truth.amplifier)
            amplifier.enable()
        self.amplifier = amplifier
        self._noise, self._quantisation = bool(noise), bool(quantisation)
        self._masses = dict(sensor_masses_kg or {})
        self._record = bool(record_output)
        self._out: list[np.ndarray] = []
        self._stop_ramp_s = float(stop_ramp_s)
        self._substeps = time_substeps or (4 if mode == "time" else 1)
        self._config: Any = None
        self._rate = math.nan
        self.rig: RigModel | None = None
        self.simulation: RigSimulation | None = None
        self._chain: ChannelChain | None = None
        self._reset_run()
        self._state = _NEW

    # -- what only a simulation knows ---------------------------------------------------------
    def reference_values(self) -> dict:
        """The truth's parameter values, units and modal damping, as a lab would quote a
        reference structure's data sheet (:func:`rig.backends.protocol.reference_values`).

        Only the simulated rig can answer: these are the values the analysis tries to find, so
        they go to a separate file beside the results, never into a measurement file."""
        model = self.truth.model
        return {
            "source": f"simulated rig, truth {self.truth.name!r}",
            "truth": str(self.truth.name),
            "hidden_effect": self.truth.hidden_effect,
            "description": self.truth.description,
            "parameters": model.values(),
            "units": {n: p.unit for n, p in model.parameters.items()},
            "modal_damping": {str(k): float(v) for k, v in model.damping.per_mode.items()},
            "default_modal_damping": float(model.damping.default_zeta),
        }

    # -- properties ---------------------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        """Realised sample rate [Hz] (NaN before :meth:`configure`)."""
        return self._rate

    @property
    def faults(self) -> FaultSwitches:
        """Faults in force."""
        return self._faults

    def set_faults(self, faults: FaultSwitches) -> None:
        """Switch faults; they act from the next :meth:`read`."""
        if not isinstance(faults, FaultSwitches):
            raise backend_error(f"set_faults: expected FaultSwitches, got {faults!r}")
        self._check_fault_channels(faults)
        self._faults = faults

    def output_samples(self) -> np.ndarray:
        """Drive samples generated since :meth:`start` (needs ``record_output``), V."""
        if not self._record:
            raise backend_error("output_samples: construct the SimulatedDaq with record_output")
        return np.concatenate(self._out) if self._out else np.zeros(0)

    @property
    def simulated_time_s(self) -> float:
        """Samples read since :meth:`start` over the sample rate [s]."""
        return self._next / self._rate if self._state == _RUNNING else 0.0

    # -- protocol -----------------------------------------------------------------------------
    def configure(self, config) -> float:
        """Set up the channels and the physics for them; return the realised rate [Hz]."""
        if self._state == _CLOSED:
            raise backend_error("configure: the simulated DAQ is closed")
        if not all(hasattr(config, k) for k in ("sample_rate_hz", "ao", "ai", "buffer_s")):
            raise backend_error(f"configure: expected an AcquisitionConfig, got {config!r}")
        self.stop()
        specs = sensor_specs(config, self.truth, self._masses)
        drive_point = next(
            (c.point for c in config.ai if c.quantity == "force"), self.truth.drive_point
        )
        drive_dir = next((c.direction for c in config.ai if c.quantity == "force"), None)
        key = (id(self.truth), tuple(specs), drive_point, drive_dir)
        cached = _RIG_CACHE.get(key)
        rig = cached[1] if cached is not None and cached[0] is self.truth else None
        if rig is None:
            try:
                rig = RigModel(self.truth, specs, drive_point, drive_dir)
            except (ValueError, KeyError) as exc:
                raise backend_error(f"configure: {exc}") from exc
            if len(_RIG_CACHE) >= _RIG_CACHE_SIZE:
                _RIG_CACHE.pop(next(iter(_RIG_CACHE)))
            _RIG_CACHE[key] = (self.truth, rig)  # the truth is kept: its id stays unique
        rate = float(config.sample_rate_hz)
        self.rig = rig
        self.simulation = RigSimulation(rig, self.amplifier, rate, self.mode, self._substeps)
        noise = self.truth.noise
        self._chain = ChannelChain(
            [c.quantity for c in config.ai],
            [c.sensitivity for c in config.ai],
            [c.range_v for c in config.ai],
            [noise.for_quantity(c.quantity) for c in config.ai],
            rate,
            self.truth.sensors.adc_bits,
            self.seed,
            noise=self._noise,
            quantisation=self._quantisation,
        )
        self._config, self._rate = config, rate
        self._check_fault_channels(self._faults)
        self._physical_columns = [i for i, c in enumerate(config.ai) if c.quantity != "voltage"]
        self._voltage_columns = [i for i, c in enumerate(config.ai) if c.quantity == "voltage"]
        self._reset_run()
        self._state = _CONFIGURED
        logger.info(
            "simulated DAQ configured: truth %s, %d inputs at %g Hz, drive at point %d (%s mode)",
            self.truth.name,
            len(config.ai),
            rate,
            drive_point,
            self.mode,
        )
        return rate

    def write_periodic(self, period_v: np.ndarray, ramp_s: float) -> int:
        """Cross-fade the output to a new periodic waveform (timing as the NI driver).

        Returns
        -------
        int
            First sample of a whole period of the new waveform at full weight; before
            :meth:`start`, the rounded fade length.
        """
        if self._state not in (_CONFIGURED, _RUNNING):
            raise backend_error(
                f"write_periodic: the simulated DAQ is {self._state}, not configured"
            )
        wave = checked_wave(period_v, self._config.ao)
        try:
            ramp = float(ramp_s)
        except (TypeError, ValueError):
            ramp = math.nan
        if not (math.isfinite(ramp) and ramp >= 0):
            raise backend_error(f"write_periodic: ramp_s must be finite and >= 0, got {ramp_s!r}")
        if self._state != _RUNNING:
            self._program = DriveProgram.zero().replaced(wave, 0, ramp * self._rate)
            return self._program.steady_from
        start = self._program.next_boundary(self._generation_point())
        self._program = self._program.replaced(wave, start, ramp * self._rate)
        self.simulation.set_program(self._program, start)
        return self._program.steady_from

    def start(self) -> None:
        """Start output and inputs (the rig starts at rest)."""
        if self._state != _CONFIGURED:
            raise backend_error(f"start: the simulated DAQ is {self._state}, not configured")
        self.simulation.reset()
        self.simulation.set_program(self._program, 0)
        self._out = []
        self._t0 = time.monotonic()
        self._state = _RUNNING

    def read(self, n_samples: int, timeout_s: float) -> tuple[np.ndarray, int]:
        """Read the next input samples.

        Returns
        -------
        data : ndarray, shape (n_samples, n_channels)
            Samples in N, m/s^2 and V, columns in channel order.
        first_index : int
            Sample index of ``data[0]`` counted from :meth:`start`.
        """
        if self._state != _RUNNING:
            raise backend_error(f"read: the simulated DAQ is {self._state}, not running")
        if isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer):
            raise backend_error(f"read: n_samples must be an int, got {n_samples!r}")
        if n_samples < 1:
            raise backend_error(f"read: n_samples must be >= 1, got {n_samples}")
        if not (isinstance(timeout_s, int | float) and math.isfinite(timeout_s) and timeout_s >= 0):
            raise backend_error(f"read: timeout_s must be finite and >= 0, got {timeout_s!r}")
        n, first = int(n_samples), self._next
        self._wait_for(first + n, float(timeout_s))
        faults = self._faults
        if faults.amplifier_overload and not self.amplifier.state().overload:
            self.amplifier.force_overload("fault injection")
        physical = self.simulation.take(n)
        index = np.arange(first, first + n)
        drive = self._program.samples(index)
        signals = np.empty((n, len(self._config.ai)))
        signals[:, self._physical_columns] = physical
        signals[:, self._voltage_columns] = drive[:, None]
        names = [c.name for c in self._config.ai]
        data = self._chain.acquire(
            signals,
            first,
            [names.index(c) for c in faults.disconnected],
            {names.index(c): v for c, v in faults.clip_levels.items()},
        )
        if self._record:
            self._out.append(drive)
        self._next = first + n
        return data, first

    def stop(self) -> None:
        """Ramp the output to 0 V (``stop_ramp_s``) and stop (idempotent)."""
        if self._state != _RUNNING:
            return
        start = self._generation_point()
        end = start + round(self._stop_ramp_s * self._rate)
        program = DriveProgram(
            np.zeros(1), start, start, end - start, self._program.from_index(start)
        )
        if self._record:
            self._out.append(self._program.samples(np.arange(self._next, start)))
            self._out.append(program.samples(np.arange(start, end + 1)))
        logger.info("simulated DAQ stopped at sample %d (output ramped to 0 V)", end)
        self._reset_run()
        self._state = _CONFIGURED

    def close(self) -> None:
        """Stop and release (idempotent)."""
        if self._state == _CLOSED:
            return
        try:
            self.stop()
        finally:
            self._state = _CLOSED

    def __enter__(self) -> SimulatedDaq:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- helpers ------------------------------------------------------------------------------
    def _reset_run(self) -> None:
        self._program = DriveProgram.zero()
        self._next = 0
        self._t0 = 0.0

    def _generation_point(self) -> int:
        point = max(self._next, self.simulation.index)
        if self.realtime:
            clock = (time.monotonic() - self._t0) * self._rate
            point = max(point, math.ceil(clock + _WRITE_MARGIN_S * self._rate))
        return point

    def _wait_for(self, end_index: int, timeout_s: float) -> None:
        if self._faults.read_timeout:
            if self.realtime:
                time.sleep(timeout_s)
            raise timeout_error(
                f"read: samples up to {end_index} did not arrive within {timeout_s:g} s "
                "(inputs stalled)"
            )
        if not self.realtime:
            return
        now = time.monotonic() - self._t0
        behind = now * self._rate - self._next
        if behind > self._config.buffer_s * self._rate:
            raise backend_error(
                f"read: the input buffer overflowed (read() was not called often enough for "
                f"buffer_s = {self._config.buffer_s:g} s)"
            )
        wait = end_index / self._rate - now
        if wait > timeout_s:
            time.sleep(timeout_s)
            raise timeout_error(
                f"read: {end_index - self._next} samples did not arrive within {timeout_s:g} s"
            )
        if wait > 0:
            time.sleep(wait)

    def _check_fault_channels(self, faults: FaultSwitches) -> None:
        if self._config is None:
            return
        names = {c.name for c in self._config.ai}
        unknown = faults.channels() - names
        if unknown:
            raise backend_error(f"faults name unknown channel(s) {sorted(unknown)}")
