"""The thread that owns the rig: device lock, backend, amplifier, and the runs, one at a time.

:class:`RigOwner` opens the rig once (:func:`rig.run.session.open_rig`: the device lock first) and
keeps it for the life of the service. It takes runs from the queue (:class:`ServiceState`) in
order and runs each as the headless ``rig run`` does (:class:`rig.run.session.TestRun`, or
:meth:`~rig.run.session.TestRun.resume` for a run that continues its file), passing every event of
the run's engine to the service's event hub. Pause, resume and abort reach the run's
:class:`~rig.run.engine.RunEngine` from any thread; a request that arrives before the engine
exists is applied as soon as it does.

Stopping (:meth:`RigOwner.stop`) aborts the run under way through its engine (the output ramps
to 0 V, every completed step stays in the file), records it and every queued run as
``interrupted``, and closes the rig.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rig.run.events import Event
from rig.run.session import RunSession
from rig.service.state import RunRecord, RunState, ServiceState

__all__ = ["RigOptions", "RigOwner"]

logger = logging.getLogger(__name__)

STOP_REASON = "the acquisition service was stopped"


@dataclass(frozen=True)
class RigOptions:
    """What the service opens.

    Attributes
    ----------
    backend : {"sim", "ni"}
    setup : rig.config.setup.LabSetup
        The bench; every run uses it.
    backend_options : mapping
        Passed to the backend (``truth``, ``seed``, ``realtime`` for ``sim``).
    lock_dir : path or None
        Directory of the device locks.
    amplifier_port : str or None
        Serial port of the amplifier (default the setup's; "" for none).
    """

    backend: str
    setup: Any
    backend_options: Mapping[str, Any] = field(default_factory=dict)
    lock_dir: Path | None = None
    amplifier_port: str | None = None


class RigOwner(threading.Thread):
    """Owns the rig and runs the queue (a thread of the service process).

    Parameters
    ----------
    options : RigOptions
    state : ServiceState
    publish : callable(run_id, event)
        Receives every event of every run (called in this thread: must return quickly).
    run_info : mapping
        Stored in each measurement file's ``config_json`` (backend and its options).
    on_exit : callable(), optional
        Called from this thread when it ends other than by :meth:`stop` (the rig failed):
        the service then stops too.
    """

    def __init__(
        self,
        options: RigOptions,
        state: ServiceState,
        publish: Callable[[str, Event], None],
        run_info: Mapping[str, Any],
        on_exit: Callable[[], None] | None = None,
    ) -> None:
        super().__init__(name="rig-owner", daemon=True)
        self.on_exit = on_exit
        self.options = options
        self.state = state
        self.publish = publish
        self.run_info = dict(run_info)
        self.ready = threading.Event()
        self.error: BaseException | None = None
        self._stopping = threading.Event()
        self._lock = threading.Lock()  # guards _current and _session
        self._current: RunRecord | None = None
        self._session = RunSession()

    # ------------------------------------------------------------------ control (any thread)
    @property
    def stopping(self) -> bool:
        return self._stopping.is_set()

    def stop(self) -> None:
        """End the run under way (ramped down, recorded interrupted) and close the rig."""
        self._stopping.set()
        self.abort(STOP_REASON)
        self.state.wake()

    def is_current(self, run_id: str) -> bool:
        with self._lock:
            return self._current is not None and self._current.id == run_id

    def pause(self, run_id: str) -> bool:
        """Pause the run if it is the one under way; False otherwise."""
        with self._lock:
            if self._current is None or self._current.id != run_id:
                return False
            self._session.pause()
            return True

    def resume(self, run_id: str) -> bool:
        """Continue the run if it is the one under way (and paused); False otherwise."""
        with self._lock:
            if self._current is None or self._current.id != run_id:
                return False
            self._session.resume()
            return True

    def abort(self, reason: str, run_id: str | None = None) -> bool:
        """Abort the run under way (only if it is ``run_id``, when given)."""
        with self._lock:
            if self._current is None or (run_id is not None and self._current.id != run_id):
                return False
            self._session.abort(reason)
            return True

    # ------------------------------------------------------------------ the thread
    def run(self) -> None:
        from rig.run.session import open_rig

        o = self.options
        try:
            with open_rig(
                o.backend,
                o.setup,
                backend_options=o.backend_options,
                lock_dir=o.lock_dir,
                amplifier_port=o.amplifier_port,
            ) as rig:
                logger.info("rig opened: %s backend, device lock %r", o.backend, rig.lock_name)
                self.ready.set()
                while True:
                    record = self.state.take_next(self._stopping)
                    if record is None:
                        break
                    self._execute(rig, record)
        except BaseException as exc:  # reported by the service's main thread
            self.error = exc
            if not self.ready.is_set():
                logger.debug("opening the rig failed", exc_info=True)
            else:
                logger.exception("the rig owner failed")
        finally:
            left = self.state.interrupt_queue("the service stopped before the run started")
            for r in left:
                self.publish(r.id, RunState(r.state, r.message, r.n_done, r.n_steps))
            was_ready = self.ready.is_set()
            self.ready.set()
            logger.info("rig closed")
            if was_ready and not self.stopping and self.on_exit is not None:
                self.on_exit()

    def _execute(self, rig, record: RunRecord) -> None:
        from rig.config.plans import plan_from_dict

        with self._lock:
            self._current = record
            session = self._session = RunSession()
            if self._stopping.is_set():  # stopped between taking the run and getting here
                session.abort(STOP_REASON)
        self.publish(record.id, RunState("running", "", record.n_done, record.n_steps))
        logger.info("run %s (%s) started, attempt %d", record.id, record.plan_name, record.attempts)
        state, message, n_done, summary = "failed", "", record.n_done, None
        try:
            plan = plan_from_dict(record.plan, f"plan of run {record.id}")
            path = Path(record.path)
            common = {
                "amplifier": rig.amplifier,
                "run_info": {**self.run_info, "service_run": record.id},
                "pause_on_fault": record.pause_on_fault,
            }
            # a run taken up again after the service stopped continues its file; one that had
            # not written it yet (or a random test) starts it again
            resume = record.resume and path.exists() and plan.kind == "stepped-sine"
            if not resume:
                common["overwrite"] = record.resume
            run = session.prepare(
                rig.backend,
                plan,
                self.options.setup,
                path,
                resume=resume,
                subscribers=[lambda event: self.publish(record.id, event)],
                **common,
            )
            summary = session.execute(run)
            state, message, n_done = summary.status, summary.message, summary.n_done
        except Exception as exc:
            message = f"{type(exc).__name__}: {exc}"
            logger.error("run %s failed to run: %s", record.id, message)
        finally:
            with self._lock:
                session.detach()
                self._current = None
        if self.stopping and state != "success":
            state = "interrupted"
        self.state.finish(record, state, message, n_done, summary)
        self.publish(record.id, RunState(state, message, n_done, record.n_steps))
        logger.info("run %s ended: %s%s", record.id, state, f" ({message})" if message else "")
