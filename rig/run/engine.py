"""The run engine: executes a procedure's commands on a DAQ backend, safely.

A procedure (a generator of :mod:`rig.run.commands`) decides what to do; the engine does it:
writes drive waveforms, reads the inputs in phase-synchronous blocks, checks every block
against the limits (:mod:`rig.run.safety`), writes completed steps through a sink (the
measurement file), and publishes events (:mod:`rig.run.events`). The numbers in between
(synthesis, harmonic estimation, the settling test) are :mod:`rig.run.acquisition`'s. Further
commands are added with :meth:`RunEngine.register_command`.

Whatever way the run ends, the engine ramps the output to 0 V (the backend's ``stop()``) and
mutes the amplifier if it controls one: on success, on an abort (the operator, a signal, an
abort limit), on a fault, on a DAQ error, on an exception in the procedure, on Ctrl-C. The
outcome (:class:`RunOutcome`) says how the run ended, in words for the file's
``exit_message``, and whether the ramp to 0 V (and the amplifier's mute) actually completed:
when ``stop()`` raises, the message names the error and says the output may not be at 0 V
(never "Output ramped to 0 V").

Pause, resume and abort may be called from any thread. A pause takes effect at the next block
(at most ``read_chunk_s`` of data later): the output ramps to 0 V and the run waits; on resume
the drive is re-applied and the acquisition in progress starts again, settling included (the
force controller's state stays valid: the same drive is applied again). With
``pause_on_fault``, recoverable faults (:data:`rig.run.faults.RECOVERABLE`: clipping, a silent
sensor, no force, an amplifier overload) pause the run instead of ending it.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Protocol

import numpy as np

from analysis.planning.drive_current import ShakerDrive
from rig.backends.protocol import BackendError, DaqBackend, ReadTimeoutError
from rig.config.plans import Limits
from rig.run.acquisition import (
    Output,
    drive_output,
    estimate_window,
    first_sample,
    settling_test,
    silent_output,
    waveform_output,
)
from rig.run.commands import (
    Acquire,
    AcquireRecords,
    BeginStep,
    DriveApplied,
    Measurement,
    Notify,
    Records,
    RunContext,
    SetDrive,
    SetWaveform,
    Warn,
    WaveformApplied,
    WriteRandom,
    WriteStep,
)
from rig.run.events import (
    Event,
    EventBus,
    FaultRaised,
    RecordAcquired,
    RunFinished,
    RunPaused,
    RunResumed,
    RunWarning,
    StepFinished,
    StepStarted,
)
from rig.run.faults import RunAborted, RunFault
from rig.run.safety import SignalChecks, deferred_interrupts

__all__ = ["RunEngine", "RunOutcome", "StepSink"]

logger = logging.getLogger(__name__)

Procedure = Callable[[RunContext], Generator[Any, Any, Any]]


class StepSink(Protocol):
    """Where completed results go (the measurement-file writer, or a test's list)."""

    def append_step(self, record: Any) -> None: ...


@dataclass(frozen=True)
class RunOutcome:
    """How a run ended.

    Attributes
    ----------
    status : {"success", "aborted", "failed"}
        The file's ``exit_status``.
    message : str
        What happened, in words (the file's ``exit_message``; empty on success).
    fault_kind : str
        Kind of the :class:`~rig.run.faults.RunFault` that ended the run, else "".
    interrupted : bool
        Ended by Ctrl-C or a signal.
    steps_written : int
        Steps written in this run.
    rig_time_s : float
        Acquisition time on the DAQ clock (samples read / sample rate) [s].
    wall_s : float
        Wall-clock duration [s].
    output_at_zero : bool
        Whether the final ramp of the output to 0 V (the backend's ``stop()``) completed; when
        it did not, ``message`` names the error and says the output may not be at 0 V.
    """

    status: str
    message: str
    fault_kind: str = ""
    interrupted: bool = False
    steps_written: int = 0
    rig_time_s: float = 0.0
    wall_s: float = 0.0
    output_at_zero: bool = True


class _Restart(Exception):
    """The output was stopped and restarted (a pause): the acquisition starts over."""


class _ProcedureError(Exception):
    """An exception raised by procedure code (not by the engine)."""


class RunEngine:
    """Runs procedures on a backend.

    Parameters
    ----------
    backend : DaqBackend
        Opened (not necessarily configured); the caller closes it.
    setup : rig.config.setup.LabSetup
    channels : sequence of rig.config.setup.ChannelSetup
        Channels to acquire (one of them the drive force).
    limits : Limits
        The plan's drive limit and response limits.
    sample_rate_hz : float, optional
        Requested sample rate (default the setup's).
    bus : EventBus, optional
        Where events go (a new bus by default; see :attr:`bus`).
    amplifier : rig.instruments.PowerAmplifier, optional
        Polled for overload after every measurement and muted at the end.
    pause_on_fault : bool
        Pause on recoverable faults instead of ending the run.
    read_chunk_s : float
        Longest single read [s]: bounds the latency of pause and abort.
    """

    def __init__(
        self,
        backend: DaqBackend,
        setup,
        channels: Sequence,
        limits: Limits,
        *,
        sample_rate_hz: float | None = None,
        bus: EventBus | None = None,
        amplifier=None,
        pause_on_fault: bool = False,
        read_chunk_s: float = 0.25,
    ) -> None:
        self.backend = backend
        self.setup = setup
        self.channels = tuple(channels)
        self.limits = limits
        self.sample_rate_hz = float(sample_rate_hz or setup.daq.sample_rate_hz)
        self.bus = bus or EventBus()
        self.amplifier = amplifier
        self.pause_on_fault = bool(pause_on_fault)
        self.read_chunk_s = float(read_chunk_s)
        roles = [c.role for c in self.channels]
        if roles.count("drive-force") != 1:
            raise ValueError("RunEngine.channels: exactly one drive-force channel is needed")
        self._force_col = roles.index("drive-force")
        self._drive_limit_v = min(limits.drive_peak_v, setup.drive.limit_v)
        self._lock = threading.Lock()
        self._abort = threading.Event()
        self._pause = threading.Event()
        self._resume = threading.Event()
        self._abort_reason = ""
        self._pause_reason = ""
        self._state = "idle"
        self._fs = float("nan")
        self._cursor = 0
        self._samples_read = 0
        self._steps_written = 0
        self._driven = False  # a non-zero output was written (so there was a ramp down)
        self._output: Output | None = None
        self._checks: SignalChecks | None = None
        self._sink: Any = None
        self._amp_warned = False
        self._mute_error = ""
        self._handlers: dict[type, Callable[[RunEngine, Any], Any]] = dict(self._HANDLERS)

    # ------------------------------------------------------------------ control (any thread)
    @property
    def state(self) -> str:
        """``"idle"``, ``"running"``, ``"paused"`` or ``"finished"``."""
        return self._state

    def pause(self, reason: str = "paused by the operator") -> None:
        """Ramp the output down at the next block and wait for :meth:`resume` or :meth:`abort`."""
        with self._lock:
            self._pause_reason = reason
            self._resume.clear()
            self._pause.set()

    def resume(self) -> None:
        """Continue a paused run."""
        with self._lock:
            self._pause.clear()
            self._resume.set()

    def abort(self, reason: str = "aborted by the operator") -> None:
        """End the run at the next block; it is recorded as aborted with ``reason``."""
        with self._lock:
            if not self._abort.is_set():
                self._abort_reason = reason
            self._abort.set()
            self._resume.set()

    def publish(self, event: Event) -> None:
        """Publish an event on the engine's bus."""
        self.bus.publish(event)

    # ------------------------------------------------------------------ the run
    def run(self, procedure: Procedure, sink: Any = None) -> RunOutcome:
        """Configure the backend, run the procedure, ramp down; never raises for run faults.

        Parameters
        ----------
        procedure : callable(RunContext) -> generator
            Yields commands (:mod:`rig.run.commands`).
        sink : object, optional
            Receives ``append_step(record)`` (and ``append_raw(...)``, ``write_random(frf)``).

        Returns
        -------
        RunOutcome
        """
        self._reset(sink)
        t0 = time.monotonic()
        status, message, kind, interrupted = "success", "", "", False
        gen = None
        try:
            ctx = self._start()
            gen = procedure(ctx)
            self._drive_procedure(gen)
        except RunAborted as exc:
            status, message = "aborted", exc.reason
            interrupted = "Ctrl-C" in exc.reason or "signal" in exc.reason
        except RunFault as exc:
            status, message, kind = "aborted", exc.message, exc.kind
            self.publish(FaultRaised(exc.kind, exc.message, exc.channel))
        except KeyboardInterrupt:
            status, message, interrupted = "aborted", "interrupted by the user (Ctrl-C)", True
        except ReadTimeoutError as exc:
            status, kind = "failed", "daq"
            message = f"the DAQ stopped delivering samples ({exc}){self._where()}"
            self.publish(FaultRaised("daq", message))
        except BackendError as exc:
            status, kind = "failed", "daq"
            message = f"DAQ error: {exc}{self._where()}"
            self.publish(FaultRaised("daq", message))
        except _ProcedureError as exc:
            cause = exc.__cause__
            status = "failed"
            message = f"error in the test procedure: {type(cause).__name__}: {cause}"
            logger.error("%s", message, exc_info=cause)
        except Exception as exc:
            status, message = "failed", f"{type(exc).__name__}: {exc}{self._where()}"
            logger.exception("run failed")
        finally:
            with deferred_interrupts():
                stop_error = self._shutdown(gen)
        message = self._ending(status, message, stop_error)
        outcome = RunOutcome(
            status,
            message,
            kind,
            interrupted,
            self._steps_written,
            self._samples_read / self._fs if self._fs == self._fs else 0.0,
            time.monotonic() - t0,
            not stop_error,
        )
        self._state = "finished"
        clean = status == "success" and not stop_error and not self._mute_error
        log = logger.info if clean else logger.warning
        log("run ended: %s %s", status, message)
        self.publish(RunFinished(status, message))
        return outcome

    def _reset(self, sink: Any) -> None:
        self._sink = sink
        self._state = "running"
        self._steps_written = 0
        self._driven = False
        self._samples_read = 0
        self._mute_error = ""

    def _ending(self, status: str, message: str, stop_error: str) -> str:
        """``message`` with what happened to the output (and the amplifier) at the end: said
        only as it happened."""
        if stop_error:
            ending = (
                f"Ramping the output to 0 V FAILED ({stop_error}): the output may not be at 0 V, "
                "check the amplifier and the DAQ output"
            )
            message = f"{message}. {ending}" if message else ending
            message = f"{message}; {self._steps_written} step(s) written"
        elif status != "success":
            output = "Output ramped to 0 V" if self._driven else "Output at 0 V (never driven)"
            message = f"{message}. {output}; {self._steps_written} step(s) written"
        if self._mute_error:
            ending = f"muting the amplifier FAILED ({self._mute_error})"
            message = f"{message}; {ending}" if message else ending
        return message

    def _start(self) -> RunContext:
        config = self.setup.acquisition_config(self.channels, self.sample_rate_hz)
        self._fs = float(self.backend.configure(config))
        drive = ShakerDrive.from_setup(self.setup.to_dict())
        self._checks = SignalChecks(self.channels, self.limits, self._fs, self._warn, drive)
        zero = silent_output(self._fs)
        steady = int(self.backend.write_periodic(zero, 0.0))
        self.backend.start()
        self._output = Output(zero, zero.size, steady, None)
        self._cursor = 0
        return RunContext(self._fs, self.channels, self._force_col, self._drive_limit_v)

    def _drive_procedure(self, gen: Generator) -> None:
        result: Any = None
        while True:
            try:
                command = gen.send(result)
            except StopIteration:
                return
            except (RunFault, RunAborted):
                raise
            except Exception as exc:
                raise _ProcedureError() from exc
            try:
                self._checkpoint()
            except _Restart:
                pass  # paused and resumed between commands: the drive in force is back
            result = self._execute(command)

    def _shutdown(self, gen) -> str:
        """Ramp down, mute, close the procedure; returns why the ramp to 0 V failed, or ""."""
        self._pause.clear()
        stop_error = ""
        try:
            self.backend.stop()
        except Exception as exc:
            logger.exception("ramping the output down failed")
            stop_error = f"{type(exc).__name__}: {exc}"
        if self.amplifier is not None:
            try:
                self.amplifier.mute()
            except Exception as exc:
                logger.exception("muting the amplifier failed")
                self._mute_error = f"{type(exc).__name__}: {exc}"
        if gen is not None:
            try:
                gen.close()
            except Exception:
                logger.exception("closing the procedure failed")
        return stop_error

    # ------------------------------------------------------------------ commands
    def _execute(self, command: Any) -> Any:
        handler = self._handlers.get(type(command))
        if handler is None:
            raise TypeError(f"the engine does not know the command {command!r}")
        return handler(self, command)

    def register_command(
        self, command_type: type, handler: Callable[[RunEngine, Any], Any]
    ) -> None:
        """Let procedures yield commands of ``command_type``.

        The engine calls ``handler(engine, command)`` between its abort and pause checks and
        sends the return value back into the procedure; an exception from the handler ends the
        run like one from the engine's own commands (a :class:`~rig.run.faults.RunFault` as
        that fault), with the output ramped to 0 V. A command type is registered once: the
        built-in commands (:mod:`rig.run.commands`) cannot be replaced.
        """
        if not isinstance(command_type, type):
            raise TypeError(f"register_command: expected a class, got {command_type!r}")
        if not callable(handler):
            raise TypeError(
                f"register_command: the handler of {command_type.__name__} is not callable"
            )
        if command_type in self._handlers:
            raise ValueError(f"register_command: {command_type.__name__} is already registered")
        self._handlers[command_type] = handler

    def _set_drive(self, cmd: SetDrive) -> DriveApplied:
        try:
            out, wave = drive_output(cmd, self._fs, self._drive_limit_v)
        except ValueError as exc:
            raise RunFault(
                "drive-limit",
                f"the drive needed ({exc}) exceeds the drive limit {self._drive_limit_v:g} V"
                f"{self._where()}",
            ) from exc
        out.steady_index = self._write(wave, cmd.ramp_s)
        self._output = out
        return DriveApplied(out.period, out.steady_index, out.drive_v)

    def _set_waveform(self, cmd: SetWaveform) -> WaveformApplied:
        out = waveform_output(cmd)
        peak = float(np.max(np.abs(out.wave))) if out.wave.size else 0.0
        if peak > self._drive_limit_v:
            raise RunFault(
                "drive-limit",
                f"the {cmd.label or 'drive'} waveform peaks at {peak:.4g} V, above the drive "
                f"limit {self._drive_limit_v:g} V",
            )
        out.steady_index = self._write(out.wave, cmd.ramp_s)
        self._output = out
        return WaveformApplied(out.samples_per_period, out.steady_index, peak)

    def _write(self, wave: np.ndarray, ramp_s: float) -> int:
        self._driven = self._driven or bool(np.any(wave))
        return int(self.backend.write_periodic(wave, ramp_s))

    def _begin_step(self, cmd: BeginStep) -> None:
        s = cmd.step
        context = f"at {s.frequency_hz:.4g} Hz, {s.level_n:g} N (step {s.plan_index})"
        self._checks.new_step(context)
        self.publish(StepStarted(s, cmd.n_steps))

    def _write_step(self, cmd: WriteStep) -> None:
        if self._sink is None:
            raise RuntimeError("WriteStep: the run has no sink (measurement file)")
        with deferred_interrupts():
            self._sink.append_step(cmd.record)
            if cmd.samples is not None and hasattr(self._sink, "append_raw"):
                self._sink.append_raw(cmd.record.plan_index, cmd.samples, self._fs, cmd.t0_s)
        self._steps_written += 1
        n_done = getattr(self._sink, "n_complete", self._steps_written)
        n_steps = getattr(self._sink, "n_planned", 0)
        names = tuple(c.name for c in self.channels)
        self.publish(StepFinished(cmd.record, cmd.control, names, n_done, n_steps, cmd.settled))

    def _write_random(self, cmd: WriteRandom) -> None:
        if self._sink is None or not hasattr(self._sink, "write_random"):
            raise RuntimeError("WriteRandom: the run has no sink for a random test")
        with deferred_interrupts():
            self._sink.write_random(cmd.frf)
        self._steps_written += 1

    def _notify(self, cmd: Notify) -> None:
        self.publish(cmd.event)

    def _warn_cmd(self, cmd: Warn) -> None:
        self._warn(cmd.kind, cmd.message, cmd.channel)

    def _warn(self, kind: str, message: str, channel: str = "") -> None:
        logger.warning("%s", message)
        self.publish(RunWarning(kind, message, channel))

    # ------------------------------------------------------------------ acquisition
    def _acquire(self, cmd: Acquire) -> Measurement:
        while True:
            try:
                return self._acquire_once(cmd)
            except _Restart:
                settle = max(cmd.settle_periods, 20)
                cmd = dataclasses.replace(cmd, settle_periods=settle)

    def _acquire_once(self, cmd: Acquire) -> Measurement:
        out = self._output
        if out is None or out.period is None:
            raise RuntimeError("Acquire: no multi-sine drive in force (yield SetDrive first)")
        n = out.samples_per_period
        block = cmd.block_periods * n
        self._skip_to(first_sample(out, self._cursor, cmd.settle_periods), n, out.band_hz)
        orders = out.period.orders
        f = out.period.fundamental_hz
        blocks: deque[np.ndarray] = deque(maxlen=cmd.blocks)
        settled, message = True, ""
        while True:
            blocks.append(self._read_span(block, n, out.band_hz))
            if len(blocks) < cmd.blocks:
                continue
            window = np.concatenate(blocks)
            est, extra = estimate_window(window, self._fs, out, cmd)
            waited = (self._cursor - window.shape[0] - out.steady_index) // n
            if cmd.max_settle_periods is None:
                break
            settled, message = settling_test(est, orders, cmd)
            if settled:
                break
            if waited >= cmd.max_settle_periods:
                self._warn(
                    "not-settled",
                    f"the response did not settle within {cmd.max_settle_periods} periods"
                    f"{self._where()} ({message}); the last {cmd.blocks} blocks are used",
                )
                break
        first = self._cursor - window.shape[0]
        if cmd.check_signals:
            self._poll_amplifier()
            i1 = orders.index(Fraction(1)) if Fraction(1) in orders else 0
            amp = float(abs(out.drive_v[i1])) if out.drive_v is not None else 0.0
            try:
                self._checks.check_measurement(est, window, n, i1, amp)
            except RunFault as fault:
                self._on_fault(fault)
        return Measurement(
            est,
            f,
            first,
            settled,
            int(waited),
            message,
            np.std(window, axis=0),
            window if cmd.keep_samples else None,
            extra,
        )

    def _acquire_records(self, cmd: AcquireRecords) -> Records:
        while True:
            try:
                return self._acquire_records_once(cmd)
            except _Restart:
                cmd = dataclasses.replace(cmd, settle_records=max(cmd.settle_records, 1))

    def _acquire_records_once(self, cmd: AcquireRecords) -> Records:
        out = self._output
        n = out.samples_per_period
        start = first_sample(out, self._cursor, cmd.settle_records)
        self._skip_to(start, n, out.band_hz)
        records = []
        for i in range(cmd.records):
            records.append(self._read_span(n, n, out.band_hz))
            self.publish(RecordAcquired(i, cmd.records, cmd.purpose))
        return Records(np.concatenate(records), start, n, self._fs)

    def _skip_to(self, index: int, period: int, band) -> None:
        """Read (and check) everything before ``index``, in whole periods where possible."""
        if index <= self._cursor:
            return
        head = (index - self._cursor) % period
        if head:
            self._read(head, band, False)
        self._read_span(index - self._cursor, period, band)

    def _read_span(self, n_samples: int, period: int, band) -> np.ndarray:
        """Read ``n_samples`` in pieces of at most ``read_chunk_s`` (whole periods when a period
        fits in that)."""
        chunk = max(1, int(self.read_chunk_s * self._fs))
        per_chunk = (chunk // period) * period if period <= chunk else chunk
        pieces = []
        left = n_samples
        while left > 0:
            k = min(left, per_chunk)
            pieces.append(self._read(k, band, k % period == 0))
            left -= k
        return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)

    def _read(self, n: int, band, periodic: bool = True) -> np.ndarray:
        self._checkpoint()
        timeout = n / self._fs + 5.0
        data, first = self.backend.read(int(n), timeout)
        if first != self._cursor:
            raise BackendError(
                f"samples lost: expected the read to start at sample {self._cursor}, got {first}"
            )
        self._cursor += n
        self._samples_read += n
        try:
            self._checks.check_block(np.asarray(data), band, periodic)
        except RunFault as fault:
            self._on_fault(fault)
        return np.asarray(data)

    def _poll_amplifier(self) -> None:
        amp = self.amplifier
        if amp is None:
            return
        try:
            status = amp.status()
        except Exception as exc:  # a serial hiccup must not end a run
            if not self._amp_warned:
                self._amp_warned = True
                self._warn("amplifier", f"cannot read the amplifier's status: {exc}")
            return
        if status.overload:
            self._on_fault(
                RunFault(
                    "amplifier-overload",
                    f"the power amplifier reported an overload (output current "
                    f"{status.current_a:.3g} A){self._where()}: its output is off; find the "
                    "cause (level, shaker, cables), clear the latch ('rig amplifier clear') and "
                    "resume",
                )
            )
        elif not status.drive_ok:
            self._on_fault(
                RunFault(
                    "no-force",
                    f"the power amplifier's output is {'muted' if status.muted else 'off'}"
                    f"{self._where()}: no drive reaches the shaker",
                )
            )

    # ------------------------------------------------------------------ pause and faults
    def _where(self) -> str:
        ctx = self._checks.context if self._checks is not None else ""
        return f" {ctx}" if ctx else ""

    def _on_fault(self, fault: RunFault) -> None:
        if not (self.pause_on_fault and fault.recoverable):
            raise fault
        self.pause(fault.message)
        logger.warning("pausing: %s", fault.message)
        self.publish(FaultRaised(fault.kind, fault.message, fault.channel, paused=True))
        self._checkpoint()

    def _checkpoint(self) -> None:
        """Honour abort and pause requests (raises RunAborted or _Restart)."""
        if self._abort.is_set():
            raise RunAborted(self._abort_reason or "aborted")
        if not self._pause.is_set():
            return
        with deferred_interrupts():
            self.backend.stop()
        self._state = "paused"
        self.publish(RunPaused(self._pause_reason))
        logger.info("run paused: %s", self._pause_reason)
        while not self._resume.wait(0.1):
            pass
        if self._abort.is_set():
            raise RunAborted(self._abort_reason or "aborted")
        out = self._output
        out.steady_index = self._write(out.wave, 0.2)
        self.backend.start()
        self._cursor = 0
        self._state = "running"
        self.publish(RunResumed())
        logger.info("run resumed")
        raise _Restart()

    _HANDLERS: dict[type, Callable[[RunEngine, Any], Any]] = {
        SetDrive: _set_drive,
        SetWaveform: _set_waveform,
        Acquire: _acquire,
        AcquireRecords: _acquire_records,
        BeginStep: _begin_step,
        WriteStep: _write_step,
        WriteRandom: _write_random,
        Notify: _notify,
        Warn: _warn_cmd,
    }
