"""Runs on the acquisition service: a :class:`~rig.gui.controller.RunController` over its client.

The service owns the rig (its backend, lab setup and amplifier); the GUI submits the plan,
follows the run's event stream in a worker thread and asks for pause, resume and abort
(:class:`rig.service.client.ServiceClient`). The stream's events are JSON
(:mod:`rig.service.codec`); :func:`decode_event` turns them back into the event classes of
:mod:`rig.events` (complex phasors from ``[re, im]`` pairs, NaN from ``null``), so the window
draws a run on the service exactly as one in this process. The service does not stream
samples, run a pretest alone or report its amplifier here: those views say so.
"""

from __future__ import annotations

import logging
import math
import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from PySide6 import QtCore

from rig.events import (
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
from rig.gui.controller import RunController, RunEnd, RunRequest
from rig.plans import PlannedStep
from rig.pretest import ChannelCheck, PretestReport
from rig.service.client import ServiceClient, ServiceError

__all__ = ["ServiceRunController", "decode_event"]

logger = logging.getLogger(__name__)

_COMPLEX = ("force", "response", "drive", "drive_v", "force_n", "gain_n_per_v")
_REAL = ("force_std", "response_std", "force_std_n")
_SUMMARY = ("path", "n_done", "n_planned", "converged_fraction", "wall_s", "rig_time_s")


def _number(x: Any) -> float:
    return math.nan if x is None else float(x)


def _complex(x: Any) -> np.ndarray:
    """Nested lists ending in ``[re, im]`` pairs -> complex array (``null`` -> NaN)."""
    a = np.array(x, dtype=float)
    return a[..., 0] + 1j * a[..., 1]


def _fields(d: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        if k in _COMPLEX and v is not None:
            out[k] = _complex(v)
        elif k in _REAL and v is not None:
            out[k] = np.array(v, dtype=float)
        else:
            out[k] = v
    return out


def _pretest(d: dict[str, Any]) -> PretestReport:
    channels = tuple(
        ChannelCheck(
            c["name"],
            int(c["point"]),
            c["status"],
            _number(c["noise_rms"]),
            _number(c["response"]),
            _number(c["snr"]),
            c.get("message", ""),
        )
        for c in d.get("channels", [])
    )
    gain = d.get("gain_n_per_v")
    return PretestReport(
        _number(d.get("frequency_hz")),
        channels,
        _complex(d["drive_v"]) if d.get("drive_v") else np.zeros(0, complex),
        _complex(d["force_n"]) if d.get("force_n") else np.zeros(0, complex),
        None if gain is None else _complex(gain),
    )


def decode_event(obj: dict[str, Any]) -> Event | None:
    """The :mod:`rig.events` object of one event of the stream (None for the service's own
    ``RunState`` and for types this GUI does not draw)."""
    kind, d = obj.get("type"), obj.get("data", {})
    t = {"time_s": _number(obj.get("time_s"))}
    if kind == "RunStarted":
        return RunStarted(d["plan_name"], d["kind"], d["n_steps"], d["n_done"], d["path"], **t)
    if kind == "PretestFinished":
        return PretestFinished(_pretest(d["report"]), **t)
    if kind == "StepStarted":
        return StepStarted(PlannedStep(**d["step"]), d["n_steps"], **t)
    if kind == "ControlIteration":
        f = _fields(d)
        return ControlIteration(
            f["plan_index"],
            f["iteration"],
            f["status"],
            f["accepted"],
            _number(f["error"]),
            _number(f["frequency_hz"]),
            f["drive_v"],
            f["force_n"],
            f["force_std_n"],
            **t,
        )
    if kind == "StepFinished":
        record = SimpleNamespace(**_fields(d["record"]))
        record.control_error = _number(record.control_error)
        names = tuple(d["channel_names"])
        return StepFinished(record, None, names, d["n_done"], d["n_steps"], d["settled"], **t)
    if kind == "RecordAcquired":
        return RecordAcquired(d["index"], d["n_records"], d["purpose"], **t)
    if kind == "RunWarning":
        return RunWarning(d["kind"], d["message"], d.get("channel", ""), **t)
    if kind == "FaultRaised":
        return FaultRaised(
            d["kind"], d["message"], d.get("channel", ""), bool(d.get("paused")), **t
        )
    if kind == "RunPaused":
        return RunPaused(d.get("reason", ""), **t)
    if kind == "RunResumed":
        return RunResumed(**t)
    if kind == "RunFinished":
        return RunFinished(d["status"], d.get("message", ""), **t)
    return None


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
        self._stream = None
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
