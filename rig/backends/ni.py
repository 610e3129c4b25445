"""NI-DAQmx driver: the drive output and the IEPE inputs on one clock.

Tasks
-----
* Output (AO): one voltage channel to the power amplifier, continuous sample-clock timing,
  regeneration allowed, started on the input's start trigger (``/<device>/ai/StartTrigger``).
  The output task is started first (it then waits for the trigger) and the input task second,
  as in NI's ``ai_ao_sync`` example, so output sample ``k`` and input sample ``k`` are taken on
  the same clock edge and a sample index is a phase reference.
* Input (AI): IEPE accelerometers (``add_ai_accel_chan``) and IEPE force sensors
  (``add_ai_force_iepe_chan``) with internal constant-current excitation and AC coupling, and
  voltage channels; continuous, with an input buffer of ``buffer_s``. Samples are returned in
  N, m/s^2 (converted from g with 9.80665 m/s^2 when the channel reports g) and V.
* Watchdog: :class:`rig.backends.ni_watchdog.AoWatchdog`, reset by every :meth:`read`.
* Idle output: where the device supports it, the drive channel's idle output behaviour is set
  to 0 V, so the output drops to 0 V whenever no generation runs (after an abort, or when the
  driver clears the tasks of a killed process); elsewhere it keeps its last value.

For a cDAQ chassis, ``device`` is the chassis name (``"cDAQ1"``, which owns the start-trigger
terminal and the watchdog) and the channels may sit on its modules (``"cDAQ1Mod1/ai0"``).

Output buffer and cross-fades
-----------------------------
The output regenerates a host buffer of ``L`` samples (:attr:`NiDaqBackend.ao_buffer_samples`),
fixed at :meth:`~NiDaqBackend.start` as the smallest whole number of periods of the waveform
then in force that is at least ``ao_buffer_s`` and twice the write margin. The driver describes
the output as a *program*, a function of the sample index counted from start: the periodic
waveform in force, or a raised-cosine cross-fade from the previous program to a new periodic
waveform. It writes the program into the buffer at NI-DAQmx's current write position (Relative
To = current write position, Offset 0), never more samples than the space NI-DAQmx computes
(samples generated + ``L`` - samples written), so a write never waits, and never for samples
closer to the generation point than a margin (the device's onboard output FIFO plus 50 ms),
because samples already moved to the device cannot be changed.

Buffer slot ``s`` is generated at indices ``s, s + L, s + 2L, ...``. When generation has passed
the write position (the host did not write in time, or the steady state needed no writing), the
write position is moved on by whole buffer lengths, which keeps the slot, so every written sample
still lands at the index the program gives it.

Once the last ``L`` written samples lie in the steady part of the program and ``L`` is a whole
number of periods of the waveform, the buffer holds whole periods and the device regenerates it
with no further host involvement. During a cross-fade, and while a waveform whose period does not
divide ``L`` is in force, the driver tops the buffer up from :meth:`~NiDaqBackend.read` (between
input chunks, so a long read does not starve it) and from :meth:`~NiDaqBackend.write_periodic`.

Timing of :meth:`~NiDaqBackend.write_periodic` while running:

* the cross-fade starts at ``k0``, the first period boundary of the current waveform at or after
  the write position (itself at least one margin ahead of generation), so the new waveform's
  period starts where an old period starts: a level change at the same frequency is a pure
  amplitude ramp. ``k0`` lies between one margin and about ``L`` + one margin + one old period
  after the call;
* the fade lasts ``ramp_s`` rounded up to whole periods of the new waveform, and the returned
  index ``k0 + fade`` is the first sample of a whole period of the new waveform;
* this holds if :meth:`~NiDaqBackend.read` is called at least once every ``(L - margin) / fs``
  seconds while a fade runs (or a non-dividing waveform is in force). Otherwise the device
  regenerates older buffer content for the missing time (every written sample is within the
  output limit), a warning is logged, and the hardware watchdog, reset only by reads, forces
  0 V after ``watchdog_s``.

Before :meth:`~NiDaqBackend.start`, :meth:`~NiDaqBackend.write_periodic` replaces the program
with a fade from 0 V starting at index 0 and returns the fade length.
"""

from __future__ import annotations

import atexit
import functools
import logging
import math
import time
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from rig.backends.ni_watchdog import AoWatchdog
from rig.backends.protocol import (
    AcquisitionConfig,
    AIChannelConfig,
    AOChannelConfig,
    BackendError,
    ReadTimeoutError,
)

__all__ = ["NiDaqBackend", "STANDARD_GRAVITY"]

logger = logging.getLogger(__name__)

STANDARD_GRAVITY = 9.80665  # m/s^2 per g
DRIVER_HINT = "Install NI-DAQmx or use --backend sim"

_GUARD_S = 0.05  # host latency allowed between reading the generation count and writing
_DEFAULT_ONBOARD_FIFO = 8192  # used when the device does not report its output FIFO size
_SENSITIVITY_UNITS = {"force": "mV/N", "acceleration": "mV/g", "voltage": "V/V"}
_ACCEL_UNITS = ("g", "m/s^2")

# NI-DAQmx error codes (nidaqmx.error_codes.DAQmxErrors)
_SAMPLES_NOT_YET_AVAILABLE = -200284
_SAMPLES_NO_LONGER_AVAILABLE = -200279
_RESOURCE_RESERVED = -50103
_WATCHDOG_EXPIRED_CODES = frozenset({-200678, -201434, -200712, -200681, -200644, -201478})

_NEW, _CONFIGURED, _RUNNING, _CLOSED = "new", "configured", "running", "closed"


def _import_nidaqmx() -> Any:
    try:
        import nidaqmx
        import nidaqmx.constants
        import nidaqmx.errors
        import nidaqmx.system
    except ImportError as exc:
        raise BackendError(
            f"the nidaqmx Python package is not installed ({exc}); pip install nidaqmx, "
            "or use --backend sim"
        ) from exc
    return nidaqmx


def _driver_missing(exc: BaseException) -> BackendError:
    return BackendError(f"NI-DAQmx driver not found ({exc}). {DRIVER_HINT}")


@dataclass(frozen=True)
class _Program:
    """The drive output as a function of the sample index counted from start.

    ``wave`` (one period, V) repeats with ``wave[0]`` at index ``anchor``; before
    ``fade_start + fade_len`` it is cross-faded from ``before`` (None: 0 V) with the raised-cosine
    weight ``0.5 - 0.5 cos(pi (j + 1) / fade_len)`` of ``wave`` at ``fade_start + j``, which
    reaches exactly 1 at the last sample of the fade.
    """

    wave: np.ndarray
    anchor: int
    fade_start: int
    fade_len: int
    before: _Program | None = None

    @classmethod
    def zero(cls) -> _Program:
        return cls(np.zeros(1), 0, 0, 0, None)

    @property
    def period(self) -> int:
        return int(self.wave.size)

    @property
    def steady_from(self) -> int:
        return self.fade_start + self.fade_len

    def samples(self, index: np.ndarray) -> np.ndarray:
        out = self.wave[(index - self.anchor) % self.period]
        early = index < self.steady_from
        if early.any():
            k = index[early]
            old = self.before.samples(k) if self.before is not None else np.zeros(k.size)
            if self.fade_len:
                x = np.clip((k - self.fade_start + 1) / self.fade_len, 0.0, 1.0)
                weight = 0.5 - 0.5 * np.cos(np.pi * x)
            else:
                weight = np.zeros(k.size)
            out[early] = old + weight * (out[early] - old)
        return out

    def next_boundary(self, index: int) -> int:
        """First index at or after ``index`` where a period of ``wave`` starts."""
        return self.anchor - ((self.anchor - index) // self.period) * self.period

    def from_index(self, index: int) -> _Program:
        """An equivalent program for indices at or after ``index`` (finished fades dropped)."""
        if index >= self.steady_from:
            return _Program(self.wave, self.anchor, self.steady_from, 0, None)
        before = self.before.from_index(index) if self.before is not None else None
        return replace(self, before=before)


def _close_at_exit(ref: weakref.ReferenceType) -> None:
    backend = ref()
    if backend is None:
        return
    try:
        backend.close()
    except Exception as exc:  # at interpreter exit: report, never raise
        logger.error("closing the NI backend at exit failed: %s", exc)


class NiDaqBackend:
    """DAQ backend for NI-DAQmx devices (satisfies :class:`rig.backends.protocol.DaqBackend`).

    Parameters
    ----------
    device : str
        Device name as in NI MAX (``"Dev1"``), or a cDAQ chassis name (``"cDAQ1"``). Every
        channel must sit on it (or on one of the chassis' modules, ``"cDAQ1Mod2/ao0"``).
    task_factory : callable, optional
        Creates a task, ``nidaqmx.Task`` by default. Tests pass a stand-in with its interface.
    watchdog_factory : callable, optional
        Creates a watchdog task, ``nidaqmx.system.WatchdogTask`` by default.
    ao_buffer_s : float
        Minimum output buffer length [s]; see the module notes for what it trades (latency of
        :meth:`write_periodic` against tolerance of late reads).
    stop_ramp_s : float
        Length of the raised-cosine ramp to 0 V in :meth:`stop` [s].
    accel_units : {"g", "m/s^2"}
        Units the accelerometer channels are created in (``AccelUnits.G`` is supported by every
        driver version; data are returned in m/s^2 either way).
    stop_timeout_s : float
        Extra time allowed for the ramp in :meth:`stop` before the output is stopped abruptly
        and brought to 0 V otherwise (see :meth:`stop`) [s].

    Raises
    ------
    BackendError
        If ``task_factory`` is not given and the NI-DAQmx driver is not installed.

    Notes
    -----
    Not thread-safe: call it from one thread. Use it as a context manager, or call
    :meth:`close`; an interpreter exit and garbage collection also close it (output ramped to
    0 V first).
    """

    # the output buffer's run state (set by _reset_run_state)
    _next_index: int
    _carry: np.ndarray | None
    _logged_period: int

    name = "ni"

    def __init__(
        self,
        device: str = "Dev1",
        task_factory: Callable[[], Any] | None = None,
        watchdog_factory: Callable[..., Any] | None = None,
        *,
        ao_buffer_s: float = 0.5,
        stop_ramp_s: float = 0.5,
        accel_units: str = "g",
        stop_timeout_s: float = 5.0,
    ) -> None:
        self._state = _CLOSED  # until fully constructed, so __del__ has nothing to do
        if not isinstance(device, str) or not device.strip("/ "):
            raise BackendError(f"NiDaqBackend.device: expected a device name, got {device!r}")
        for label, value, zero_ok in (
            ("ao_buffer_s", ao_buffer_s, False),
            ("stop_ramp_s", stop_ramp_s, True),
            ("stop_timeout_s", stop_timeout_s, False),
        ):
            if not (math.isfinite(value) and (value > 0 or (zero_ok and value == 0))):
                bound = ">= 0" if zero_ok else "> 0"
                raise BackendError(f"NiDaqBackend.{label}: must be finite and {bound}, got {value}")
        if accel_units not in _ACCEL_UNITS:
            raise BackendError(
                f"NiDaqBackend.accel_units: expected one of {_ACCEL_UNITS}, got {accel_units!r}"
            )
        self._nidaqmx = _import_nidaqmx()
        if task_factory is None:
            try:
                version = self._nidaqmx.system.System.local().driver_version
            except self._nidaqmx.errors.Error as exc:
                raise _driver_missing(exc) from exc
            logger.debug("NI-DAQmx driver %s", version)
            task_factory = self._nidaqmx.Task
        self.device = device.strip("/ ")
        self._task_factory = task_factory
        self._watchdog_factory = watchdog_factory or self._nidaqmx.system.WatchdogTask
        self._ao_buffer_s = float(ao_buffer_s)
        self._stop_ramp_s = float(stop_ramp_s)
        self._stop_timeout_s = float(stop_timeout_s)
        self._accel_units = accel_units
        self._config: AcquisitionConfig | None = None
        self._ao: Any = None
        self._ai: Any = None
        self._watchdog = AoWatchdog(None, self.device, 0.0)
        self._rate = math.nan
        self._scale = np.ones(0)
        self._idle_zero = False
        self._margin = 0
        self._atexit_hook: Callable[[], None] | None = None
        self._reset_run_state()
        self._state = _NEW

    # ------------------------------------------------------------------ properties

    @property
    def sample_rate_hz(self) -> float:
        """Realised sample rate [Hz] (NaN before :meth:`configure`)."""
        return self._rate

    @property
    def ao_buffer_samples(self) -> int:
        """Length ``L`` of the regenerated output buffer (0 before :meth:`start`).

        A waveform whose period divides it is regenerated by the device alone once in force.
        """
        return self._buf_len

    @property
    def write_margin_samples(self) -> int:
        """How far ahead of generation the driver writes at least (FIFO + 50 ms)."""
        return self._margin

    @property
    def watchdog_armed(self) -> bool:
        """Whether the device's hardware watchdog guards the drive output."""
        return self._watchdog.armed

    # ------------------------------------------------------------------ protocol

    def configure(self, config: AcquisitionConfig) -> float:
        """Create the output and input tasks and the watchdog; return the realised rate [Hz].

        The drive channel is first set to 0 V by an on-demand write (a crashed earlier run
        may have left a level on it; a device without on-demand output only logs a warning).
        Configuring again releases the previous tasks first.

        Raises
        ------
        BackendError
            On an invalid configuration (channel not on ``device``, sensitivity unit not
            matching the quantity, non-positive buffer or watchdog time), a missing driver, or
            any NI-DAQmx error (the message names the step and the device).
        """
        if self._state == _CLOSED:
            raise BackendError("configure: the NI backend is closed")
        if not isinstance(config, AcquisitionConfig):
            raise BackendError(f"configure: expected an AcquisitionConfig, got {config!r}")
        self._validate(config)
        if self._state != _NEW:
            problems = self._release()
            if problems:
                raise BackendError(
                    "configure: releasing the previous tasks failed: " + "; ".join(problems)
                )
        const = self._nidaqmx.constants
        rate = float(config.sample_rate_hz)
        created: list[Any] = []
        try:
            self._zero_before_configure(config.ao)
            with self._errors("creating the output task"):
                ao = self._new_task(created)
                ao_chan = ao.ao_channels.add_ao_voltage_chan(
                    config.ao.physical, min_val=-config.ao.limit_v, max_val=config.ao.limit_v
                )
                ao.timing.cfg_samp_clk_timing(
                    rate,
                    sample_mode=const.AcquisitionType.CONTINUOUS,
                    samps_per_chan=max(2, round(self._ao_buffer_s * rate)),
                )
                ao.out_stream.regen_mode = const.RegenerationMode.ALLOW_REGENERATION
                ao.triggers.start_trigger.cfg_dig_edge_start_trig(f"/{self.device}/ai/StartTrigger")
                idle_zero = self._zero_when_idle(ao, ao_chan, config.ao.physical)
            with self._errors("creating the input task"):
                ai = self._new_task(created)
                scale = [self._add_input(ai, channel) for channel in config.ai]
                ai.timing.cfg_samp_clk_timing(
                    rate,
                    sample_mode=const.AcquisitionType.CONTINUOUS,
                    samps_per_chan=max(2, math.ceil(config.buffer_s * rate)),
                )
            with self._errors("reading back the sample clock"):
                ai_rate = float(ai.timing.samp_clk_rate)
                ao_rate = float(ao.timing.samp_clk_rate)
            if not math.isclose(ai_rate, ao_rate, rel_tol=1e-9):
                raise BackendError(
                    f"configure: {self.device} realised {ai_rate:.6g} Hz for the inputs but "
                    f"{ao_rate:.6g} Hz for the output (requested {rate:.6g} Hz); choose a rate "
                    "both can realise"
                )
            fifo = self._onboard_fifo(ao)
            watchdog = AoWatchdog.create(
                self._watchdog_factory, self.device, config.ao.physical, config.watchdog_s
            )
        except BaseException:
            for task in created:
                _close_quietly(task)
            raise
        self._config, self._ao, self._ai, self._watchdog = config, ao, ai, watchdog
        self._rate = ai_rate
        self._scale = np.asarray(scale, dtype=float)
        self._idle_zero = idle_zero
        self._margin = fifo + math.ceil(_GUARD_S * ai_rate)
        self._reset_run_state()
        self._state = _CONFIGURED
        if self._atexit_hook is None:
            self._atexit_hook = functools.partial(_close_at_exit, weakref.ref(self))
            atexit.register(self._atexit_hook)
        logger.info(
            "configured %s: %d inputs at %.6g Hz (requested %.6g Hz), drive %s within +/-%g V",
            self.device,
            len(config.ai),
            ai_rate,
            rate,
            config.ao.physical,
            config.ao.limit_v,
        )
        return ai_rate

    def write_periodic(self, period_v: np.ndarray, ramp_s: float) -> int:
        """Cross-fade the output to a new periodic waveform; see the module notes for timing.

        Parameters
        ----------
        period_v : ndarray, shape (n,), V
            One or more whole periods of the new drive; regenerated until the next call.
        ramp_s : float
            Raised-cosine cross-fade length [s], rounded up to whole periods of ``period_v``.

        Returns
        -------
        int
            Index (from :meth:`start`) of the first sample of the new waveform at full weight,
            the start of one of its periods. Before :meth:`start`: the rounded fade length.

        Raises
        ------
        BackendError
            If not configured, if ``period_v`` is not a non-empty finite 1-D array, if any
            sample exceeds the output limit (the message names the limit and the peak), or if
            ``ramp_s`` is negative.
        """
        if self._state not in (_CONFIGURED, _RUNNING):
            raise BackendError(f"write_periodic: the NI backend is {self._state}, not configured")
        wave = self._checked_wave(period_v)
        try:
            ramp = float(ramp_s)
        except (TypeError, ValueError):
            ramp = math.nan
        if not (math.isfinite(ramp) and ramp >= 0):
            raise BackendError(f"write_periodic: ramp_s must be finite and >= 0, got {ramp_s!r}")
        n = wave.size
        fade = math.ceil(ramp * self._rate / n - 1e-9) * n
        if self._state != _RUNNING:
            self._program = _Program(wave, 0, 0, fade, None)
            return fade
        with self._errors("updating the drive output"):
            self._sync_write_position()
            start = self._program.next_boundary(self._w)
            self._program = _Program(wave, start, start, fade, self._program.from_index(self._w))
            self._written_steady = 0
            self._feed()
        if self._buf_len % n and n != self._logged_period:
            self._logged_period = n
            logger.info(
                "period of %d samples does not divide the output buffer of %d samples: the "
                "output is written from read() while it is in force",
                n,
                self._buf_len,
            )
        return start + fade

    def start(self) -> None:
        """Fill the output buffer, arm the watchdog, start the output (armed) and the inputs."""
        if self._state != _CONFIGURED:
            raise BackendError(f"start: the NI backend is {self._state}, not configured")
        const = self._nidaqmx.constants
        n = self._program.period
        floor = max(round(self._ao_buffer_s * self._rate), 2 * self._margin, 2)
        length = math.ceil(floor / n) * n
        data = self._program.samples(np.arange(length))
        try:
            with self._errors("starting"):
                self._watchdog.start()
                stream = self._ao.out_stream
                stream.output_buf_size = length
                stream.relative_to = const.WriteRelativeTo.FIRST_SAMPLE
                stream.offset = 0
                self._ao.write(data, auto_start=False)
                stream.relative_to = const.WriteRelativeTo.CURRENT_WRITE_POSITION
                self._watchdog.reset()
                self._ao.start()
                self._ai.start()
        except BaseException:
            self._halt(ramped=False)
            raise
        self._buf_len = length
        self._chunk = max(1, (length - self._margin) // 2)
        self._w = length
        self._written_steady = int(np.count_nonzero(np.arange(length) >= self._program.steady_from))
        self._state = _RUNNING
        logger.info(
            "started %s: output buffer %d samples (%.3g s), write margin %d samples",
            self.device,
            length,
            length / self._rate,
            self._margin,
        )

    def read(self, n_samples: int, timeout_s: float) -> tuple[np.ndarray, int]:
        """Read the next input samples, keeping the output buffer written between chunks.

        Parameters
        ----------
        n_samples : int
            Samples per channel to read.
        timeout_s : float
            Time allowed for all of them to arrive [s].

        Returns
        -------
        data : ndarray, shape (n_samples, n_channels)
            Samples in N, m/s^2 and V, columns in channel order.
        first_index : int
            Sample index of ``data[0]`` counted from :meth:`start`.

        Raises
        ------
        ReadTimeoutError
            If the samples did not arrive in time. Samples read before the timeout are kept and
            returned first by the next read; if NI-DAQmx consumed samples in the timed-out
            call, they are lost and the next ``first_index`` skips them.
        BackendError
            If not running, on an input-buffer overflow, an expired watchdog or another
            NI-DAQmx error.
        """
        if self._state != _RUNNING:
            raise BackendError(f"read: the NI backend is {self._state}, not running")
        if isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer):
            raise BackendError(f"read: n_samples must be an int, got {n_samples!r}")
        if n_samples < 1:
            raise BackendError(f"read: n_samples must be >= 1, got {n_samples}")
        if not (math.isfinite(timeout_s) and timeout_s >= 0):
            raise BackendError(f"read: timeout_s must be finite and >= 0, got {timeout_s!r}")
        n = int(n_samples)
        deadline = time.monotonic() + float(timeout_s)
        blocks: list[np.ndarray] = []
        got = 0
        if self._carry is not None:
            blocks.append(self._carry[:n])
            got = blocks[0].shape[0]
            self._carry = self._carry[got:] if self._carry.shape[0] > got else None
        while got < n:
            size = min(self._chunk, n - got)
            try:
                blocks.append(self._read_block(size, max(0.0, deadline - time.monotonic())))
            except _Timeout as exc:
                self._after_timeout(blocks, got, exc.lost)
                lost = f", {exc.lost} consumed by the timed-out read and lost" if exc.lost else ""
                raise ReadTimeoutError(
                    f"read: {n} samples did not arrive within {timeout_s:g} s from {self.device} "
                    f"({got} read{lost})"
                ) from exc.__cause__
            got += size
        with self._errors("writing the drive output"):
            self._feed()
        first = self._next_index
        self._next_index += n
        data = blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
        return data, first

    def stop(self) -> None:
        """Ramp the output to 0 V (``stop_ramp_s``), then stop output, inputs and watchdog.

        Idempotent. Input samples acquired during the ramp are discarded. If the ramp cannot
        be completed, the output is stopped abruptly (logged as an error) and held at 0 V by the
        expired watchdog or the idle output behaviour, or else set to 0 V by an on-demand write.

        Raises
        ------
        BackendError
            Only if a task could not be stopped or the drive could not be set to 0 V: the
            output may then not be at 0 V.
        """
        if self._state != _RUNNING:
            return
        ramped = False
        try:
            self._ramp_down()
            ramped = True
        except Exception as exc:
            logger.error("stop: the ramp to 0 V failed (%s); stopping the output abruptly", exc)
        finally:
            problems = self._halt(ramped)
        if problems:
            raise BackendError(
                "stop: " + "; ".join(problems) + " - the drive output may not be at 0 V: "
                "mute the amplifier"
            )

    def close(self) -> None:
        """Stop (output ramped to 0 V) and release every task, even after errors; idempotent.

        Raises
        ------
        BackendError
            If stopping or closing a task failed (everything else is still attempted).
        """
        if self._state == _CLOSED:
            return
        try:
            problems = self._release()
        finally:
            self._state = _CLOSED
            if self._atexit_hook is not None:
                atexit.unregister(self._atexit_hook)
                self._atexit_hook = None
        if problems:
            raise BackendError("close: " + "; ".join(problems))

    def __enter__(self) -> NiDaqBackend:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_state", _CLOSED) == _CLOSED:
            return
        try:
            self.close()
        except Exception:  # garbage collection must not raise
            pass

    # ------------------------------------------------------------------ configuration

    def _validate(self, config: AcquisitionConfig) -> None:
        if not (math.isfinite(config.buffer_s) and config.buffer_s > 0):
            raise BackendError(f"configure: buffer_s must be > 0, got {config.buffer_s}")
        if not (math.isfinite(config.watchdog_s) and config.watchdog_s > 0):
            raise BackendError(f"configure: watchdog_s must be > 0, got {config.watchdog_s}")
        self._check_on_device(config.ao.physical, "the drive output")
        for channel in config.ai:
            self._check_on_device(channel.physical, f"AI channel {channel.name!r}")
            expected = _SENSITIVITY_UNITS[channel.quantity]
            if channel.sensitivity_unit != expected:
                raise BackendError(
                    f"configure: AI channel {channel.name!r}: sensitivity_unit must be "
                    f"{expected!r} for a {channel.quantity} channel, got "
                    f"{channel.sensitivity_unit!r}"
                )
            if channel.iepe and not (0 < channel.excitation_a <= 0.02):
                raise BackendError(
                    f"configure: AI channel {channel.name!r}: excitation_a must be in "
                    f"(0, 0.02] A for IEPE, got {channel.excitation_a}"
                )

    def _check_on_device(self, physical: str, what: str) -> None:
        owner = physical.strip("/").split("/", 1)[0]
        if owner != self.device and not owner.startswith(self.device + "Mod"):
            raise BackendError(
                f"configure: {what} {physical!r} is not on device {self.device!r} (the output "
                "start trigger and the watchdog belong to that device)"
            )

    def _add_input(self, task: Any, channel: AIChannelConfig) -> float:
        """Create one input channel; return the factor from its units to N, m/s^2 or V."""
        const = self._nidaqmx.constants
        source = const.ExcitationSource.INTERNAL if channel.iepe else const.ExcitationSource.NONE
        current = channel.excitation_a if channel.iepe else 0.0
        full_scale = channel.range_v * 1000.0 / channel.sensitivity  # g or N at range_v
        if channel.quantity == "acceleration":
            in_g = self._accel_units == "g"
            limit = full_scale if in_g else full_scale * STANDARD_GRAVITY
            units = const.AccelUnits.G if in_g else const.AccelUnits.METERS_PER_SECOND_SQUARED
            chan = task.ai_channels.add_ai_accel_chan(
                channel.physical,
                name_to_assign_to_channel=channel.name,
                min_val=-limit,
                max_val=limit,
                units=units,
                sensitivity=channel.sensitivity,
                sensitivity_units=const.AccelSensitivityUnits.MILLIVOLTS_PER_G,
                current_excit_source=source,
                current_excit_val=current,
            )
            scale = STANDARD_GRAVITY if in_g else 1.0
        elif channel.quantity == "force":
            chan = task.ai_channels.add_ai_force_iepe_chan(
                channel.physical,
                name_to_assign_to_channel=channel.name,
                min_val=-full_scale,
                max_val=full_scale,
                units=const.ForceUnits.NEWTONS,
                sensitivity=channel.sensitivity,
                sensitivity_units=const.ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON,
                current_excit_source=source,
                current_excit_val=current,
            )
            scale = 1.0
        else:
            chan = task.ai_channels.add_ai_voltage_chan(
                channel.physical,
                name_to_assign_to_channel=channel.name,
                min_val=-channel.range_v,
                max_val=channel.range_v,
                units=const.VoltageUnits.VOLTS,
            )
            if channel.iepe:
                chan.ai_excit_src = const.ExcitationSource.INTERNAL
                chan.ai_excit_voltage_or_current = const.ExcitationVoltageOrCurrent.USE_CURRENT
                chan.ai_excit_val = channel.excitation_a
            scale = 1.0 / channel.sensitivity
        if channel.iepe:
            chan.ai_coupling = const.Coupling.AC
        return scale

    def _zero_when_idle(self, task: Any, chan: Any, physical: str) -> bool:
        """Set the channel to 0 V whenever no generation runs, if the device can; say if so."""
        const, errors = self._nidaqmx.constants, self._nidaqmx.errors
        try:
            chan.ao_idle_output_behavior = const.AOIdleOutputBehavior.ZERO_VOLTS
            task.control(const.TaskMode.TASK_VERIFY)
            return True
        except errors.DaqError as exc:
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
        del chan.ao_idle_output_behavior
        task.control(const.TaskMode.TASK_VERIFY)  # any other problem is a real error
        logger.info(
            "%s cannot be set to 0 V when idle (%s): after an abort it keeps its last value",
            physical,
            reason,
        )
        return False

    def _onboard_fifo(self, ao: Any) -> int:
        try:
            fifo = int(ao.out_stream.output_onbrd_buf_size)
        except self._nidaqmx.errors.DaqError as exc:
            logger.debug(
                "output FIFO size not reported (%s); assuming %d", exc, _DEFAULT_ONBOARD_FIFO
            )
            return _DEFAULT_ONBOARD_FIFO
        return fifo if fifo > 0 else _DEFAULT_ONBOARD_FIFO

    def _new_task(self, created: list[Any]) -> Any:
        task = self._task_factory()
        created.append(task)
        return task

    def _zero_before_configure(self, ao: AOChannelConfig) -> None:
        errors = self._nidaqmx.errors
        try:
            self._zero_output(ao)
        except errors.DaqError as exc:
            if exc.error_code == _RESOURCE_RESERVED:
                raise self._translate(exc, "setting the drive output to 0 V") from exc
            logger.warning(
                "could not set %s to 0 V on demand before configuring (%s)",
                ao.physical,
                str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__,
            )
        except errors.Error as exc:
            raise _driver_missing(exc) from exc

    def _zero_output(self, ao: AOChannelConfig) -> None:
        """Set the drive channel to 0 V with a one-sample on-demand task."""
        task = self._task_factory()
        try:
            task.ao_channels.add_ao_voltage_chan(
                ao.physical, min_val=-ao.limit_v, max_val=ao.limit_v
            )
            task.write(0.0, auto_start=True)
        finally:
            task.close()

    def _checked_wave(self, period_v: np.ndarray) -> np.ndarray:
        try:
            wave = np.array(period_v, dtype=float, copy=True)
        except (TypeError, ValueError) as exc:
            raise BackendError(f"write_periodic: period_v is not numeric: {exc}") from exc
        if wave.ndim != 1 or wave.size == 0:
            raise BackendError(
                f"write_periodic: period_v must be a non-empty 1-D array, got shape {wave.shape}"
            )
        if not np.all(np.isfinite(wave)):
            raise BackendError("write_periodic: period_v contains NaN or infinite samples")
        limit = self._config.ao.limit_v
        peak = float(np.max(np.abs(wave)))
        if peak > limit:
            raise BackendError(
                f"write_periodic: peak {peak:.6g} V exceeds the output limit {limit:g} V of "
                f"{self._config.ao.physical}; nothing was written"
            )
        wave.setflags(write=False)
        return wave

    # ------------------------------------------------------------------ output buffer

    def _reset_run_state(self) -> None:
        self._program = _Program.zero()
        self._buf_len = 0
        self._chunk = 1
        self._w = 0
        self._written_steady = 0
        self._next_index = 0
        self._carry = None
        self._logged_period = 0

    def _buffer_clean(self) -> bool:
        """Whether the buffer holds whole periods of the steady waveform (no writing needed)."""
        return self._written_steady >= self._buf_len and self._buf_len % self._program.period == 0

    def _sync_write_position(self) -> int:
        """Move the write position ahead of generation by whole laps; return samples generated."""
        generated = int(self._ao.out_stream.total_samp_per_chan_generated)
        safe = generated + self._margin
        if self._w < safe:
            if self._w < generated and not self._buffer_clean():
                logger.warning(
                    "output buffer of %s ran dry: %d samples of older buffer content were "
                    "regenerated (read() was not called often enough during a cross-fade)",
                    self.device,
                    generated - self._w,
                )
            laps = -((self._w - safe) // self._buf_len)
            self._w += laps * self._buf_len
        return generated

    def _feed(self) -> None:
        """Write the program into the buffer up to one buffer length ahead of generation."""
        generated = self._sync_write_position()
        if self._buffer_clean():
            return
        count = generated + self._buf_len - self._w
        if count <= 0:
            return
        data = self._program.samples(np.arange(self._w, self._w + count))
        self._ao.write(data, auto_start=False, timeout=1.0)
        self._w += count
        steady = min(count, max(0, self._w - self._program.steady_from))
        written = self._written_steady + count if steady == count else steady
        self._written_steady = min(written, self._buf_len)

    def _ramp_down(self) -> None:
        with self._errors("ramping the drive output to 0 V"):
            generated = self._sync_write_position()
            start = self._w
            end = start + round(self._stop_ramp_s * self._rate)
            self._program = _Program(
                np.zeros(1), start, start, end - start, self._program.from_index(start)
            )
            self._written_steady = 0
            self._feed()
        deadline = time.monotonic() + (end - generated) / self._rate + self._stop_timeout_s
        while True:
            with self._errors("ramping the drive output to 0 V"):
                generated = int(self._ao.out_stream.total_samp_per_chan_generated)
            if generated >= end:
                return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BackendError(
                    f"the ramp to 0 V did not finish within {self._stop_timeout_s} s"
                )
            size = max(1, min(self._chunk, end - generated))
            try:
                self._read_block(size, remaining)
            except _Timeout as exc:
                raise BackendError("no input samples arrived during the ramp to 0 V") from exc
            self._next_index += size

    def _halt(self, ramped: bool) -> list[str]:
        """Stop output, inputs and watchdog (each attempted); 0 V on demand if not ramped."""
        problems: list[str] = []
        unreserve = self._nidaqmx.constants.TaskMode.TASK_UNRESERVE
        for label, action in (
            ("stopping the output task", lambda: self._ao.stop()),
            # a task written before start stays reserved after stop: release the channel
            ("releasing the output channel", lambda: self._ao.control(unreserve)),
            ("stopping the input task", lambda: self._ai.stop()),
        ):
            try:
                action()
            except Exception as exc:
                problems.append(f"{label} failed: {exc}")
        physical = self._config.ao.physical if self._config is not None else "the drive"
        if ramped:
            pass
        elif self._watchdog.expired():
            logger.error("stopped without a ramp; the expired watchdog holds %s at 0 V", physical)
        elif self._idle_zero:
            logger.error(
                "stopped without a ramp; the idle output behaviour holds %s at 0 V", physical
            )
        elif self._config is not None:
            try:
                self._zero_output(self._config.ao)
                logger.error("stopped without a ramp; %s set to 0 V on demand", physical)
            except Exception as exc:
                problems.append(f"setting the drive output to 0 V failed: {exc}")
        try:
            self._watchdog.stop()
        except Exception as exc:
            problems.append(f"stopping the watchdog failed: {exc}")
        self._reset_run_state()
        self._state = _CONFIGURED
        for problem in problems:
            logger.error("%s: %s", self.device, problem)
        return problems

    def _release(self) -> list[str]:
        """Stop, then close every task (each attempted); return what failed."""
        problems: list[str] = []
        try:
            self.stop()
        except Exception as exc:
            problems.append(str(exc))
        finally:
            for label, task in (("output", self._ao), ("input", self._ai)):
                if task is None:
                    continue
                try:
                    task.close()
                except Exception as exc:
                    problems.append(f"closing the {label} task failed: {exc}")
            try:
                self._watchdog.close()
            except Exception as exc:
                problems.append(f"closing the watchdog failed: {exc}")
            self._ao = self._ai = None
            self._watchdog = AoWatchdog(None, self.device, 0.0)
            self._reset_run_state()
            self._state = _NEW
        return problems

    # ------------------------------------------------------------------ input

    def _read_block(self, size: int, timeout_s: float) -> np.ndarray:
        """Write the output ahead, reset the watchdog and read ``size`` samples (SI units)."""
        errors = self._nidaqmx.errors
        with self._errors("writing the drive output"):
            self._feed()
            self._watchdog.reset()
        try:
            raw = self._ai.read(number_of_samples_per_channel=size, timeout=timeout_s)
        except errors.DaqError as exc:
            if exc.error_code == _SAMPLES_NOT_YET_AVAILABLE:
                lost = int(getattr(exc, "samps_per_chan_read", 0) or 0)
                raise _Timeout(lost) from exc
            raise self._translate(exc, "reading the inputs") from exc
        block = np.asarray(raw, dtype=float)
        n_channels = self._scale.size
        if block.size != size * n_channels:
            raise BackendError(
                f"reading the inputs: expected {size} samples x {n_channels} channels, got "
                f"{block.size} values"
            )
        return block.reshape(n_channels, size).T * self._scale

    def _after_timeout(self, blocks: list[np.ndarray], got: int, lost: int) -> None:
        if lost:
            self._next_index += got + lost
            self._carry = None
        elif got:
            self._carry = np.concatenate(blocks)

    # ------------------------------------------------------------------ errors

    @contextmanager
    def _errors(self, action: str) -> Iterator[None]:
        errors = self._nidaqmx.errors
        try:
            yield
        except errors.DaqError as exc:
            raise self._translate(exc, action) from exc
        except errors.Error as exc:
            raise _driver_missing(exc) from exc

    def _translate(self, exc: Any, action: str) -> BackendError:
        code = getattr(exc, "error_code", 0)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        where = f"{action} on {self.device} failed"
        if code in _WATCHDOG_EXPIRED_CODES or self._watchdog.expired():
            return BackendError(f"{where}: {self._watchdog.expiry_message()} ({first})")
        if code == _SAMPLES_NO_LONGER_AVAILABLE:
            buffer_s = self._config.buffer_s if self._config is not None else math.nan
            return BackendError(
                f"{where}: the input buffer overflowed (read() was not called often enough for "
                f"buffer_s = {buffer_s:g} s) ({first})"
            )
        if code == _RESOURCE_RESERVED:
            return BackendError(
                f"{where}: a channel is in use by another task; a crashed process may still "
                f"hold it: reset the device in NI MAX or with "
                f"nidaqmx.system.Device({self.device!r}).reset_device() ({first})"
            )
        return BackendError(f"{where}: {exc}")


class _Timeout(Exception):
    """An input read timed out; ``lost`` samples were consumed by NI-DAQmx and are gone."""

    def __init__(self, lost: int) -> None:
        super().__init__(lost)
        self.lost = lost


def _close_quietly(task: Any) -> None:
    try:
        task.close()
    except Exception as exc:  # cleanup after a failed configuration
        logger.debug("closing a task failed: %s", exc)
