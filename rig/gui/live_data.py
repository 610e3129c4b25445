"""What the live plots show: a run's events accumulated (no Qt here).

:class:`LiveRun` takes every event of :mod:`rig.run.events` in order and keeps what the acquisition
window draws: each finished step's frequency, level and phasors (the multi-harmonic FRFs grow
from them step by step), the force controller's error at every iteration of the step under way,
the iterations and outcome of every step, progress and an estimate of the time left, the
pretest report, warnings and faults, and the run's state.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rig.run.events import (
    ControlIteration,
    Event,
    FaultRaised,
    PretestFinished,
    RecordAcquired,
    RunFinished,
    RunPaused,
    RunResumed,
    RunStarted,
    RunWarning,
    StepFinished,
    StepStarted,
)

__all__ = ["Alarm", "LiveRun", "StepPoint"]


@dataclass(frozen=True)
class StepPoint:
    """One finished step.

    Attributes
    ----------
    plan_index, level_index : int
    sweep_direction : int
        +1 up, -1 down.
    level_n : float
        Target fundamental force [N] (NaN if unknown).
    frequency_hz : float
        Realised fundamental [Hz].
    force : ndarray, shape (H,), complex, N
    response : ndarray, shape (C, H), complex, channel units
    iterations : int
    converged : bool
    error : float
        Final ``max_k |F_k - T_k| / |T_1|``.
    """

    plan_index: int
    level_index: int
    sweep_direction: int
    level_n: float
    frequency_hz: float
    force: np.ndarray
    response: np.ndarray
    iterations: int
    converged: bool
    error: float


@dataclass(frozen=True)
class Alarm:
    """A warning or a fault, for the alarm list."""

    time_s: float
    severity: str  # "warning", "fault", "paused", "info"
    kind: str
    message: str
    channel: str = ""


@dataclass
class LiveRun:
    """Accumulates the events of one run.

    Attributes
    ----------
    state : str
        ``"idle"``, ``"running"``, ``"paused"`` or ``"finished"``.
    plan_name, kind, path : str
    n_steps, n_done : int
        Steps in the plan and on disk (a resumed run starts with some done).
    n_done_at_start : int
    steps : list of StepPoint
        Steps finished in this run, in order.
    channel_names : tuple of str
    current : object or None
        The :class:`rig.config.plans.PlannedStep` under way.
    iterations : list of (int, float, str)
        (iteration, error, status) of the controller in the step under way.
    last_iterations : list of (int, float, str)
        The same for the previous step.
    alarms : list of Alarm
    pretest : object or None
        :class:`rig.procedures.pretest.PretestReport`.
    status, message : str
        How the run ended (``RunFinished``).
    revision : int
        Grows with every event (the plots redraw when it changed).
    """

    state: str = "idle"
    plan_name: str = ""
    kind: str = ""
    path: str = ""
    n_steps: int = 0
    n_done: int = 0
    n_done_at_start: int = 0
    steps: list[StepPoint] = field(default_factory=list)
    channel_names: tuple[str, ...] = ()
    current: Any = None
    iterations: list[tuple[int, float, str]] = field(default_factory=list)
    last_iterations: list[tuple[int, float, str]] = field(default_factory=list)
    alarms: list[Alarm] = field(default_factory=list)
    pretest: object = None
    status: str = ""
    message: str = ""
    records: tuple[int, int] = (0, 0)
    revision: int = 0
    started_at: float = math.nan
    first_step_at: float = math.nan
    paused_s: float = 0.0
    _paused_at: float = math.nan

    def reset(self) -> None:
        self.__init__()

    # -- events -----------------------------------------------------------------------------
    def add(self, event: Event, now: float | None = None) -> None:
        """Take one event (in the order the engine published them)."""
        now = time.monotonic() if now is None else now
        self.revision += 1
        handler = self._HANDLERS.get(type(event))
        if handler is not None:
            handler(self, event, now)

    def _started(self, e: RunStarted, now: float) -> None:
        keep_alarms = self.alarms
        self.reset()
        self.alarms = keep_alarms
        self.revision = 1
        self.state = "running"
        self.plan_name, self.kind, self.path = e.plan_name, e.kind, e.path
        self.n_steps, self.n_done, self.n_done_at_start = e.n_steps, e.n_done, e.n_done
        self.started_at = now

    def _pretest(self, e: PretestFinished, now: float) -> None:
        self.pretest = e.report
        if self.state == "idle":
            self.state = "running"
        for c in e.report.channels:
            if c.message:
                severity = "fault" if c.status in ("flat", "silent") else "warning"
                self.alarms.append(
                    Alarm(e.time_s, severity, f"pretest {c.status}", c.message, c.name)
                )

    def _step_started(self, e: StepStarted, now: float) -> None:
        if math.isnan(self.first_step_at):
            self.first_step_at = now
        self.current = e.step
        self.n_steps = e.n_steps or self.n_steps
        if self.iterations:
            self.last_iterations = self.iterations
        self.iterations = []

    def _iteration(self, e: ControlIteration, now: float) -> None:
        self.iterations.append((e.iteration, float(e.error), e.status))

    def _step_finished(self, e: StepFinished, now: float) -> None:
        r = e.record
        level = math.nan
        step = self.current
        if step is not None and getattr(step, "plan_index", None) == r.plan_index:
            level = float(step.level_n)
        self.channel_names = tuple(e.channel_names)
        self.steps.append(
            StepPoint(
                int(r.plan_index),
                int(r.level_index),
                int(r.sweep_direction),
                level,
                float(r.frequency_hz),
                np.asarray(r.force, dtype=complex),
                np.asarray(r.response, dtype=complex),
                int(r.control_iterations),
                bool(r.control_converged),
                float(r.control_error),
            )
        )
        self.n_done = e.n_done
        self.n_steps = e.n_steps or self.n_steps

    def _record(self, e: RecordAcquired, now: float) -> None:
        if math.isnan(self.first_step_at):
            self.first_step_at = now
        self.records = (e.index + 1, e.n_records)

    def _warning(self, e: RunWarning, now: float) -> None:
        self.alarms.append(Alarm(e.time_s, "warning", e.kind, e.message, e.channel))

    def _fault(self, e: FaultRaised, now: float) -> None:
        severity = "paused" if e.paused else "fault"
        self.alarms.append(Alarm(e.time_s, severity, e.kind, e.message, e.channel))

    def _paused(self, e: RunPaused, now: float) -> None:
        self.state = "paused"
        self._paused_at = now
        self.alarms.append(Alarm(e.time_s, "info", "paused", f"paused: {e.reason}"))

    def _resumed(self, e: RunResumed, now: float) -> None:
        self.state = "running"
        if not math.isnan(self._paused_at):
            self.paused_s += now - self._paused_at
            self._paused_at = math.nan
        self.alarms.append(Alarm(e.time_s, "info", "resumed", "resumed"))

    def _finished(self, e: RunFinished, now: float) -> None:
        self.state = "finished"
        self.status, self.message = e.status, e.message
        if e.status != "success":
            self.alarms.append(Alarm(e.time_s, "fault", e.status, e.message))

    _HANDLERS = {
        RunStarted: _started,
        PretestFinished: _pretest,
        StepStarted: _step_started,
        ControlIteration: _iteration,
        StepFinished: _step_finished,
        RecordAcquired: _record,
        RunWarning: _warning,
        FaultRaised: _fault,
        RunPaused: _paused,
        RunResumed: _resumed,
        RunFinished: _finished,
    }

    # -- derived ----------------------------------------------------------------------------
    @property
    def fraction_done(self) -> float:
        """Share of the plan done (steps, or records of a random test)."""
        if self.kind == "random":
            done, total = self.records
            return done / total if total else 0.0
        return self.n_done / self.n_steps if self.n_steps else 0.0

    def time_left_s(self, now: float | None = None) -> float:
        """Wall time left at the pace of this run's finished steps (NaN before the first)."""
        now = time.monotonic() if now is None else now
        if self.kind == "random":
            done, total = self.records
            left = total - done
        else:
            done = self.n_done - self.n_done_at_start
            left = self.n_steps - self.n_done
        if done <= 0 or math.isnan(self.first_step_at):
            return math.nan
        paused = self.paused_s + (now - self._paused_at if self.state == "paused" else 0.0)
        per_step = (now - self.first_step_at - paused) / done
        return max(0.0, per_step * left)

    def frf(self, channel: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Over the finished steps: frequencies [Hz], level indices, sweep directions and the
        FRFs ``response / force`` (n, H) of one channel."""
        if not self.steps:
            return np.zeros(0), np.zeros(0, int), np.zeros(0, int), np.zeros((0, 0), complex)
        f = np.array([s.frequency_hz for s in self.steps])
        lv = np.array([s.level_index for s in self.steps])
        sweep = np.array([s.sweep_direction for s in self.steps])
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.array([s.response[channel] / s.force for s in self.steps])
        return f, lv, sweep, h

    def levels_n(self) -> dict[int, float]:
        """Level index -> target force [N] of the levels seen so far."""
        out: dict[int, float] = {}
        for s in self.steps:
            if not math.isnan(s.level_n):
                out[s.level_index] = s.level_n
        return out
