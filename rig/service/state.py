"""Run records and the queue of the acquisition service, kept as JSON in the service directory.

A run is submitted (``queued``), started by the worker (``running``, ``paused`` while the
engine waits), and ends ``success``, ``aborted`` or ``failed`` (the measurement file's
``exit_status``), ``cancelled`` (aborted before it started) or ``interrupted`` (the service
stopped or died while the run was under way or queued). An interrupted, aborted or failed
stepped-sine run can be resumed: it is queued again and completes its file (the steps on disk
are kept; :meth:`rig.run.session.TestRun.resume`).

Every change is written to ``state.json`` at once (atomically, mode 0600), so a service that
restarts, whether it was stopped or killed, knows every run and reports the interrupted ones;
nothing starts by itself after a restart.

All methods are thread-safe: the HTTP side and the worker thread share one
:class:`ServiceState`.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from rig.run.events import Event
from rig.service.client import FINAL_STATES
from rig.service.directory import write_private

__all__ = ["ACTIVE_STATES", "FINAL_STATES", "RunRecord", "RunState", "ServiceState"]

logger = logging.getLogger(__name__)

ACTIVE_STATES = frozenset({"queued", "running", "paused"})
RESUMABLE_STATES = frozenset({"interrupted", "aborted", "failed"})
_VERSION = 1


@dataclass(frozen=True)
class RunState(Event):
    """The service's own event: a run changed state (queued, running, or how it ended).

    Attributes
    ----------
    state : str
        One of ``queued, running, success, aborted, failed, interrupted, cancelled``.
    message : str
        Why (empty when nothing needs saying).
    n_done, n_steps : int
        Steps on disk and in the plan.
    """

    state: str
    message: str = ""
    n_done: int = 0
    n_steps: int = 0


@dataclass
class RunRecord:
    """What the service knows about one run (the API's run object, plus the plan).

    Attributes
    ----------
    id : str
    plan_name, kind : str
    n_steps : int
        Steps in the plan (records for a random test).
    path : str
        The measurement file.
    plan : dict
        The plan as data (:meth:`rig.config.plans.SteppedSinePlan.to_dict`); rebuilt when it starts.
    label : str
    pause_on_fault : bool
        Recoverable faults pause the run instead of ending it.
    state, message : str
    n_done : int
        Steps on disk.
    events : int
        ``seq`` of the run's last event.
    submitted_s, started_s, finished_s : float or None
        POSIX times; started and finished of the latest attempt.
    attempts : int
        Times the run was started (a resumed run adds one).
    steps_written : int
        Steps written by the latest attempt.
    wall_s, rig_time_s : float
        Wall-clock and DAQ-clock duration of the latest attempt's run [s].
    resume : bool
        The next start continues the file (set when it is resumed).
    """

    id: str
    plan_name: str
    kind: str
    n_steps: int
    path: str
    plan: dict[str, Any]
    label: str = ""
    pause_on_fault: bool = False
    state: str = "queued"
    message: str = ""
    n_done: int = 0
    events: int = 0
    submitted_s: float = field(default_factory=time.time)
    started_s: float | None = None
    finished_s: float | None = None
    attempts: int = 0
    steps_written: int = 0
    wall_s: float = 0.0
    rig_time_s: float = 0.0
    resume: bool = False

    @property
    def resumable(self) -> bool:
        """Ended early: a stepped-sine run completes its file, a random test (whose file is
        written at its end) starts again."""
        if self.state not in RESUMABLE_STATES:
            return False
        if self.kind == "stepped-sine":
            return self.n_done < self.n_steps
        return not Path(self.path).exists()

    def public(self) -> dict[str, Any]:
        """The API's run object (everything but the plan data)."""
        d = {k: v for k, v in asdict(self).items() if k not in ("plan", "resume")}
        d["plan"] = self.plan_name
        d["resumable"] = self.resumable
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunRecord:
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})


class ServiceState:
    """The runs and the queue, persisted to ``path`` on every change.

    Parameters
    ----------
    path : Path
        ``state.json`` in the service directory.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.lock = threading.RLock()
        self.changed = threading.Condition(self.lock)
        self.runs: dict[str, RunRecord] = {}
        self.queue: list[str] = []
        self.next_number = 1

    # ------------------------------------------------------------------ persistence
    @classmethod
    def load(cls, path: Path) -> ServiceState:
        """Read ``path`` (if present); runs left active by a previous service become
        ``interrupted``."""
        state = cls(path)
        if not state.path.exists():
            state.save()
            return state
        try:
            data = json.loads(state.path.read_text(encoding="utf-8"))
            runs = [RunRecord.from_dict(r) for r in data.get("runs", [])]
            state.next_number = int(data.get("next_number", len(runs) + 1))
        except (OSError, ValueError, TypeError) as exc:
            broken = state.path.with_suffix(".broken.json")
            state.path.replace(broken)
            logger.error("%s could not be read (%s); kept as %s", path, exc, broken)
            return state
        for r in runs:
            state.runs[r.id] = r
            if r.state in ("running", "paused"):
                r.state = "interrupted"
                r.message = "the service ended while the run was under way"
                r.finished_s = r.finished_s or time.time()
            elif r.state == "queued":
                r.state = "interrupted"
                r.message = "the service ended before the run started"
        state.save()
        return state

    def save(self) -> None:
        with self.lock:
            data = {
                "version": _VERSION,
                "next_number": self.next_number,
                "runs": [asdict(r) for r in self.runs.values()],
            }
            write_private(self.path, json.dumps(data, indent=1))

    # ------------------------------------------------------------------ queries
    def get(self, run_id: str) -> RunRecord | None:
        with self.lock:
            return self.runs.get(run_id)

    def current(self) -> RunRecord | None:
        """The run under way (running or paused), if any."""
        with self.lock:
            for r in self.runs.values():
                if r.state in ("running", "paused"):
                    return r
            return None

    def queued(self) -> list[RunRecord]:
        with self.lock:
            return [self.runs[i] for i in self.queue]

    def interrupted(self) -> list[RunRecord]:
        with self.lock:
            return [r for r in self.runs.values() if r.state == "interrupted"]

    def paths_in_use(self) -> set[str]:
        with self.lock:
            return {r.path for r in self.runs.values()}

    # ------------------------------------------------------------------ changes
    def add(
        self, plan: Any, path: Path, label: str = "", pause_on_fault: bool = False
    ) -> RunRecord:
        """Queue a new run of ``plan`` writing ``path`` (a path from :meth:`new_id`)."""
        with self.lock:
            run_id = self.new_id()
            record = RunRecord(
                id=run_id,
                plan_name=plan.name,
                kind=plan.kind,
                n_steps=plan.n_steps,
                path=str(path),
                plan=plan.to_dict(),
                label=label,
                pause_on_fault=pause_on_fault,
            )
            self.next_number += 1
            self.runs[run_id] = record
            self.queue.append(run_id)
            self.save()
            self.changed.notify_all()
            return record

    def new_id(self) -> str:
        """The id the next :meth:`add` gives."""
        with self.lock:
            return f"r{self.next_number:04d}"

    def take_next(self, stopping: threading.Event, poll_s: float = 0.25) -> RunRecord | None:
        """Wait for a queued run and mark it running; None once ``stopping`` is set."""
        with self.changed:
            while not self.queue:
                if stopping.is_set():
                    return None
                self.changed.wait(poll_s)
            if stopping.is_set():
                return None
            record = self.runs[self.queue.pop(0)]
            record.state = "running"
            record.message = ""
            record.attempts += 1
            record.started_s = time.time()
            record.finished_s = None
            record.steps_written, record.wall_s, record.rig_time_s = 0, 0.0, 0.0
            self.save()
            return record

    def finish(
        self, record: RunRecord, state: str, message: str, n_done: int, summary: Any = None
    ) -> None:
        """Record how an attempt ended (with the figures of its
        :class:`~rig.run.session.RunSummary`, if it ran)."""
        with self.lock:
            record.state = state
            record.message = message
            record.n_done = n_done
            record.finished_s = time.time()
            record.resume = False
            if summary is not None:
                record.steps_written = int(summary.written_this_run)
                record.wall_s = float(summary.wall_s)
                record.rig_time_s = float(summary.rig_time_s)
            self.save()

    def requeue(self, record: RunRecord) -> None:
        """Queue a resumable run again; its next start continues the file."""
        with self.lock:
            if not record.resumable:
                raise ValueError(f"run {record.id} ({record.state}) cannot be resumed")
            record.state = "queued"
            record.message = ""
            record.resume = True
            self.queue.append(record.id)
            self.save()
            self.changed.notify_all()

    def cancel(self, record: RunRecord, message: str) -> None:
        """Take a queued run off the queue."""
        with self.lock:
            if record.id in self.queue:
                self.queue.remove(record.id)
            record.state = "cancelled"
            record.message = message
            record.finished_s = time.time()
            self.save()

    def interrupt_queue(self, message: str) -> list[RunRecord]:
        """Mark every queued run interrupted (the service is stopping); returns them."""
        with self.lock:
            out = [self.runs[i] for i in self.queue]
            self.queue.clear()
            for r in out:
                r.state = "interrupted"
                r.message = message
            self.save()
            return out

    def wake(self) -> None:
        """Wake a :meth:`take_next` that waits (e.g. to see that the service stops)."""
        with self.changed:
            self.changed.notify_all()
