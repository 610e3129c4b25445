"""Runs on the acquisition service: a :class:`~rig.gui.controller.RunController` over its client.

The service owns the rig (its backend, lab setup and amplifier); the GUI submits the plan,
follows the run's event stream in a worker thread and asks for pause, resume and abort
(:class:`rig.service.client.ServiceClient`). The stream's events are JSON
(:mod:`rig.service.codec`); :func:`~rig.service.codec.decode_event` turns them back into the
event classes of :mod:`rig.run.events` (complex phasors from ``[re, im]`` pairs, NaN from
``null``), so the window draws a run on the service exactly as one in this process. The
service does not stream samples, run a pretest alone or report its amplifier here: those views
say so.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from PySide6 import QtCore

from rig.gui.controller import RunController, RunEnd, RunRequest
from rig.run.events import (
    RunWarning,
)
from rig.service.client import ServiceClient, ServiceError
from rig.service.codec import decode_event

__all__ = ["ServiceRunController"]

logger = logging.getLogger(__name__)

_SUMMARY = ("path", "n_done", "n_planned", "converged_fraction", "wall_s", "rig_time_s")


class ServiceRunController(RunController):
    """Runs tests on the acquisition service.

    Parameters
    ----------
    client : ServiceClient
    """

    supports: frozenset[str] = frozenset()

    def __init__(self, client: ServiceClient, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.client = client
        self.description = f"the acquisition service at {client.url}"
        self.run_id: str | None = None
        self._thread: threading.Thread | None = None
        self._stream: Any = None
        self._lock = threading.Lock()

    @classmethod
    def connect(
        cls, service_dir: str | None = None, *, url: str | None = None
    ) -> ServiceRunController:
        """A controller for the running service (address and token as ``rig submit`` finds
        them); raises :class:`~rig.service.client.ServiceError` when none answers."""
        client = ServiceClient.connect(service_dir, url=url)
        client.status()
        return cls(client)

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, request: RunRequest) -> None:
        if self.busy:
            raise RuntimeError("a run is being followed; abort it or wait for it to end")
        self.run_id = None
        self._thread = threading.Thread(
            target=self._follow, args=(request,), name="service run", daemon=True
        )
        self._thread.start()

    # -- control: one HTTP request each, off the GUI thread ----------------------------------
    def _send(self, action: str) -> None:
        run_id = self.run_id

        def call() -> None:
            try:
                getattr(self.client, action)(run_id)
            except ServiceError as exc:
                self.event.emit(RunWarning("service", f"{action} refused by the service: {exc}"))

        if run_id is not None:
            threading.Thread(target=call, name=f"service {action}", daemon=True).start()

    def pause(self) -> None:
        self._send("pause")

    def resume(self) -> None:
        self._send("resume")

    def abort(self) -> None:
        self._send("abort")

    def clear_amplifier_overload(self) -> None:
        self.amplifier.emit("the service owns the amplifier: clear it there ('rig amplifier')")

    def shutdown(self, timeout_s: float = 10.0) -> None:
        """Stop following (the run goes on on the service)."""
        with self._lock:
            stream = self._stream
        if stream is not None:
            stream.close()
        if self._thread is not None:
            self._thread.join(timeout_s)

    # -- following a run (worker thread) ----------------------------------------------------
    def _submit(self, request: RunRequest) -> str:
        if request.pretest_only:
            raise ServiceError("the service runs pretests as part of a run only")
        if request.resume:
            for r in reversed(self.client.runs()):
                if r.get("path") and Path(r["path"]).resolve() == Path(request.path).resolve():
                    return str(self.client.resume(r["id"])["id"])
            raise ServiceError(f"the service has no run that wrote {request.path}")
        return self.client.submit(
            request.plan, out=Path(request.path).name, pause_on_fault=request.pause_on_fault
        )

    def _follow(self, request: RunRequest) -> None:
        try:
            run_id = self._submit(request)
        except (ServiceError, OSError, ValueError) as exc:
            self.ended.emit(RunEnd("failed", f"the service refused the run: {exc}", started=False))
            return
        self.run_id = run_id
        try:
            with self.client.events(run_id) as stream:
                with self._lock:
                    self._stream = stream
                for obj in stream:
                    event = decode_event(obj)
                    if event is not None:
                        self.event.emit(event)
            result = self.client.result(run_id)
        except ServiceError as exc:
            self.ended.emit(RunEnd("failed", f"lost the service's event stream: {exc}"))
            return
        finally:
            with self._lock:
                self._stream = None
        record = result.get("run", {})
        summary = result.get("summary") or {}
        lines = tuple(f"{k} {summary[k]}" for k in _SUMMARY if summary.get(k) is not None)
        path = Path(result["path"]) if result.get("exists") else None
        self.ended.emit(
            RunEnd(record.get("state", "failed"), record.get("message", ""), path, lines)
        )
