"""RECORDING STAND-IN for nidaqmx's task API (``nidaqmx.Task``, ``nidaqmx.system.WatchdogTask``).

This is the one stand-in the test suite allows: it takes the place of the NI-DAQmx driver, which
cannot be reached on machines without NI hardware. It

* records every method call and property assignment, with the arguments bound to the signature
  of the installed nidaqmx method (a misspelt keyword, a missing property or an argument of the
  wrong enum type fails here as it would on the rig);
* emulates one device on one virtual sample clock: a regenerating output buffer (write
  position, space available, onboard FIFO, regeneration of old content), the output start
  trigger on the input start trigger, on-demand output, channel reservation, the idle output
  behaviour, a watchdog timer, input-buffer overflow and read timeouts, raising nidaqmx's own
  error classes with NI-DAQmx error codes;
* returns input samples from a configurable source, by default the output voltage looped back
  through a gain, so the driver's data path (scaling, ordering, sample indices) is exercised.

Time passes only on demand: a read of ``n`` samples advances the clock until ``n`` samples are
there (as a device does while a read blocks), unless :attr:`StandinDevice.stall_after` stops
the clock, and :meth:`StandinDevice.advance` lets time pass with no call from the host (a
stalled or hung host).

What it knows of NI-DAQmx behaviour is taken from NI's documentation (Key Concepts: regeneration,
write status attributes, controlling where in the buffer to write) and from nidaqmx's sources;
it is no substitute for the hardware tests.
"""

from __future__ import annotations

import inspect
import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
from nidaqmx.constants import (
    AccelUnits,
    AOIdleOutputBehavior,
    Coupling,
    ExcitationSource,
    ExcitationVoltageOrCurrent,
    RegenerationMode,
    TaskMode,
    WatchdogAOExpirState,
    WriteRelativeTo,
)
from nidaqmx.error_codes import DAQmxErrors
from nidaqmx.errors import DaqError, DaqReadError, DaqWriteError
from nidaqmx.system import WatchdogTask
from nidaqmx.task import InStream, OutStream, Task, Timing
from nidaqmx.task.channels import AIChannel, AOChannel
from nidaqmx.task.collections import AIChannelCollection, AOChannelCollection
from nidaqmx.task.triggering import StartTrigger
from nidaqmx.types import AOExpirationState

__all__ = ["Call", "StandinDevice", "StandinTask", "StandinWatchdog", "loopback"]

STANDARD_GRAVITY = 9.80665
_ENUM_PROPERTIES: dict[str, type[Enum]] = {
    "ai_coupling": Coupling,
    "ao_idle_output_behavior": AOIdleOutputBehavior,
    "ai_excit_src": ExcitationSource,
    "ai_excit_voltage_or_current": ExcitationVoltageOrCurrent,
    "regen_mode": RegenerationMode,
    "relative_to": WriteRelativeTo,
}

Source = Callable[[np.ndarray, int, Sequence["StandinAIChannel"]], np.ndarray]
_SAMPLES_UNSET = inspect.signature(Task.read).parameters["number_of_samples_per_channel"].default


@dataclass(frozen=True)
class Call:
    """One recorded call: on which object, which method (or ``set <property>``), bound arguments.

    ``target`` reads ``"<kind>:<label>"`` with kind ``ao`` (buffered output task),
    ``ao-on-demand``, ``ai``, ``task`` (no channel) or ``watchdog``, as the object is now.
    """

    source: Any = field(repr=False)
    name: str
    args: dict[str, Any] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return StandinDevice._target(self.source)

    @property
    def target(self) -> str:
        return f"{self.kind}:{self.source.label}"


def loopback(gains: float | Sequence[float] | Mapping[str, float] = 1.0) -> Source:
    """Input source: every channel sees the drive voltage times a gain, in SI units.

    Parameters
    ----------
    gains : float, sequence or mapping
        One gain for all channels, one per channel in order, or one per channel name
        (missing names get 0). Units: N/V, (m/s^2)/V or V/V.
    """

    def source(dac_v: np.ndarray, first_index: int, channels: Sequence[StandinAIChannel]):
        if isinstance(gains, Mapping):
            g = [gains.get(c.name, 0.0) for c in channels]
        elif np.ndim(gains) == 0:
            g = [float(gains)] * len(channels)
        else:
            g = list(gains)
        return np.asarray(g, dtype=float)[:, None] * dac_v[None, :]

    return source


def _bind(func: Callable, *args: Any, **kwargs: Any) -> dict[str, Any]:
    """Bind arguments to the real nidaqmx signature; check enum-typed parameters."""
    signature = inspect.signature(func)
    bound = signature.bind(None, *args, **kwargs)
    bound.apply_defaults()
    values = dict(bound.arguments)
    values.pop(next(iter(signature.parameters)))
    for name, parameter in signature.parameters.items():
        default = parameter.default
        if isinstance(default, Enum) and not isinstance(values[name], type(default)):
            raise TypeError(
                f"{func.__qualname__}: {name} must be a {type(default).__name__}, "
                f"got {values[name]!r}"
            )
    return values


def _error(message: str, code: DAQmxErrors) -> DaqError:
    return DaqError(f"(stand-in) {message}", code.value)


class _Recorded:
    """Base for stand-in objects whose public attributes mirror properties of a real class."""

    _real: type = object

    def __init__(self, task: StandinTask, path: str) -> None:
        object.__setattr__(self, "_task", task)
        object.__setattr__(self, "_path", path)
        object.__setattr__(self, "_values", {})

    def __setattr__(self, name: str, value: Any) -> None:
        if name.startswith("_"):
            object.__setattr__(self, name, value)
            return
        attr = inspect.getattr_static(self._real, name, None)
        if not isinstance(attr, property) or attr.fset is None:
            raise AttributeError(f"{self._real.__name__} has no settable property {name!r}")
        enum = _ENUM_PROPERTIES.get(name)
        if enum is not None and not isinstance(value, enum):
            raise TypeError(f"{self._real.__name__}.{name} takes a {enum.__name__}, got {value!r}")
        self._task._record(f"set {self._path}.{name}", value=value)
        self._values[name] = value

    def __delattr__(self, name: str) -> None:
        attr = inspect.getattr_static(self._real, name, None)
        if not isinstance(attr, property) or attr.fdel is None:
            raise AttributeError(f"{self._real.__name__} has no resettable property {name!r}")
        self._task._record(f"del {self._path}.{name}")
        self._values.pop(name, None)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        if not isinstance(inspect.getattr_static(self._real, name, None), property):
            raise AttributeError(f"{self._real.__name__} has no property {name!r}")
        if name in self._values:
            return self._values[name]
        raise AttributeError(f"the stand-in does not emulate {self._real.__name__}.{name}")


class StandinAIChannel(_Recorded):
    """An input channel: what it measures, its units and range, and its settable properties."""

    _real = AIChannel

    def __init__(self, task: StandinTask, kind: str, args: dict[str, Any]) -> None:
        super().__init__(task, f"ai_channels[{args['name_to_assign_to_channel']!r}]")
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "args", args)
        object.__setattr__(self, "name", args["name_to_assign_to_channel"])
        object.__setattr__(self, "physical", args["physical_channel"])

    def to_channel_units(self, si: np.ndarray) -> np.ndarray:
        """Convert SI samples (N, m/s^2, V) to the units NI-DAQmx returns, clipped to range."""
        if self.kind == "accel" and self.args["units"] is AccelUnits.G:
            si = si / STANDARD_GRAVITY
        return np.clip(si, self.args["min_val"], self.args["max_val"])


class StandinAOChannel(_Recorded):
    """An output channel and its settable properties."""

    _real = AOChannel


class _AIChannels:
    def __init__(self, task: StandinTask) -> None:
        self._task = task

    def _add(self, kind: str, func: Callable, *args: Any, **kwargs: Any) -> StandinAIChannel:
        bound = self._task._record_bound(f"ai_channels.{func.__name__}", func, *args, **kwargs)
        self._task._set_kind("ai", bound["physical_channel"])
        channel = StandinAIChannel(self._task, kind, bound)
        self._task.channels.append(channel)
        return channel

    def add_ai_accel_chan(self, *args: Any, **kwargs: Any) -> StandinAIChannel:
        return self._add("accel", AIChannelCollection.add_ai_accel_chan, *args, **kwargs)

    def add_ai_force_iepe_chan(self, *args: Any, **kwargs: Any) -> StandinAIChannel:
        return self._add("force", AIChannelCollection.add_ai_force_iepe_chan, *args, **kwargs)

    def add_ai_voltage_chan(self, *args: Any, **kwargs: Any) -> StandinAIChannel:
        return self._add("voltage", AIChannelCollection.add_ai_voltage_chan, *args, **kwargs)


class _AOChannels:
    def __init__(self, task: StandinTask) -> None:
        self._task = task

    def add_ao_voltage_chan(self, *args: Any, **kwargs: Any) -> StandinAOChannel:
        func = AOChannelCollection.add_ao_voltage_chan
        bound = self._task._record_bound("ao_channels.add_ao_voltage_chan", func, *args, **kwargs)
        self._task._set_kind("ao", bound["physical_channel"])
        self._task.ao_limits = (bound["min_val"], bound["max_val"])
        channel = StandinAOChannel(self._task, f"ao_channels[{bound['physical_channel']!r}]")
        self._task.ao_channel_objects.append(channel)
        return channel


class _Timing(_Recorded):
    _real = Timing

    def cfg_samp_clk_timing(self, *args: Any, **kwargs: Any) -> None:
        task = self._task
        bound = task._record_bound(
            "timing.cfg_samp_clk_timing", Timing.cfg_samp_clk_timing, *args, **kwargs
        )
        device = task.device
        rate = float(bound["rate"])
        if not 0 < rate <= device.max_rate_hz:
            raise _error(
                f"rate {rate} outside (0, {device.max_rate_hz}]",
                DAQmxErrors.INVALID_ATTRIBUTE_VALUE,
            )
        timebase = device.ao_timebase_hz if task.kind == "ao" else device.timebase_hz
        task.rate = timebase / max(1, round(timebase / rate))
        task.samps_per_chan = int(bound["samps_per_chan"])
        task.timed = True
        if task.kind == "ai":
            device.rate = task.rate

    @property
    def samp_clk_rate(self) -> float:
        return self._task.rate


class _StartTrigger(_Recorded):
    _real = StartTrigger

    def cfg_dig_edge_start_trig(self, *args: Any, **kwargs: Any) -> None:
        func = StartTrigger.cfg_dig_edge_start_trig
        bound = self._task._record_bound(
            "triggers.start_trigger.cfg_dig_edge_start_trig", func, *args, **kwargs
        )
        self._task.trigger_source = bound["trigger_source"]


class _Triggers:
    def __init__(self, task: StandinTask) -> None:
        self.start_trigger = _StartTrigger(task, "triggers.start_trigger")


class _OutStream(_Recorded):
    _real = OutStream

    @property
    def total_samp_per_chan_generated(self) -> int:
        self._task._check_usable()
        return self._task.generated

    @property
    def space_avail(self) -> int:
        return self._task.space_available()

    @property
    def curr_write_pos(self) -> int:
        return self._task.written

    @property
    def output_onbrd_buf_size(self) -> int:
        return self._task.device.onboard_fifo

    @property
    def output_buf_size(self) -> int:
        return self._values.get("output_buf_size", self._task.samps_per_chan)


class _InStream(_Recorded):
    _real = InStream

    @property
    def total_samp_per_chan_acquired(self) -> int:
        return self._task.acquired

    @property
    def avail_samp_per_chan(self) -> int:
        return self._task.acquired - self._task.read_pos

    @property
    def curr_read_pos(self) -> int:
        return self._task.read_pos

    @property
    def input_buf_size(self) -> int:
        return self._values.get("input_buf_size", self._task.samps_per_chan)


class StandinTask:
    """Stands in for ``nidaqmx.Task``: an output or an input task on a :class:`StandinDevice`."""

    def __init__(self, device: StandinDevice, label: str) -> None:
        self.device = device
        self.label = label
        self.kind = ""  # "ao" or "ai" once a channel is added
        self.channels: list[StandinAIChannel] = []
        self.ao_channel_objects: list[StandinAOChannel] = []
        self.physical: list[str] = []
        self.ao_limits = (-10.0, 10.0)
        self.ao_channels = _AOChannels(self)
        self.ai_channels = _AIChannels(self)
        self.timing = _Timing(self, "timing")
        self.triggers = _Triggers(self)
        self.out_stream = _OutStream(self, "out_stream")
        self.in_stream = _InStream(self, "in_stream")
        self.rate = 0.0
        self.samps_per_chan = 0
        self.timed = False
        self.trigger_source = ""
        self.closed = False
        self.running = False
        self.armed = False
        self.error: DaqError | None = None
        # output buffer (absolute sample counts since start)
        self.ring = np.zeros(0)
        self.written = 0
        self.generated = 0
        self.transferred = 0
        self.fifo = np.zeros(0)
        self.history: list[np.ndarray] = []
        # input buffer
        self.acquired = 0
        self.read_pos = 0
        self.unread = np.zeros((0, 0))
        self.overflowed = False

    # -------------------------------------------------------------- recording

    @property
    def name(self) -> str:
        return self.label

    def _record(self, name: str, **args: Any) -> None:
        self.device._record(self, name, args)

    def _record_bound(self, name: str, func: Callable, *args: Any, **kwargs: Any) -> dict[str, Any]:
        bound = _bind(func, *args, **kwargs)
        self._check_open()
        self.device._record(self, name, bound)
        return bound

    def _set_kind(self, kind: str, physical: str) -> None:
        if self.kind and self.kind != kind:
            raise _error("mixing input and output channels in one task", DAQmxErrors.UNKNOWN)
        owner = physical.strip("/").split("/")[0]
        if owner != self.device.name and not owner.startswith(self.device.name + "Mod"):
            raise _error(f"device {owner!r} not found", DAQmxErrors.INVALID_DEVICE_ID)
        self.kind = kind
        self.physical.append(physical)

    def _check_open(self) -> None:
        if self.closed:
            raise _error("task specified is invalid or does not exist", DAQmxErrors.INVALID_TASK)

    def _check_usable(self) -> None:
        self._check_open()
        if self.error is not None:
            raise self.error

    @property
    def buffer_size(self) -> int:
        return int(self.out_stream.output_buf_size)

    # -------------------------------------------------------------- nidaqmx.Task API

    def start(self) -> None:
        self._record_bound("start", Task.start)
        self._check_usable()
        if self.kind == "ao":
            self._start_output()
        elif self.kind == "ai":
            self._start_input()

    def stop(self) -> None:
        self._record_bound("stop", Task.stop)
        self._end_generation()

    def close(self) -> None:
        if self.closed:
            return
        self._record_bound("close", Task.close)
        self._end_generation()
        self.device._release(self)
        self.closed = True

    def control(self, *args: Any, **kwargs: Any) -> None:
        bound = self._record_bound("control", Task.control, *args, **kwargs)
        if not isinstance(bound["action"], TaskMode):
            raise TypeError(f"Task.control: action must be a TaskMode, got {bound['action']!r}")
        if bound["action"] is TaskMode.TASK_VERIFY and self.idle_zero and not self.device.idle_zero:
            raise _error(
                "ao_idle_output_behavior is not supported by the device",
                DAQmxErrors.ATTRIBUTE_NOT_SUPPORTED_IN_TASK_CONTEXT,
            )
        if bound["action"] in (TaskMode.TASK_UNRESERVE, TaskMode.TASK_ABORT):
            self._end_generation()
            self.device._release(self)

    @property
    def idle_zero(self) -> bool:
        """Whether an output channel's idle output behaviour is set to 0 V."""
        return any(
            c._values.get("ao_idle_output_behavior") is AOIdleOutputBehavior.ZERO_VOLTS
            for c in self.ao_channel_objects
        )

    def _end_generation(self) -> None:
        generating = self.kind == "ao" and self.timed and (self.running or self.armed)
        self.running = self.armed = False
        if generating and self.idle_zero and self.device.idle_zero and not self.device.ao_locked:
            self.device.dac_v = 0.0

    def write(self, *args: Any, **kwargs: Any) -> int:
        bound = self._record_bound("write", Task.write, *args, **kwargs)
        self._check_usable()
        if self.kind != "ao":
            raise _error("write to a task without output channels", DAQmxErrors.UNKNOWN)
        if self.device.ao_locked:
            raise DaqWriteError("(stand-in) watchdog expired", -200678, 0)
        data = np.atleast_1d(np.asarray(bound["data"], dtype=float)).ravel()
        low, high = self.ao_limits
        if np.any(data < low) or np.any(data > high):
            raise DaqWriteError(
                "(stand-in) sample outside the channel range",
                DAQmxErrors.INVALID_AO_DATA_WRITE.value,
                0,
            )
        self.device._reserve(self)
        if not self.timed:
            self.device.dac_v = float(data[-1])
            self.device.on_demand_writes.append(float(data[-1]))
            return data.size
        return self._write_buffer(data)

    def read(self, *args: Any, **kwargs: Any) -> Any:
        bound = self._record_bound("read", Task.read, *args, **kwargs)
        self._check_usable()
        if self.kind != "ai" or not self.running:
            raise _error(
                "read from an input task that is not running",
                DAQmxErrors.CANNOT_READ_WHEN_AUTO_START_FALSE_AND_TASK_NOT_RUNNING_OR_COMMITTED,
            )
        requested = bound["number_of_samples_per_channel"]
        scalar = requested is _SAMPLES_UNSET
        n = 1 if scalar else int(requested)
        if self.acquired - self.read_pos < n:
            need = n - (self.acquired - self.read_pos)
            if self.device.stall_after is not None:
                need = min(need, max(0, self.device.stall_after - self.device.clock))
            self.device.advance(need)
        if self.overflowed:
            raise DaqReadError(
                "(stand-in) samples no longer available (input buffer overflow)",
                DAQmxErrors.SAMPLES_NO_LONGER_AVAILABLE.value,
                0,
            )
        available = self.acquired - self.read_pos
        if available < n:
            self.unread = self.unread[:, available:]
            self.read_pos += available
            raise DaqReadError(
                "(stand-in) some or all of the samples requested have not yet been acquired",
                DAQmxErrors.SAMPLES_NOT_YET_AVAILABLE.value,
                available,
            )
        data, self.unread = self.unread[:, :n], self.unread[:, n:]
        self.read_pos += n
        if scalar:
            return float(data[0, 0]) if data.shape[0] == 1 else data[:, 0].tolist()
        return data[0].tolist() if data.shape[0] == 1 else data.tolist()

    # -------------------------------------------------------------- output emulation

    def space_available(self) -> int:
        """Space as NI defines it: generated + buffer size - write position, capped at size."""
        position = self._write_position()
        if not self.running and not self.armed:
            return self.buffer_size - position
        return min(self.generated + self.buffer_size - position, self.buffer_size)

    def _write_position(self) -> int:
        relative = self.out_stream._values.get(
            "relative_to", WriteRelativeTo.CURRENT_WRITE_POSITION
        )
        offset = int(self.out_stream._values.get("offset", 0))
        return offset if relative is WriteRelativeTo.FIRST_SAMPLE else self.written + offset

    def _write_buffer(self, data: np.ndarray) -> int:
        size = self.buffer_size
        if self.ring.size != size:
            if self.running or self.armed:
                raise _error("buffer size changed while running", DAQmxErrors.UNKNOWN)
            self.ring = np.zeros(size)
        position = self._write_position()
        if data.size > self.space_available():
            raise DaqWriteError(
                "(stand-in) samples could not be written yet: no space in the buffer",
                DAQmxErrors.SAMPLES_CAN_NOT_YET_BE_WRITTEN.value,
                0,
            )
        self.ring[(position + np.arange(data.size)) % size] = data
        self.written = position + data.size
        return data.size

    def _start_output(self) -> None:
        if not self.timed:
            return
        if self.ring.size == 0 or self.written < self.ring.size:
            raise _error(
                "write the whole output buffer before start", DAQmxErrors.OUTPUT_BUFFER_EMPTY
            )
        self.device._reserve(self)
        self.generated = 0
        self.transferred = 0
        self.fifo = np.zeros(0)
        self.history = []
        self._transfer(self.device.onboard_fifo)
        self.device.ao_task = self
        if not self.trigger_source:
            self.running = True
            self.device._drive(self.device.untriggered_lead)
            return
        expected = f"/{self.device.name}/ai/StartTrigger"
        if self.trigger_source != expected:
            raise _error(f"unknown trigger terminal {self.trigger_source!r}", DAQmxErrors.UNKNOWN)
        self.armed = True  # waits for the input start trigger

    def _transfer(self, upto: int) -> None:
        if upto <= self.transferred:
            return
        index = np.arange(self.transferred, upto)
        regen = self.out_stream._values.get("regen_mode", RegenerationMode.ALLOW_REGENERATION)
        if regen is RegenerationMode.DONT_ALLOW_REGENERATION and index[-1] >= self.written:
            self.error = _error(
                "generation stopped to prevent regeneration of old samples",
                DAQmxErrors.GEN_STOPPED_TO_PREVENT_REGEN_OF_OLD_SAMPLES,
            )
            index = index[index < self.written]
        self.fifo = np.concatenate([self.fifo, self.ring[index % self.ring.size]])
        self.transferred = self.transferred + index.size

    def _generate(self, n: int) -> np.ndarray:
        self._transfer(self.generated + n + self.device.onboard_fifo)
        out = self.fifo[:n]
        if out.size < n:  # buffer underflow: the DAC holds its last value
            hold = out[-1] if out.size else self.device.dac_v
            out = np.concatenate([out, np.full(n - out.size, hold)])
        self.fifo = self.fifo[n:]
        self.generated += n
        self.history.append(out)
        return out

    # -------------------------------------------------------------- input emulation

    def _start_input(self) -> None:
        if not self.timed:
            raise _error("input task needs sample-clock timing", DAQmxErrors.UNKNOWN)
        self.running = True
        self.acquired = 0
        self.read_pos = 0
        self.unread = np.zeros((len(self.channels), 0))
        self.overflowed = False
        self.device.clock = 0
        self.device.ai_task = self
        ao = self.device.ao_task
        if ao is not None and ao.armed and not ao.closed:
            ao.armed = False
            ao.running = True

    def _acquire(self, dac_v: np.ndarray, first_index: int) -> None:
        si = np.asarray(self.device.ai_source(dac_v, first_index, self.channels), dtype=float)
        if si.shape != (len(self.channels), dac_v.size):
            raise ValueError(f"ai_source returned shape {si.shape}")
        values = np.stack(
            [c.to_channel_units(row) for c, row in zip(self.channels, si, strict=True)]
        )
        self.unread = np.concatenate([self.unread, values], axis=1)
        self.acquired += dac_v.size
        if self.acquired - self.read_pos > int(self.in_stream.input_buf_size):
            self.overflowed = True


class StandinWatchdog:
    """Stands in for ``nidaqmx.system.WatchdogTask`` (timer in virtual clock samples)."""

    def __init__(self, device: StandinDevice, *args: Any, **kwargs: Any) -> None:
        self.device = device
        self.label = f"watchdog{next(device._counter)}"
        self.args = _bind(WatchdogTask.__init__, *args, **kwargs)
        device._record(self, "WatchdogTask", self.args)
        device._maybe_fail(self, "create")
        if not device.has_watchdog:
            raise _error(
                "watchdog timer not supported by the device",
                DAQmxErrors.WATCHDOG_TIMER_NOT_SUPPORTED,
            )
        if self.args["device_name"] != device.name:
            raise _error(
                f"device {self.args['device_name']!r} not found", DAQmxErrors.INVALID_DEVICE_ID
            )
        self.timeout_s = float(self.args["timeout"])
        self.states: list[AOExpirationState] = []
        self.running = False
        self.closed = False
        self._expired = False
        self.last_reset = 0

    def _call(self, name: str, func: Callable, *args: Any, **kwargs: Any) -> dict[str, Any]:
        bound = _bind(func, *args, **kwargs)
        if self.closed:
            raise _error("watchdog task was closed", DAQmxErrors.INVALID_TASK)
        self.device._record(self, name, bound)
        return bound

    def cfg_watchdog_ao_expir_states(self, *args: Any, **kwargs: Any) -> list:
        func = WatchdogTask.cfg_watchdog_ao_expir_states
        bound = self._call("cfg_watchdog_ao_expir_states", func, *args, **kwargs)
        for state in bound["expiration_states"]:
            if not isinstance(state, AOExpirationState):
                raise TypeError(f"expected AOExpirationState, got {state!r}")
            if not isinstance(state.output_type, WatchdogAOExpirState):
                raise TypeError(
                    f"output_type must be a WatchdogAOExpirState, got {state.output_type!r}"
                )
        self.states = list(bound["expiration_states"])
        return []

    def start(self) -> None:
        self._call("start", WatchdogTask.start)
        self.running = True
        self.last_reset = self.device.clock
        self.device.watchdog = self

    def reset_timer(self) -> None:
        self._call("reset_timer", WatchdogTask.reset_timer)
        if self._expired:
            raise _error(
                "cannot reset an expired watchdog", DAQmxErrors.CANT_RESET_EXPIRED_WATCHDOG
            )
        self.last_reset = self.device.clock

    @property
    def expired(self) -> bool:
        return self._expired

    def clear_expiration(self) -> None:
        self._call("clear_expiration", WatchdogTask.clear_expiration)
        self._expired = False
        self.device.ao_locked = False

    def stop(self) -> None:
        self._call("stop", WatchdogTask.stop)
        self.running = False

    def close(self) -> None:
        self._call("close", WatchdogTask.close)
        self.running = False
        self.closed = True
        if self.device.watchdog is self:
            self.device.watchdog = None

    def _check(self, n: int) -> int | None:
        """Offset within the next ``n`` clock samples at which the timer expires, if it does."""
        if not self.running or self._expired or not self.device.rate:
            return None
        limit = round(self.timeout_s * self.device.rate)
        at = self.last_reset + limit - self.device.clock
        return max(0, at) if at < n else None


class StandinDevice:
    """One emulated NI device; hand :meth:`task_factory` and :meth:`watchdog_factory` to the driver.

    Parameters
    ----------
    name : str
        Device name (``"Dev1"``).
    ai_source : callable, optional
        ``source(dac_v, first_index, channels) -> ndarray (n_channels, n)`` in N, m/s^2, V: the
        sensors' signals given the drive voltage at each input sample. Default: loop-back, gain 1.
    has_watchdog : bool
        Whether the device has a watchdog timer able to hold analogue outputs.
    onboard_fifo : int
        Output FIFO size [samples]: samples already moved to it can no longer be changed.
    timebase_hz, max_rate_hz : float
        Sample clocks are ``timebase_hz / integer``; rates above ``max_rate_hz`` are refused.
    ao_timebase_hz : float, optional
        Timebase of the output sample clock, if it differs from the inputs'.
    untriggered_lead : int
        How many samples an output started without a start trigger runs ahead of the inputs.
    idle_zero : bool
        Whether the output channel's idle output behaviour can be set to 0 V.
    """

    def __init__(
        self,
        name: str = "Dev1",
        ai_source: Source | None = None,
        *,
        has_watchdog: bool = True,
        onboard_fifo: int = 64,
        timebase_hz: float = 100e6,
        max_rate_hz: float = 250e3,
        untriggered_lead: int = 37,
        ao_timebase_hz: float | None = None,
        idle_zero: bool = True,
    ) -> None:
        self.name = name
        self.ai_source: Source = ai_source or loopback(1.0)
        self.has_watchdog = has_watchdog
        self.onboard_fifo = onboard_fifo
        self.timebase_hz = timebase_hz
        self.ao_timebase_hz = ao_timebase_hz or timebase_hz
        self.max_rate_hz = max_rate_hz
        self.untriggered_lead = untriggered_lead
        self.idle_zero = idle_zero
        self.calls: list[Call] = []
        self.tasks: list[StandinTask] = []
        self.watchdogs: list[StandinWatchdog] = []
        self.on_demand_writes: list[float] = []
        self.stall_after: int | None = None
        self.rate = 0.0
        self.clock = 0
        self.dac_v = 0.0
        self.ao_locked = False
        self.locked_level = 0.0
        self.ao_task: StandinTask | None = None
        self.ai_task: StandinTask | None = None
        self.watchdog: StandinWatchdog | None = None
        self.dac_trace: list[np.ndarray] = []
        self._reserved: dict[str, StandinTask] = {}
        self._failures: dict[str, list[BaseException]] = {}
        self._counter = itertools.count(1)

    # -------------------------------------------------------------- factories

    def task_factory(self, *args: Any, **kwargs: Any) -> StandinTask:
        """Stands in for ``nidaqmx.Task(new_task_name="")``."""
        bound = _bind(Task.__init__, *args, **kwargs)
        task = StandinTask(self, f"task{next(self._counter)}")
        self._record(task, "Task", bound)
        self._maybe_fail(task, "create")
        self.tasks.append(task)
        return task

    def watchdog_factory(self, *args: Any, **kwargs: Any) -> StandinWatchdog:
        """Stands in for ``nidaqmx.system.WatchdogTask(device_name, timeout=...)``."""
        watchdog = StandinWatchdog(self, *args, **kwargs)
        self.watchdogs.append(watchdog)
        return watchdog

    # -------------------------------------------------------------- test controls

    def fail_next(self, name: str, error: BaseException) -> None:
        """Make the next call ``name`` raise ``error``.

        ``name`` is ``"<target>.<method>"`` with target ``ao`` (buffered output task),
        ``ao-on-demand``, ``ai``, ``task`` (no channel yet) or ``watchdog``, and method as
        recorded (``read``, ``write``, ``start``, ``reset_timer``, ``create``, ...).
        """
        self._failures.setdefault(name, []).append(error)

    def advance(self, n: int) -> None:
        """Let ``n`` clock samples pass with no host call (a stalled or hung host)."""
        if n <= 0:
            return
        ao = self.ao_task
        if self.ao_locked:
            dac = np.full(n, self.locked_level)
        elif ao is not None and ao.running and not ao.closed and ao.error is None:
            dac = ao._generate(n)
        else:
            dac = np.full(n, self.dac_v)
        watchdog = self.watchdog
        if watchdog is not None and not self.ao_locked:
            at = watchdog._check(n)
            if at is not None:
                levels = {s.physical_channel: s.expiration_state for s in watchdog.states}
                held = dac[at - 1] if at else self.dac_v
                self.locked_level = levels.get(ao.physical[0] if ao else "", held)
                dac[at:] = self.locked_level
                watchdog._expired = True
                self.ao_locked = True
                if ao is not None:
                    ao.error = DaqError("(stand-in) watchdog expired", -200678)
        self.dac_v = float(dac[-1])
        self.dac_trace.append(dac)
        ai = self.ai_task
        if ai is not None and ai.running and not ai.closed:
            ai._acquire(dac, self.clock)
        self.clock += n

    def _drive(self, n: int) -> None:
        """Generate ``n`` output samples ahead of the clock (output started without trigger)."""
        if self.ao_task is not None and n > 0:
            self.dac_v = float(self.ao_task._generate(n)[-1])

    # -------------------------------------------------------------- inspection

    @property
    def ao_samples(self) -> np.ndarray:
        """Every sample the buffered output generated since its (last) start, in order."""
        task = self.ao_task
        if task is None or not task.history:
            return np.zeros(0)
        return np.concatenate(task.history)

    @property
    def dac_samples(self) -> np.ndarray:
        """The output voltage at every clock sample (what the amplifier saw)."""
        return np.concatenate(self.dac_trace) if self.dac_trace else np.zeros(0)

    def calls_named(self, name: str, kind: str | None = None) -> list[Call]:
        """Recorded calls with this name (``"write"``, ``"set out_stream.regen_mode"``, ...).

        ``kind`` keeps only calls on objects of that kind (see :class:`Call`).
        """
        return [c for c in self.calls if c.name == name and (kind is None or c.kind == kind)]

    # -------------------------------------------------------------- internals

    @staticmethod
    def _target(obj: StandinTask | StandinWatchdog) -> str:
        if isinstance(obj, StandinWatchdog):
            return "watchdog"
        if obj.kind == "ao":
            return "ao" if obj.timed else "ao-on-demand"
        return obj.kind or "task"

    def _record(self, obj: StandinTask | StandinWatchdog, name: str, args: dict[str, Any]) -> None:
        self.calls.append(Call(obj, name, dict(args)))
        self._maybe_fail(obj, name)

    def _maybe_fail(self, obj: StandinTask | StandinWatchdog, name: str) -> None:
        queue = self._failures.get(f"{self._target(obj)}.{name}")
        if queue:
            raise queue.pop(0)

    def _reserve(self, task: StandinTask) -> None:
        for physical in task.physical:
            owner = self._reserved.get(physical)
            if owner is not None and owner is not task and not owner.closed:
                raise DaqError(
                    f"(stand-in) resource {physical} is reserved",
                    DAQmxErrors.PAL_RESOURCE_RESERVED.value,
                )
            if task.timed:
                self._reserved[physical] = task

    def _release(self, task: StandinTask) -> None:
        for physical, owner in list(self._reserved.items()):
            if owner is task:
                del self._reserved[physical]
