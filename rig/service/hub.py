"""Each run's event log, and the streams that follow it.

Events reach the hub from the engine's thread (:meth:`EventHub.publish_threadsafe` only hands
them to the event loop, so the run never waits for a client). On the loop each event gets the
run's next ``seq`` (1, 2, ... without gaps), is encoded once (:mod:`rig.service.codec`),
appended to the run's log in memory and to ``events/<run>.ndjson``, and wakes the streams of
that run. A stream is a reader of the log with its own position: a slow or stalled client only
falls behind (nothing is dropped, nobody else waits), one that disconnects just stops reading,
and one that connects late, or reconnects with ``since``, gets everything after that ``seq``.

A run's log is *final* once the service's ``RunState`` event with a final state is in it;
streams then end after the last line. Resuming the run appends to the same log.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
from pathlib import Path
from typing import Any, BinaryIO

from rig.run.events import Event, RunPaused, RunResumed, RunStarted, StepFinished
from rig.service.codec import encode_event, event_line
from rig.service.state import FINAL_STATES, RunState, ServiceState

__all__ = ["EventHub", "RunLog"]

logger = logging.getLogger(__name__)

_CACHE_FINISHED = 16  # logs of ended runs kept in memory


class RunLog:
    """The encoded events of one run, in ``seq`` order (``lines[seq - 1]``)."""

    def __init__(self, run_id: str, path: Path) -> None:
        self.run_id = run_id
        self.path = path
        self.lines: list[bytes] = []
        self.final = False
        self._changed = asyncio.Event()
        self._fh: BinaryIO | None = None
        if path.exists():
            with open(path, "rb") as fh:
                self.lines = [line for line in fh if line.endswith(b"\n")]
            if self.lines:
                self.final = _is_final(json.loads(self.lines[-1]))

    @property
    def last_seq(self) -> int:
        return len(self.lines)

    def append(self, obj: dict[str, Any]) -> None:
        line = event_line(obj)
        self.lines.append(line)
        if obj.get("type") == "RunState":
            self.final = _is_final(obj)
        if self._fh is None:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
            self._fh = os.fdopen(fd, "ab")
        self._fh.write(line)
        self._fh.flush()
        self.wake()

    def wake(self) -> None:
        event, self._changed = self._changed, asyncio.Event()
        event.set()

    async def wait(self, timeout_s: float) -> bool:
        """Wait for a new line (or a wake-up); False after ``timeout_s`` with none."""
        event = self._changed
        try:
            await asyncio.wait_for(event.wait(), timeout_s)
        except TimeoutError:
            return False
        return True

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _is_final(obj: dict[str, Any]) -> bool:
    return obj.get("type") == "RunState" and obj.get("data", {}).get("state") in FINAL_STATES


class EventHub:
    """The event logs of the service's runs.

    Parameters
    ----------
    events_dir : Path
        Where the logs are kept (``<run>.ndjson``).
    state : ServiceState
        Updated from the events (steps done, paused, events count).
    loop : asyncio.AbstractEventLoop
        The service's event loop (every method but :meth:`publish_threadsafe` runs on it).
    """

    def __init__(
        self, events_dir: Path, state: ServiceState, loop: asyncio.AbstractEventLoop
    ) -> None:
        self.events_dir = Path(events_dir)
        self.state = state
        self.loop = loop
        self.closing = False
        self._logs: dict[str, RunLog] = {}

    def log(self, run_id: str) -> RunLog:
        """The log of a run (read from disk the first time)."""
        log = self._logs.get(run_id)
        if log is None:
            log = RunLog(run_id, self.events_dir / f"{run_id}.ndjson")
            self._logs[run_id] = log
            self._evict()
        return log

    def _evict(self) -> None:
        ended = [k for k, v in self._logs.items() if v.final]
        for k in ended[: max(0, len(ended) - _CACHE_FINISHED)]:
            self._logs.pop(k).close()

    def publish_threadsafe(self, run_id: str, event: Event) -> None:
        """Hand an event to the loop (from any thread; returns at once)."""
        try:
            self.loop.call_soon_threadsafe(self.publish, run_id, event)
        except RuntimeError:  # the loop has closed: the service is gone
            logger.warning("event %s of run %s after the service closed", event, run_id)

    def publish(self, run_id: str, event: Event) -> None:
        """Number, encode, store and announce an event (on the loop)."""
        log = self.log(run_id)
        seq = log.last_seq + 1
        try:
            obj = encode_event(event, run_id, seq)
            log.append(obj)
        except Exception:
            logger.exception("event %s of run %s could not be stored", type(event).__name__, run_id)
            return
        self._observe(run_id, event, seq)

    def _observe(self, run_id: str, event: Event, seq: int) -> None:
        with self.state.lock:
            record = self.state.get(run_id)
            if record is None:
                return
            record.events = seq
            if isinstance(event, StepFinished):
                record.n_done = int(event.n_done)
            elif isinstance(event, RunStarted):
                record.n_done = int(event.n_done)
            elif isinstance(event, RunPaused) and record.state == "running":
                record.state = "paused"
                record.message = event.reason
            elif isinstance(event, RunResumed) and record.state == "paused":
                record.state = "running"
                record.message = ""
            elif isinstance(event, RunState) and record.state in FINAL_STATES:
                self.state.save()  # the event count of an ended run is kept

    def close(self) -> None:
        """The service stops: wake every stream so that it ends, close the files."""
        self.closing = True
        for log in self._logs.values():
            log.wake()
            log.close()
