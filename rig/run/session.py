"""Running a plan end to end: device lock, backend, amplifier, measurement file, summary.

This is what the command line, the GUI and a service call::

    with open_rig("sim", setup, backend_options={"truth": "reference"}) as rig:
        run = TestRun(rig.backend, plan, setup, "run.h5", amplifier=rig.amplifier)
        run.engine.bus.subscribe(print)          # progress events
        summary = run.execute()                  # ramps to 0 V however it ends
    print("\\n".join(summary.lines()))

:func:`open_rig` takes the device lock (:mod:`rig.run.lock`) before it opens the backend and, when
the setup names a serial port, prepares the power amplifier. :class:`TestRun` creates the
measurement file (or reopens it to resume: :meth:`TestRun.resume`), runs the plan's procedure on
a :class:`~rig.run.engine.RunEngine`, and records how the run ended in the file.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from analysis.measurement_file import (
    SteppedSineData,
    create_stepped_sine,
    note_output_not_at_zero,
    open_for_resume,
    read_measurement,
    write_random,
)
from rig.backends import open_backend
from rig.config.plans import Plan, RandomPlan, SteppedSinePlan, plan_from_dict
from rig.config.setup import LabSetup, setup_from_dict
from rig.procedures.random_test import random_procedure
from rig.procedures.stepped_sine import stepped_sine_procedure
from rig.run.engine import Procedure, RunEngine, RunOutcome
from rig.run.events import EventBus, RunStarted
from rig.run.lock import DeviceLock, user_lock_dir
from rig.run.safety import deferred_interrupts

__all__ = [
    "Rig",
    "RunSession",
    "RunSummary",
    "TestRun",
    "lock_name",
    "open_rig",
    "previous_rig",
    "summarize",
]

logger = logging.getLogger(__name__)


# ------------------------------------------------------------------------ the rig


@dataclass
class Rig:
    """An opened rig: backend, amplifier (or None) and the name of the lock held."""

    backend: Any
    amplifier: Any
    lock_name: str


def lock_name(backend: str, setup: LabSetup) -> str:
    """Name of the device lock: the DAQ device, prefixed for a simulated one."""
    device = setup.daq.device
    return device if backend == "ni" else f"{backend}-{device}"


@contextmanager
def open_rig(
    backend: str,
    setup: LabSetup,
    *,
    backend_options: Mapping[str, Any] | None = None,
    lock_dir: str | PathLike[str] | None = None,
    amplifier_port: str | None = None,
) -> Iterator[Rig]:
    """Lock the device, open the backend and prepare the amplifier; undo all on exit.

    Parameters
    ----------
    backend : {"ni", "sim"}
    setup : LabSetup
    backend_options : mapping, optional
        Passed to the backend (``truth``, ``seed``, ``realtime``, ... for ``sim``); ``ni`` gets
        the setup's device unless given.
    lock_dir : path, optional
        Directory of the device locks (default: the machine-wide one of :mod:`rig.run.lock` for a
        real device, the per-user one for a simulated device).
    amplifier_port : str, optional
        Serial port of the amplifier (default the setup's; "" for none).

    Raises
    ------
    DeviceBusyError
        If another process owns the device.
    BackendError
        If the backend cannot be opened (for ``ni`` without its driver the message points to
        ``--backend sim``).
    """
    name = lock_name(backend, setup)
    if lock_dir is None and backend != "ni":
        lock_dir = user_lock_dir()  # a simulated device is one per process, not per machine
    with DeviceLock(name, lock_dir):
        options = dict(backend_options or {})
        if backend == "ni":
            options.setdefault("device", setup.daq.device)
        daq = open_backend(backend, **options)
        amp = None
        try:
            port = setup.amplifier.port if amplifier_port is None else amplifier_port
            if port:
                amp = _prepare_amplifier(port, setup)
            yield Rig(daq, amp, name)
        finally:
            with deferred_interrupts():
                if amp is not None:
                    try:
                        amp.mute()
                    except Exception:
                        logger.exception("muting the amplifier failed")
                    amp.close()
                daq.close()


def previous_rig(run_config: Any) -> tuple[str | None, dict[str, Any]]:
    """The backend a measurement file was made on and, for the simulated rig, its truth and seed.

    A follow-up test (the measurement that separates a diagnosis's tie) must run on the rig the
    first run was made on: on the simulated rig that is its truth structure and noise seed,
    which the file's ``config`` records in its ``run`` table (``backend``, ``backend_options``)
    whether the command line or the GUI made it.

    Parameters
    ----------
    run_config : dict
        The file's ``config`` (:attr:`analysis.measurement_file.RunData.config`).

    Returns
    -------
    backend : str or None
        ``"sim"``, ``"ni"``, ... or None when the file does not say.
    options : dict
        ``truth`` (str) and ``seed`` (int), those the file records, for ``"sim"``; empty
        otherwise.
    """
    before = run_config.get("run", {}) if isinstance(run_config, Mapping) else {}
    before = before if isinstance(before, Mapping) else {}
    backend = before.get("backend")
    backend = backend if isinstance(backend, str) and backend else None
    previous = before.get("backend_options", {})
    if backend != "sim" or not isinstance(previous, Mapping):
        return backend, {}
    options: dict[str, Any] = {}
    if isinstance(previous.get("truth"), str):
        options["truth"] = previous["truth"]
    seed = previous.get("seed")
    if isinstance(seed, int) and not isinstance(seed, bool):
        options["seed"] = seed
    return backend, options


def _prepare_amplifier(port: str, setup: LabSetup):
    from rig.instruments.amplifier import PowerAmplifier

    amp = PowerAmplifier(port, timeout_s=setup.amplifier.timeout_s)
    try:
        ident = amp.identify()
        status = amp.status()
        if status.overload:
            raise RuntimeError(
                f"the amplifier at {port} ({ident.model}) has its overload latch set; find the "
                f"cause, then clear it: rig amplifier clear --port {port}"
            )
        if setup.amplifier.gain_v_per_v > 0:
            amp.set_gain(setup.amplifier.gain_v_per_v)
        amp.enable()
        logger.info("amplifier %s %s at %s enabled", ident.manufacturer, ident.model, port)
    except BaseException:
        amp.close()
        raise
    return amp


# ------------------------------------------------------------------------ summary


@dataclass(frozen=True)
class RunSummary:
    """A run in figures (what the command line prints at the end).

    Attributes
    ----------
    path : Path
    kind, plan_name, status, message : str
    n_planned : int
        Steps in the plan (records for a random test).
    n_done : int
        Steps on disk (0 or 1 for a random test: the FRF set).
    written_this_run : int
    converged_fraction : float
        Share of steps on disk whose force control converged (NaN for random tests).
    median_iterations, max_control_error : float
    wall_s, rig_time_s : float
        Wall-clock and DAQ-clock duration of this run [s].
    fault_kind : str
    interrupted : bool
    output_at_zero : bool
        Whether the final ramp of the output to 0 V completed (false: the output may still be
        driven; ``message`` names the error).
    """

    path: Path
    kind: str
    plan_name: str
    status: str
    message: str
    n_planned: int
    n_done: int
    written_this_run: int
    converged_fraction: float
    median_iterations: float
    max_control_error: float
    wall_s: float
    rig_time_s: float
    fault_kind: str = ""
    interrupted: bool = False
    output_at_zero: bool = True

    def lines(self) -> list[str]:
        """A one-screen summary."""
        out = [f"run       {self.plan_name} ({self.kind}): {self.status}"]
        if self.message:
            out.append(f"ended     {self.message}")
        if not self.output_at_zero:
            out.append("OUTPUT    the ramp to 0 V failed: the output may not be at 0 V")
        out.append(f"file      {self.path}")
        if self.kind == "stepped-sine":
            out.append(
                f"steps     {self.n_done} of {self.n_planned} on disk "
                f"({self.written_this_run} in this run)"
            )
            if self.n_done:
                n_conv = round(self.converged_fraction * self.n_done)
                out.append(
                    f"control   converged {n_conv}/{self.n_done} ({self.converged_fraction:.1%}), "
                    f"median {self.median_iterations:g} iterations, max error "
                    f"{self.max_control_error:.2%}"
                )
        else:
            out.append(f"records   {self.n_planned} planned; FRF set written: {self.n_done == 1}")
        speed = self.rig_time_s / self.wall_s if self.wall_s > 0 else math.nan
        out.append(
            f"time      wall {self.wall_s:.1f} s, rig {self.rig_time_s:.1f} s "
            f"({speed:.1f}x real time)"
        )
        if (
            self.status != "success"
            and self.kind == "stepped-sine"
            and self.n_done < self.n_planned
        ):
            out.append(f"resume    python -m rig run --resume {self.path} --backend ...")
        return out


def summarize(
    path: str | PathLike[str],
    outcome: RunOutcome | None = None,
    plan_name: str = "",
    n_planned: int = 0,
) -> RunSummary:
    """Figures of a run from its file (and the engine's outcome when at hand)."""
    path = Path(path)
    data = read_measurement(path) if path.exists() else None
    status = outcome.status if outcome else (data.exit_status if data else "failed")
    message = outcome.message if outcome else (data.exit_message if data else "")
    conv = iters = err = math.nan
    n_done = 0
    kind = "random"
    if isinstance(data, SteppedSineData):
        kind = "stepped-sine"
        n_done = data.n_steps
        plan_name = plan_name or str(data.config.get("plan", {}).get("name", ""))
        if n_done:
            conv = float(np.mean(data.control_converged))
            iters = float(np.median(data.control_iterations))
            err = float(np.max(data.control_error))
    elif data is not None:
        n_done = 1
    return RunSummary(
        path=path,
        kind=kind,
        plan_name=plan_name,
        status=status,
        message=message,
        n_planned=n_planned,
        n_done=n_done,
        written_this_run=outcome.steps_written if outcome else 0,
        converged_fraction=conv,
        median_iterations=iters,
        max_control_error=err,
        wall_s=outcome.wall_s if outcome else 0.0,
        rig_time_s=outcome.rig_time_s if outcome else 0.0,
        fault_kind=outcome.fault_kind if outcome else "",
        interrupted=outcome.interrupted if outcome else False,
        output_at_zero=outcome.output_at_zero if outcome else True,
    )


# ------------------------------------------------------------------------ a run


class _FileSink:
    """The engine's sink for a stepped-sine file."""

    def __init__(self, writer, n_planned: int) -> None:
        self.writer = writer
        self.n_planned = n_planned

    @property
    def n_complete(self) -> int:
        return self.writer.n_complete

    def append_step(self, record) -> None:
        self.writer.append_step(record)

    def append_raw(self, plan_index: int, samples, fs_hz: float, t0_s: float) -> None:
        self.writer.append_raw(plan_index, samples, fs_hz, t0_s)


class _RandomSink:
    """The engine's sink for a random test: writes the file when the FRFs arrive."""

    def __init__(self, run: TestRun) -> None:
        self.run = run
        self.n_planned = run.plan.n_steps
        self.n_complete = 0

    def append_step(self, record) -> None:
        raise RuntimeError("a random test writes no stepped-sine steps")

    def write_random(self, frf) -> None:
        r = self.run
        write_random(
            r.path,
            channels=[c.channel_info() for c in r.channels],
            actuator=r.setup.actuator,
            frf=frf,
            config=r.config,
            setup=r.setup.to_dict(),
            overwrite=r.overwrite,
        )
        self.n_complete = 1


class TestRun:
    """One run of a plan on an opened backend, with its measurement file.

    Parameters
    ----------
    backend : DaqBackend
        Opened backend (from :func:`open_rig`); not closed here.
    plan : SteppedSinePlan or RandomPlan
    setup : LabSetup
    path : path
        The measurement file to create.
    bus : EventBus, optional
        Where progress events go (also :attr:`engine` ``.bus``).
    amplifier : PowerAmplifier, optional
    pause_on_fault : bool
        Pause on recoverable faults instead of ending (for a GUI that can resume).
    initial_gain : ndarray, optional
        Drive-to-force gain for the first step (see
        :func:`rig.procedures.stepped_sine.stepped_sine_procedure`).
    overwrite : bool
        Replace an existing file.
    run_info : mapping, optional
        Stored with the plan in the file's ``config_json`` (backend name and options, ...).
    procedure_wrapper : callable(procedure) -> procedure, optional
        Wraps the plan's procedure (e.g. plan code that adds commands of its own); whatever it
        raises ends the run as failed, with the output ramped down and the steps kept.

    Attributes
    ----------
    engine : RunEngine
        Pause, resume and abort it from another thread.
    """

    __test__ = False  # not a pytest test class

    def __init__(
        self,
        backend,
        plan: Plan,
        setup: LabSetup,
        path: str | PathLike[str],
        *,
        bus: EventBus | None = None,
        amplifier=None,
        pause_on_fault: bool = False,
        initial_gain: np.ndarray | None = None,
        overwrite: bool = False,
        run_info: Mapping[str, Any] | None = None,
        procedure_wrapper: Callable[[Procedure], Procedure] | None = None,
        _resume: SteppedSineData | None = None,
    ) -> None:
        self.plan = plan
        self.setup = setup
        self.path = Path(path)
        self.overwrite = overwrite
        self.initial_gain = initial_gain
        self.channels = setup.channels_for_points(plan.points)
        self.config = {"plan": plan.to_dict(), "run": dict(run_info or {})}
        self.resuming = _resume is not None
        self._stored = _resume
        self.procedure_wrapper = procedure_wrapper
        self.engine = RunEngine(
            backend,
            setup,
            self.channels,
            plan.limits,
            sample_rate_hz=plan.sample_rate_hz or None,
            bus=bus,
            amplifier=amplifier,
            pause_on_fault=pause_on_fault,
        )

    @classmethod
    def resume(
        cls,
        backend,
        path: str | PathLike[str],
        *,
        plan: Plan | None = None,
        setup: LabSetup | None = None,
        **kwargs: Any,
    ) -> TestRun:
        """A run that completes an unfinished stepped-sine file.

        The plan and the setup are read from the file (``config_json``, ``setup_json``); a plan
        given explicitly must equal the file's. Steps on disk are skipped.

        Raises
        ------
        ValueError
            If the file is not an unfinished stepped-sine run, or the plan or the channels do
            not match it.
        """
        data = read_measurement(path)
        if not isinstance(data, SteppedSineData):
            raise ValueError(f"{path}: only a stepped-sine run can be resumed (this is random)")
        if data.complete:
            raise ValueError(f"{path}: the run is complete ({data.n_steps} steps); nothing to do")
        stored = plan_from_dict(data.config["plan"], f"plan stored in {path}")
        if plan is not None and plan.to_dict() != stored.to_dict():
            raise ValueError(
                f"{path} was written by plan {stored.name!r} with other settings than the plan "
                "given; resume without naming a plan to use the stored one"
            )
        setup = setup or setup_from_dict(data.setup, f"setup stored in {path}")
        run = cls(backend, stored, setup, path, _resume=data, **kwargs)
        names = tuple(c.name for c in run.channels)
        if names != data.channel_names:
            raise ValueError(
                f"{path}: the file has channels {list(data.channel_names)}, the setup gives "
                f"{list(names)}"
            )
        return run

    def execute(self) -> RunSummary:
        """Run the plan; the output is at 0 V and the file records the end when it returns."""
        if isinstance(self.plan, SteppedSinePlan):
            outcome = self._execute_stepped()
        elif isinstance(self.plan, RandomPlan):
            outcome = self._execute_random()
        else:  # pragma: no cover - plans are one of the two
            raise TypeError(f"unknown plan type {type(self.plan).__name__}")
        return summarize(self.path, outcome, self.plan.name, self.plan.n_steps)

    def _started(self, n_done: int) -> None:
        self.engine.publish(
            RunStarted(self.plan.name, self.plan.kind, self.plan.n_steps, n_done, str(self.path))
        )

    def _execute_stepped(self) -> RunOutcome:
        plan: SteppedSinePlan = self.plan  # type: ignore[assignment]
        if self.resuming:
            writer = open_for_resume(self.path)
        else:
            orders = plan.excitation.orders
            writer = create_stepped_sine(
                self.path,
                channels=[c.channel_info() for c in self.channels],
                actuator=self.setup.actuator,
                levels_n=list(plan.levels_n),
                orders_num=[o.numerator for o in orders],
                orders_den=[o.denominator for o in orders],
                force_targets=plan.force_targets(),
                config=self.config,
                setup=self.setup.to_dict(),
                raw=plan.acquisition.store_raw,
                overwrite=self.overwrite,
                extra_orders_num=[o.numerator for o in plan.extra_orders],
                extra_orders_den=[o.denominator for o in plan.extra_orders],
            )
        completed = writer.completed_plan_indices
        recorded = {}
        if self._stored is not None:
            d = self._stored
            recorded = {
                int(p): (d.drive[i], d.force[i])
                for i, p in enumerate(d.plan_index)
                if int(p) in completed
            }
        self._started(len(completed))
        try:
            procedure = stepped_sine_procedure(plan, completed, self.initial_gain, recorded)
            if self.procedure_wrapper is not None:
                procedure = self.procedure_wrapper(procedure)
            outcome = self.engine.run(procedure, _FileSink(writer, plan.n_steps))
        except BaseException as exc:
            with deferred_interrupts():
                writer.finish("failed", f"{type(exc).__name__}: {exc}")
            raise
        with deferred_interrupts():
            writer.finish(outcome.status, outcome.message, outcome.output_at_zero)
        return outcome

    def _execute_random(self) -> RunOutcome:
        if self.path.exists() and not self.overwrite:
            raise FileExistsError(f"{self.path}: file exists (pass overwrite to replace it)")
        self._started(0)
        procedure = random_procedure(self.plan)
        if self.procedure_wrapper is not None:
            procedure = self.procedure_wrapper(procedure)
        outcome = self.engine.run(procedure, _RandomSink(self))
        if not outcome.output_at_zero and self.path.exists():
            with deferred_interrupts():
                note_output_not_at_zero(self.path, outcome.message)
        return outcome


# ------------------------------------------------------------------------ one run, as started


class RunSession:
    """One run as every front end starts it: the command line, the GUI and the service.

    A session is made before its engine exists (the rig may still be opening, the file being
    read for a resume), so a pause or an abort asked for meanwhile is held and given to the
    engine the moment it exists; afterwards they go to it directly. :meth:`pause`,
    :meth:`resume` and :meth:`abort` may be called from any thread.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._engine: RunEngine | None = None
        self._pending_pause = False
        self._pending_abort = ""

    @property
    def engine(self) -> RunEngine | None:
        """The engine of the run under way; None before it starts and after it ends."""
        with self._lock:
            return self._engine

    def pause(self) -> None:
        """Pause at the next safe point (held until the engine exists)."""
        with self._lock:
            if self._engine is None:
                self._pending_pause = True
            else:
                self._engine.pause()

    def resume(self) -> None:
        """Continue a paused run (or take back a pause not yet given)."""
        with self._lock:
            self._pending_pause = False
            if self._engine is not None:
                self._engine.resume()

    def abort(self, reason: str = "aborted by the operator") -> None:
        """End the run: output ramped to 0 V, steps kept (held until the engine exists)."""
        with self._lock:
            if self._engine is None:
                self._pending_abort = self._pending_abort or reason
            else:
                self._engine.abort(reason)

    def prepare(
        self,
        backend,
        plan: Plan | None,
        setup: LabSetup | None,
        path: str | PathLike[str],
        *,
        resume: bool = False,
        subscribers: Sequence[Callable] = (),
        **options: Any,
    ) -> TestRun:
        """The :class:`TestRun` of this session: ``resume`` continues the file at ``path`` (its
        stored plan and setup unless given), otherwise a new file; ``options`` as
        :class:`TestRun`'s. The subscribers get every event of its engine, and what was asked
        of the session so far is given to the engine."""
        if resume:
            run = TestRun.resume(backend, path, plan=plan, setup=setup, **options)
        else:
            if plan is None or setup is None:
                raise ValueError("a new run needs a plan and a setup")
            run = TestRun(backend, plan, setup, path, **options)
        self.attach(run.engine, subscribers)
        return run

    def attach(self, engine: RunEngine, subscribers: Sequence[Callable] = ()) -> None:
        """Make ``engine`` the session's (for a procedure run without a :class:`TestRun`)."""
        for subscriber in subscribers:
            engine.bus.subscribe(subscriber)
        with self._lock:
            self._engine = engine
            if self._pending_pause:
                engine.pause()
            if self._pending_abort:
                engine.abort(self._pending_abort)

    def detach(self) -> None:
        """The run is over: later requests are held for the next one."""
        with self._lock:
            self._engine = None
            self._pending_pause, self._pending_abort = False, ""

    def execute(self, run: TestRun) -> RunSummary:
        """Run ``run`` (from :meth:`prepare`) to its end; the session is free again after."""
        try:
            return run.execute()
        finally:
            self.detach()
