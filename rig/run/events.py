"""Progress events of a run, delivered to subscribers by the one event bus.

The engine publishes an event at every milestone: the run starting, the pretest result, each
step starting, every force-control iteration, each step finishing (with its phasors and the
controller's record), warnings and faults, pause and resume, the run finishing. The GUI, the
command line's progress line and an acquisition service subscribe to the same bus.

Callbacks run in the engine's thread, in subscription order, while the engine waits: keep them
short (a GUI hands the event to its own thread, e.g. through a Qt signal). An exception in a
callback is logged and does not stop the run; ``KeyboardInterrupt`` and other
``BaseException`` s pass through (a callback may end a run as Ctrl-C would). Subscribing and
unsubscribing are thread-safe and may happen while a run is under way.

The base :class:`Event`, :class:`EventBus` and :class:`Subscription` are the analysis's
(:mod:`analysis.events`): a run's events and a calibration's or a diagnosis's progress share one
protocol, a callable taking an :class:`Event`, so a front end subscribes to both the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from analysis.events import Event, EventBus, Subscription

__all__ = [
    "ControlIteration",
    "Event",
    "EventBus",
    "FaultRaised",
    "PretestFinished",
    "RecordAcquired",
    "RunFinished",
    "RunPaused",
    "RunResumed",
    "RunStarted",
    "RunWarning",
    "StepFinished",
    "StepStarted",
    "Subscription",
]


@dataclass(frozen=True)
class RunStarted(Event):
    """A run began.

    Attributes
    ----------
    plan_name, kind : str
        The plan and its kind (``"stepped-sine"`` or ``"random"``).
    n_steps : int
        Steps (or records) in the plan.
    n_done : int
        Steps already in the file (a resumed run).
    path : str
        The measurement file.
    """

    plan_name: str
    kind: str
    n_steps: int
    n_done: int
    path: str


@dataclass(frozen=True)
class PretestFinished(Event):
    """The pretest's result (:class:`rig.procedures.pretest.PretestReport`)."""

    report: Any


@dataclass(frozen=True)
class StepStarted(Event):
    """A stepped-sine step began (:class:`rig.config.plans.PlannedStep`)."""

    step: Any
    n_steps: int


@dataclass(frozen=True)
class ControlIteration(Event):
    """One force-control measurement of a step.

    Attributes
    ----------
    plan_index, iteration : int
    status : str
        The controller's decision (``"continue"``, ``"converged"``, ...).
    accepted : bool
        The step ends with this measurement (on target or the controller is done).
    error : float
        ``max_k |F_k - T_k| / |T_1|``.
    frequency_hz : float
        Realised fundamental frequency [Hz].
    drive_v, force_n : ndarray, shape (H,), complex
        Drive applied and force measured.
    force_std_n : ndarray, shape (H,)
        Standard errors of the force phasors [N].
    """

    plan_index: int
    iteration: int
    status: str
    accepted: bool
    error: float
    frequency_hz: float
    drive_v: np.ndarray
    force_n: np.ndarray
    force_std_n: np.ndarray


@dataclass(frozen=True)
class StepFinished(Event):
    """A step is on disk.

    Attributes
    ----------
    record : analysis.measurement_file.StepRecord
        Realised frequency, phasors and standard errors of every channel, drive phasors.
    control : rig.procedures.force_control.StepControlRecord or None
        Every iteration of the force controller.
    channel_names : tuple of str
    n_done, n_steps : int
        Steps on disk and in the plan.
    settled : bool
        Whether the settling test passed before the step's blocks were averaged.
    """

    record: Any
    control: Any
    channel_names: tuple[str, ...]
    n_done: int
    n_steps: int
    settled: bool = True


@dataclass(frozen=True)
class RecordAcquired(Event):
    """A record of a random test was acquired (``index`` of ``n_records``; ``purpose`` says
    ``"calibration"``, ``"settling"`` or ``"average"``)."""

    index: int
    n_records: int
    purpose: str


@dataclass(frozen=True)
class RunWarning(Event):
    """Something the operator should know; the run goes on.

    ``kind`` is a short tag (``"response-alarm"``, ``"not-settled"``, ``"not-converged"``,
    ``"fold"``, ``"amplifier"``, ...); ``channel`` names the channel concerned, if one is.
    """

    kind: str
    message: str
    channel: str = ""


@dataclass(frozen=True)
class FaultRaised(Event):
    """A fault stopped (or paused) the run; ``kind`` as :class:`rig.run.faults.RunFault`."""

    kind: str
    message: str
    channel: str = ""
    paused: bool = False


@dataclass(frozen=True)
class RunPaused(Event):
    """The drive is ramped to 0 V and the run waits for resume or abort."""

    reason: str


@dataclass(frozen=True)
class RunResumed(Event):
    """The run continues after a pause (the step in progress restarts its acquisition)."""


@dataclass(frozen=True)
class RunFinished(Event):
    """The run ended; ``status`` is the file's ``exit_status``."""

    status: str
    message: str
