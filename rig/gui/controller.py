"""Who runs the test: the :class:`RunController` interface and its in-process implementation.

The acquisition window talks to a :class:`RunController` only: it hands over a
:class:`RunRequest` (plan, setup, backend, file), receives the run's events
(:mod:`rig.run.events`) on the GUI thread through the :attr:`RunController.event` signal, and asks
for pause, resume and abort. :class:`LocalRunController` runs the engine in a worker thread of
this process (:func:`rig.run.session.open_rig` and :class:`rig.run.session.TestRun`, exactly what
the
command line runs); a controller backed by the acquisition service implements the same
interface over its client.

Events are published in the engine's thread; the controller re-emits them through a Qt signal,
which Qt queues to the GUI thread, so a subscriber never blocks the engine and the GUI never
blocks on the run. The latest samples read (for the time-trace plots) are kept by a tap on the
backend (:class:`SampleTap`) that the GUI polls on its redraw timer.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PySide6 import QtCore

from rig.config.plans import Plan
from rig.config.setup import LabSetup
from rig.gui.sample_tap import SampleTap, TappedBackend, TimeTraces
from rig.procedures.pretest import pretest_procedure
from rig.run.engine import RunEngine
from rig.run.events import Event
from rig.run.session import RunSession

__all__ = [
    "LocalRunController",
    "RunController",
    "RunEnd",
    "RunRequest",
]

logger = logging.getLogger(__name__)

#: What a controller can do besides start/pause/resume/abort (see :attr:`RunController.supports`).
CAPABILITIES = ("pretest", "time-traces", "amplifier")


@dataclass(frozen=True)
class RunRequest:
    """A run to start.

    Attributes
    ----------
    plan : SteppedSinePlan or RandomPlan
    setup : LabSetup
    path : Path
        Measurement file to write (or to complete, with ``resume``).
    backend : {"sim", "ni"}
    backend_options : mapping
        Passed to the backend (``truth``, ``seed``, ``realtime`` for ``sim``).
    overwrite : bool
        Replace an existing file.
    resume : bool
        Complete the unfinished run in ``path`` (plan and setup from the file).
    pause_on_fault : bool
        Pause on recoverable faults (clipping, a silent sensor, no force, an amplifier
        overload) so the operator can fix the cause and resume.
    pretest_only : bool
        Run only the pretest (noise floor, loop check, channel checks); no file is written.
    lock_dir : str, optional
        Directory of the device locks.
    """

    plan: Plan
    setup: LabSetup
    path: Path
    backend: str = "sim"
    backend_options: Mapping[str, Any] = field(default_factory=dict)
    overwrite: bool = False
    resume: bool = False
    pause_on_fault: bool = True
    pretest_only: bool = False
    lock_dir: str | None = None


@dataclass(frozen=True)
class RunEnd:
    """How a run (or a pretest) ended.

    Attributes
    ----------
    status : str
        ``"success"``, ``"aborted"`` or ``"failed"`` (the file's ``exit_status``).
    message : str
    path : Path or None
        The measurement file (None for a pretest or a run that could not start).
    lines : list of str
        The one-screen summary (:meth:`rig.run.session.RunSummary.lines`).
    started : bool
        False when the run could not start (setup error, device busy, no backend).
    """

    status: str
    message: str
    path: Path | None = None
    lines: tuple[str, ...] = ()
    started: bool = True


class RunController(QtCore.QObject):
    """What the acquisition window needs from whoever runs a test.

    Signals (all delivered on the GUI thread)
    -----------------------------------------
    event(object)
        Every :class:`rig.run.events.Event` of the run, in order.
    ended(object)
        A :class:`RunEnd` when the run (or pretest) is over, however it ended.
    amplifier(object)
        The power amplifier's :class:`~rig.instruments.amplifier.AmplifierStatus`, or a
        sentence when it cannot be read or is not remote controlled.

    Attributes
    ----------
    supports : frozenset of str
        Optional abilities: ``"pretest"`` (a pretest alone), ``"time-traces"``
        (:meth:`time_traces`), ``"amplifier"`` (status polling, clearing an overload).
    """

    event = QtCore.Signal(object)
    ended = QtCore.Signal(object)
    amplifier = QtCore.Signal(object)

    supports: frozenset[str] = frozenset()
    description = "run controller"

    def start(self, request: RunRequest) -> None:
        """Start a run (or a pretest) in the background; returns at once."""
        raise NotImplementedError

    @property
    def busy(self) -> bool:
        """A run is being set up or under way."""
        raise NotImplementedError

    def pause(self) -> None:
        raise NotImplementedError

    def resume(self) -> None:
        raise NotImplementedError

    def abort(self) -> None:
        """End the run: the output ramps to 0 V, the file keeps every completed step."""
        raise NotImplementedError

    def time_traces(self) -> TimeTraces | None:
        """The newest samples of every channel (None if unknown)."""
        return None

    def clear_amplifier_overload(self) -> None:
        """Clear the amplifier's overload latch and enable it (the operator found the cause)."""
        raise NotImplementedError

    def shutdown(self, timeout_s: float = 10.0) -> None:
        """Abort a run under way and wait for it to end (closing the window)."""


class _Worker(QtCore.QThread):
    """Runs one request: rig, run (or pretest), summary."""

    def __init__(self, owner: LocalRunController, request: RunRequest) -> None:
        super().__init__()
        self.owner = owner
        self.request = request

    def run(self) -> None:  # noqa: D401 - QThread entry point
        end = self.owner._run(self.request)
        self.owner._finished(end)


class LocalRunController(RunController):
    """Runs tests in this process: the engine in a worker thread.

    Parameters
    ----------
    extra_backend_options : mapping, optional
        Added to every request's backend options (e.g. a simulated amplifier shared with a
        serial front panel in a demonstration).
    amplifier_poll_s : float
        Interval of the amplifier's status polling while a run is under way [s].
    lock_dir : path, optional
        Directory of the device locks for requests that name none.
    """

    supports = frozenset(CAPABILITIES)
    description = "this computer"

    def __init__(
        self,
        parent: QtCore.QObject | None = None,
        *,
        extra_backend_options: Mapping[str, Any] | None = None,
        amplifier_poll_s: float = 1.0,
        lock_dir: str | None = None,
    ) -> None:
        super().__init__(parent)
        self.lock_dir = lock_dir
        self.extra_backend_options = dict(extra_backend_options or {})
        self.amplifier_poll_s = float(amplifier_poll_s)
        self.tap = SampleTap()
        self._worker: _Worker | None = None
        self._session = RunSession()
        self._amp = None
        self._stop_poll = threading.Event()

    # -- control (GUI thread) -------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self._worker is not None and self._worker.isRunning()

    def start(self, request: RunRequest) -> None:
        if self.busy:
            raise RuntimeError("a run is under way; abort it or wait for it to end")
        self._session = RunSession()
        self.tap = SampleTap()
        self._worker = _Worker(self, request)
        self._worker.start()

    def pause(self) -> None:
        self._session.pause()

    def resume(self) -> None:
        self._session.resume()

    def abort(self) -> None:
        self._session.abort()

    def time_traces(self) -> TimeTraces | None:
        return self.tap.snapshot()

    def clear_amplifier_overload(self) -> None:
        amp = self._amp
        if amp is None:
            self.amplifier.emit("the amplifier is not remote controlled (no serial port)")
            return

        def clear() -> None:
            try:
                amp.clear_overload()
                amp.enable()
                self.amplifier.emit(amp.status())
            except Exception as exc:  # a serial problem: say it, do not crash the GUI
                self.amplifier.emit(f"clearing the overload failed: {exc}")

        threading.Thread(target=clear, name="amplifier clear", daemon=True).start()

    def shutdown(self, timeout_s: float = 10.0) -> None:
        if self.busy:
            self.abort()
            self._worker.wait(int(timeout_s * 1000))

    # -- the run (worker thread) -----------------------------------------------------------
    def _run(self, request: RunRequest) -> RunEnd:
        from rig.run.session import open_rig

        options = {**dict(request.backend_options), **self.extra_backend_options}
        if request.backend == "sim":
            options.setdefault("sensor_masses_kg", request.setup.sensor_masses_kg())
        info = {
            "backend": request.backend,
            "backend_options": {
                k: v for k, v in options.items() if isinstance(v, str | int | float | bool)
            },
            "client": "rig gui",
        }
        try:
            with open_rig(
                request.backend,
                request.setup,
                backend_options=options,
                lock_dir=request.lock_dir or self.lock_dir,
            ) as rig:
                backend = TappedBackend(rig.backend, self.tap)
                self._amp = rig.amplifier
                if rig.amplifier is None:
                    self.amplifier.emit(
                        "not remote controlled: the setup names no serial port for the amplifier"
                    )
                session = self._session
                if request.pretest_only:
                    engine = RunEngine(
                        backend,
                        request.setup,
                        request.setup.channels_for_points(request.plan.points),
                        request.plan.limits,
                        sample_rate_hz=request.plan.sample_rate_hz or None,
                        amplifier=rig.amplifier,
                    )
                    session.attach(engine, [self._publish])
                    run = None
                else:
                    options = {"overwrite": request.overwrite} if not request.resume else {}
                    run = session.prepare(
                        backend,
                        None if request.resume else request.plan,
                        request.setup,
                        request.path,
                        resume=request.resume,
                        subscribers=[self._publish],
                        amplifier=rig.amplifier,
                        pause_on_fault=request.pause_on_fault,
                        run_info=info,
                        **options,
                    )
                poller = self._start_polling(rig.amplifier)
                try:
                    if run is None:
                        outcome = engine.run(pretest_procedure(request.plan))
                        return RunEnd(outcome.status, outcome.message)
                    summary = session.execute(run)
                finally:
                    self._stop_polling(poller, rig.amplifier)
                return RunEnd(summary.status, summary.message, summary.path, tuple(summary.lines()))
        except Exception as exc:  # setup errors, a busy device, no backend: say so
            logger.warning("the run could not start or failed: %s", exc)
            return RunEnd("failed", f"{type(exc).__name__}: {exc}", started=False)
        finally:
            self._session.detach()
            self._amp = None

    def _publish(self, event: Event) -> None:
        self.event.emit(event)

    def _finished(self, end: RunEnd) -> None:
        self.ended.emit(end)

    def _start_polling(self, amp) -> threading.Thread | None:
        if amp is None:
            return None
        self._stop_poll.clear()

        def poll() -> None:
            while True:
                try:
                    self.amplifier.emit(amp.status())
                except Exception as exc:  # a serial hiccup: say it, keep polling
                    self.amplifier.emit(f"cannot read the amplifier's status: {exc}")
                if self._stop_poll.wait(self.amplifier_poll_s):
                    return

        thread = threading.Thread(target=poll, name="amplifier status", daemon=True)
        thread.start()
        return thread

    def _stop_polling(self, thread: threading.Thread | None, amp) -> None:
        if thread is None:
            return
        self._stop_poll.set()
        thread.join(self.amplifier_poll_s + 2.0)
        try:
            self.amplifier.emit(amp.status())  # after the engine muted it
        except Exception as exc:
            self.amplifier.emit(f"cannot read the amplifier's status: {exc}")
