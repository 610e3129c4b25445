"""The run commands of ``python -m rig``: run, linear, export-uff, plans.

``run`` and ``linear`` take the device lock, open the backend (``--backend sim`` passes
``--truth``, ``--seed`` and ``--realtime`` to the simulated rig), run the plan with progress on
stderr, and print a one-screen summary on stdout. Ctrl-C (or SIGTERM) stops a run cleanly:
the output ramps to 0 V, every completed step stays in the file, and ``--resume FILE`` finishes
it later. Exit status: 0 success, 1 the run ended early (aborted or failed; the file says why),
2 a usage or setup error, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from analysis.progress import ProgressReporter, format_duration, time_left
from rig.run.events import (
    Event,
    FaultRaised,
    PretestFinished,
    RecordAcquired,
    RunPaused,
    RunResumed,
    RunWarning,
    StepFinished,
)

__all__ = ["ProgressPrinter", "add_run_commands"]

EXIT_OK, EXIT_RUN_ENDED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class UsageError(ValueError):
    """The command line asks for something inconsistent (exit status 2)."""


class ProgressPrinter:
    """Prints run events to a stream: a rewritten progress line on a terminal, one line per
    step otherwise (logs, pipes); with ``json_progress``, the steps and records as
    :mod:`analysis.progress` JSON lines instead (``--json``: for a parent process such as
    ``rig workflow``, which shows them with the time left). Warnings and faults are always
    printed as text."""

    def __init__(
        self, stream: TextIO | None = None, quiet: bool = False, json_progress: bool = False
    ) -> None:
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._open_line = False
        self._first: dict[str, tuple[float, int]] = {}
        self.progress = ProgressReporter("json", self.stream) if json_progress else None

    def _left(self, key: str, done: int, total: int) -> str:
        """``", about 2 min 10 s left"`` at the pace since the first ``key`` event."""
        now = time.perf_counter()
        t0, d0 = self._first.setdefault(key, (now, done))
        left = time_left(now - t0, done - d0, total - done) if done < total else None
        return "" if left is None else f", about {format_duration(left)} left"

    def _line(self, text: str, transient: bool = False) -> None:
        if self.tty and transient:
            self.stream.write("\r" + text[:119].ljust(119))
            self._open_line = True
        else:
            if self._open_line:
                self.stream.write("\n")
                self._open_line = False
            self.stream.write(text + "\n")
        self.stream.flush()

    def __call__(self, event: Event) -> None:
        if isinstance(event, StepFinished):
            if self.quiet:
                return
            r, c = event.record, event.control
            if self.progress is not None:
                note = f"{abs(r.force[0]):.3g} N at {r.frequency_hz:.4g} Hz"
                self.progress.update("stepped-sine steps", event.n_done, event.n_steps, note)
                return
            its = c.iterations if c is not None else r.control_iterations
            flag = "ok" if r.control_converged else "NOT CONVERGED"
            n = f"{event.n_done}/{event.n_steps}" if event.n_steps else str(event.n_done)
            bar = _bar(event.n_done, event.n_steps)
            self._line(
                f"step {n} {bar} plan {r.plan_index:3d}: {abs(r.force[0]):6.3f} N at "
                f"{r.frequency_hz:8.4f} Hz, {its} it, error {r.control_error:.2%} {flag}"
                f"{self._left('steps', event.n_done, event.n_steps) if event.n_steps else ''}",
                transient=True,
            )
        elif isinstance(event, RecordAcquired):
            if self.quiet:
                return
            done, total = event.index + 1, event.n_records
            if self.progress is not None:
                self.progress.update(f"{event.purpose} records", done, total)
            else:
                left = self._left(event.purpose, done, total)
                self._line(f"record {done}/{total} ({event.purpose}){left}", transient=True)
        elif isinstance(event, PretestFinished):
            if not self.quiet:
                self._line("pretest:")
                for line in event.report.summary():
                    self._line(line)
        elif isinstance(event, RunWarning):
            self._line(f"warning: {event.message}")
        elif isinstance(event, FaultRaised):
            self._line(f"{'paused' if event.paused else 'fault'}: {event.message}")
        elif isinstance(event, RunPaused):
            self._line(f"paused: {event.reason}")
        elif isinstance(event, RunResumed):
            self._line("resumed")

    def close(self) -> None:
        if self._open_line:
            self.stream.write("\n")
            self.stream.flush()
            self._open_line = False


def _bar(done: int, total: int, width: int = 20) -> str:
    if not total:
        return ""
    k = min(width, round(width * done / total))
    return "[" + "#" * k + "." * (width - k) + "]"


# ------------------------------------------------------------------------ commands


def _backend_options(args, setup) -> dict[str, Any]:
    if args.backend != "sim":
        for flag, value in (("--truth", args.truth), ("--seed", args.seed)):
            if value is not None:
                raise UsageError(f"{flag} applies to --backend sim only")
        if args.realtime:
            raise UsageError("--realtime applies to --backend sim only")
        if getattr(args, "fault", None):
            raise UsageError("--fault applies to --backend sim only (faults of the simulated rig)")
        return {}
    options: dict[str, Any] = {"truth": args.truth or "reference"}
    if args.seed is not None:
        options["seed"] = args.seed
    if args.realtime:
        options["realtime"] = True
    options["sensor_masses_kg"] = setup.sensor_masses_kg()
    return options


def _sim_faults(args, setup) -> list:
    """The ``--fault`` arguments, parsed and checked against the setup's channels."""
    from rig.run.faults import parse_sim_fault

    faults = []
    names = [c.name for c in setup.channels]
    for text in getattr(args, "fault", None) or ():
        try:
            fault = parse_sim_fault(text)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        if fault.channel and fault.channel not in names:
            raise UsageError(
                f"--fault {text!r}: no channel {fault.channel!r} in the setup; channels: "
                + ", ".join(names)
            )
        faults.append(fault)
    return faults


def _schedule_faults(backend, bus, faults) -> None:
    """Switch each fault on in the simulated DAQ from its step of the run on."""
    from rig.run.events import StepFinished
    from rig.run.faults import switch_on

    def due(step: int) -> list:
        return [f for f in faults if f.from_step == step]

    if due(1):
        backend.set_faults(switch_on(backend.faults, due(1)))
    finished = [0]

    def on_event(event) -> None:
        if isinstance(event, StepFinished):
            finished[0] += 1
            if now := due(finished[0] + 1):
                backend.set_faults(switch_on(backend.faults, now))

    bus.subscribe(on_event)


def _run(args, kind: str) -> int:
    from rig.config.plans import load_plan
    from rig.config.setup import load_setup
    from rig.run.safety import interrupt_handlers
    from rig.run.session import RunSession, open_rig

    resume = getattr(args, "resume", None)
    plan = load_plan(args.plan) if args.plan else None
    if plan is not None and plan.kind != kind:
        other = "linear" if plan.kind == "random" else "run"
        raise UsageError(f"plan {plan.name!r} is a {plan.kind} plan; use 'rig {other}'")
    setup = load_setup(args.setup) if args.setup else None
    if resume:
        from analysis.measurement_file import read_measurement
        from rig.config.setup import setup_from_dict

        stored = read_measurement(resume)
        setup = setup or setup_from_dict(stored.setup, f"setup stored in {resume}")
        out = Path(resume)
        before = stored.config.get("run", {}) if isinstance(stored.config, dict) else {}
        if before.get("backend") == args.backend == "sim":  # the same simulated rig as before
            previous = before.get("backend_options", {})
            if args.truth is None and isinstance(previous.get("truth"), str):
                args.truth = previous["truth"]
            if args.seed is None and isinstance(previous.get("seed"), int):
                args.seed = previous["seed"]
    else:
        if plan is None:
            raise UsageError("name a plan (see 'rig plans') or give --resume FILE")
        setup = setup or load_setup(plan.setup)
        out = Path(args.out)
    options = _backend_options(args, setup)
    faults = _sim_faults(args, setup)
    if not getattr(args, "verbose", False):
        logging.getLogger("rig").setLevel(logging.ERROR)  # the progress printer shows warnings
    info = {"backend": args.backend, "backend_options": _jsonable(options), "argv": sys.argv[1:]}
    printer = ProgressPrinter(quiet=args.quiet, json_progress=args.json)
    session = RunSession()
    with open_rig(
        args.backend,
        setup,
        backend_options=options,
        lock_dir=args.lock_dir,
        amplifier_port=args.amplifier_port,
    ) as rig:
        common = {"amplifier": rig.amplifier, "run_info": info}
        if not resume:
            common["overwrite"] = args.overwrite
        run = session.prepare(
            rig.backend, plan, setup, out, resume=bool(resume), subscribers=[printer], **common
        )
        if faults:
            _schedule_faults(rig.backend, run.engine.bus, faults)
        with interrupt_handlers(session.abort):
            summary = session.execute(run)
    printer.close()
    if args.json:
        print(json.dumps(_summary_json(summary)))
    else:
        print("\n".join(summary.lines()))
    if summary.interrupted:
        return EXIT_INTERRUPTED
    return EXIT_OK if summary.status == "success" else EXIT_RUN_ENDED


def _jsonable(options: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in options.items() if k != "sensor_masses_kg"}


def _summary_json(summary) -> dict[str, Any]:
    d = {k: getattr(summary, k) for k in summary.__dataclass_fields__}
    d["path"] = str(d["path"])
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}


def cmd_run(args) -> int:
    return _run(args, "stepped-sine")


def cmd_linear(args) -> int:
    return _run(args, "random")


def cmd_export_uff(args) -> int:
    from rig.export.uff import export_uff

    n = export_uff(args.file, args.uff, overwrite=args.overwrite)
    if args.json:
        print(json.dumps({"file": str(args.uff), "sets": n}))
    else:
        print(f"{n} FRF sets written to {args.uff}")
    return EXIT_OK


def cmd_plans(args) -> int:
    from rig.config.plans import builtin_plans, describe_plan, load_plan

    if getattr(args, "plans_command", None) == "show":
        return _show_plan(args)
    rows = {}
    for name, path in sorted(builtin_plans().items()):
        plan = load_plan(name)
        rows[name] = {"kind": plan.kind, "summary": describe_plan(plan), "file": str(path)}
    if args.json:
        print(json.dumps(rows))
    else:
        for name, row in rows.items():
            print(f"{name:8s} {row['summary']}")
    return EXIT_OK


def _show_plan(args) -> int:
    """``rig plans show PLAN``: the plan's steps and the time they take, from a dry run."""
    from analysis.progress import format_duration
    from rig.config.plans import SteppedSinePlan, describe_plan, load_plan
    from rig.config.setup import load_setup
    from rig.run.dry_run import dry_run

    plan = load_plan(args.plan)
    setup = load_setup(args.setup) if args.setup else None
    run = dry_run(plan, setup)
    if args.json:
        out = run.to_json() | {"summary": describe_plan(plan)}
        if isinstance(plan, SteppedSinePlan):
            keys = ("plan_index", "level_n", "frequency_hz", "sweep_direction")
            out["steps"] = [
                {k: getattr(step, k) for k in keys} | {"seconds_at_least": t}
                for step, t in zip(plan.steps(), run.step_seconds, strict=True)
            ]
        print(json.dumps(out))
        return EXIT_OK
    print(f"{plan.name}: {describe_plan(plan)}")
    took = format_duration(run.seconds)
    if not isinstance(plan, SteppedSinePlan):
        print(f"{run.n_measurements} records of {run.iteration_s:g} s: acquisition {took}")
        return EXIT_OK
    for level in plan.levels_n:
        for sign, freqs in plan.frequencies.sweeps():
            way = "up" if sign > 0 else "down"
            print(f"  {level:g} N, {way}: {freqs.size} steps, {freqs[0]:g} .. {freqs[-1]:g} Hz")
    print(
        f"{run.n_measurements} measurements; acquisition at least {took} (force control on "
        f"target at once); each further control iteration of a step adds about "
        f"{run.iteration_s:.2g} s"
    )
    return EXIT_OK


def _add_rig_options(sp: argparse.ArgumentParser, default_out: str) -> None:
    sp.add_argument(
        "--backend", choices=("sim", "ni"), default="sim", help="DAQ backend (default sim)"
    )
    sp.add_argument("--out", default=default_out, help=f"measurement file (default {default_out})")
    sp.add_argument("--setup", help="lab setup: built-in name or TOML file (default: the plan's)")
    sp.add_argument(
        "--truth", help="simulated rig: truth structure name or file (default reference)"
    )
    sp.add_argument("--seed", type=int, help="simulated rig: noise seed")
    sp.add_argument("--realtime", action="store_true", help="simulated rig: pace to the clock")
    sp.add_argument(
        "--fault",
        action="append",
        metavar="SPEC",
        help="simulated rig: switch a fault on, [CHANNEL:]KIND[=LEVEL][@stepN] (repeatable), "
        "e.g. acc7:disconnect@step3, acc7:clip=12@step2, read-timeout@step2, "
        "amplifier-overload; kinds: disconnect, clip, read-timeout, amplifier-overload",
    )
    sp.add_argument("--amplifier-port", help="serial port of the amplifier (overrides the setup)")
    sp.add_argument("--lock-dir", help="directory of the device locks")
    sp.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    sp.add_argument("--quiet", action="store_true", help="no per-step progress")
    sp.add_argument("--json", action="store_true", help="print the summary as one JSON object")


def add_run_commands(sub) -> None:
    """Add run, linear, export-uff and plans to the ``rig`` parser's subcommands."""
    sp = sub.add_parser(
        "run",
        help="run a stepped-sine plan",
        description="Run a force-controlled stepped multi-sine plan (built-in name or TOML file) "
        "and write every step to the measurement file as it completes. Ctrl-C stops cleanly; "
        "--resume FILE completes an unfinished file.",
    )
    sp.add_argument("plan", nargs="?", help="plan name (see 'rig plans') or plan file")
    sp.add_argument("--resume", metavar="FILE", help="complete the unfinished run in FILE")
    _add_rig_options(sp, "run.h5")
    sp.set_defaults(func=cmd_run)

    sp = sub.add_parser(
        "linear",
        help="run the low-level random test (H1, coherence)",
        description="Run a random-excitation plan (default 'linear': all points, low level) and "
        "write H1 and coherence of every channel to a kind='random' measurement file.",
    )
    sp.add_argument("plan", nargs="?", default="linear", help="random plan (default linear)")
    _add_rig_options(sp, "linear.h5")
    sp.set_defaults(func=cmd_linear)

    sp = sub.add_parser(
        "export-uff",
        help="export the FRFs of a measurement file to UFF 58",
        description="Write the FRFs of a measurement file as UFF dataset 58 records: for a "
        "stepped-sine run H^nu of every channel per order, level and sweep direction; for a "
        "random run the H1 of every channel.",
    )
    sp.add_argument("file", help="measurement file (.h5)")
    sp.add_argument("uff", help="UFF file to write")
    sp.add_argument("--overwrite", action="store_true", help="replace an existing UFF file")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_export_uff)

    sp = sub.add_parser("plans", help="list the built-in plans; 'plans show PLAN': its steps")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_plans)
    show = sp.add_subparsers(dest="plans_command").add_parser(
        "show", help="a plan's steps and the time they take (a dry run on a model plant)"
    )
    show.add_argument("plan", help="built-in plan name or plan file")
    show.add_argument("--setup", help="lab setup: built-in name or TOML file (default: the plan's)")
    show.add_argument("--json", action="store_true", help="print one JSON object")
    show.set_defaults(func=cmd_plans)
