"""The acquisition service's commands of ``python -m rig``.

``rig service start|stop|status`` runs and controls the service (one process that owns the
rig); ``rig submit PLAN``, ``rig list``, ``rig watch [RUN]``, ``rig pause|resume|abort [RUN]``
and ``rig result RUN`` are its clients, for people and for headless scripts. A client finds
the service through the service directory (``--service-dir`` or ``$RIG_SERVICE_DIR``; the
address can be given with ``--url`` or ``$RIG_SERVICE_URL``, the token with
``$RIG_SERVICE_TOKEN``).

Exit status: 0 success; 1 the run watched ended other than successfully; 2 a usage error or
a refused request; 3 no service is running.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any, TextIO

from rig.service.client import (
    ServiceClient,
    ServiceError,
    ServiceUnavailable,
)
from rig.service.directory import DEFAULT_HOST, DEFAULT_PORT, ServiceDir

__all__ = ["EventPrinter", "add_service_commands"]

EXIT_OK, EXIT_RUN_ENDED, EXIT_USAGE, EXIT_NOT_RUNNING = 0, 1, 2, 3


def _client(args) -> ServiceClient:
    return ServiceClient.connect(args.service_dir, url=args.url)


def _err(message: str) -> None:
    print(f"error: {message}", file=sys.stderr)


def _guarded(func):
    """Run a client command; a service error becomes a message and an exit status."""

    def wrapper(args) -> int:
        try:
            return func(args)
        except ServiceUnavailable as exc:
            _err(str(exc))
            return EXIT_NOT_RUNNING
        except ServiceError as exc:
            _err(str(exc))
            return EXIT_USAGE

    wrapper.__name__ = func.__name__
    wrapper.__doc__ = func.__doc__
    return wrapper


# ------------------------------------------------------------------------ printing


def _run_line(r: dict[str, Any]) -> str:
    label = f" [{r['label']}]" if r.get("label") else ""
    steps = f"{r['n_done']}/{r['n_steps']}" if r["kind"] == "stepped-sine" else f"{r['n_steps']}r"
    msg = f"  {r['message']}" if r.get("message") else ""
    resumable = " (resumable)" if r.get("resumable") else ""
    return f"{r['id']}  {r['state']:11s} {r['plan']:12s} {steps:>9s}{label}{resumable}{msg}"


def _pair_abs(z: Any) -> float:
    return float(abs(complex(z[0] or 0.0, z[1] or 0.0))) if z else float("nan")


class EventPrinter:
    """Human-readable lines for the event stream's objects (what ``rig watch`` prints)."""

    def __init__(self, stream: TextIO | None = None, iterations: bool = False) -> None:
        self.stream = stream or sys.stdout
        self.iterations = iterations

    def _line(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()

    def __call__(self, event: dict[str, Any]) -> None:
        kind, d, run = event.get("type"), event.get("data", {}), event.get("run", "")
        if kind == "RunState":
            msg = f": {d['message']}" if d.get("message") else ""
            self._line(f"run {run} {d['state']} ({d['n_done']}/{d['n_steps']} steps){msg}")
        elif kind == "RunStarted":
            self._line(
                f"run {run}: plan {d['plan_name']} ({d['kind']}), {d['n_steps']} steps, "
                f"{d['n_done']} on disk, file {d['path']}"
            )
        elif kind == "StepFinished":
            r = d["record"]
            flag = "ok" if r["control_converged"] else "NOT CONVERGED"
            error = r["control_error"] if r["control_error"] is not None else float("nan")
            self._line(
                f"step {d['n_done']}/{d['n_steps']} plan {r['plan_index']:3d}: "
                f"{_pair_abs(r['force'][0]):6.3f} N at {r['frequency_hz']:8.4f} Hz, "
                f"{r['control_iterations']} it, error {error:.2%} {flag}"
            )
        elif kind == "ControlIteration" and self.iterations:
            self._line(
                f"  iteration {d['iteration']} of plan step {d['plan_index']}: {d['status']}, "
                f"error {(d['error'] or 0.0):.2%}"
            )
        elif kind == "RecordAcquired":
            self._line(f"record {d['index'] + 1}/{d['n_records']} ({d['purpose']})")
        elif kind == "PretestFinished":
            for c in d["report"].get("channels", []):
                self._line(f"pretest  {c['name']:8s} {c['status']}")
        elif kind == "RunWarning":
            self._line(f"warning: {d['message']}")
        elif kind == "FaultRaised":
            self._line(f"{'paused' if d.get('paused') else 'fault'}: {d['message']}")
        elif kind == "RunPaused":
            self._line(f"paused: {d['reason']}")
        elif kind == "RunResumed":
            self._line("resumed")
        elif kind == "RunFinished":
            msg = f": {d['message']}" if d.get("message") else ""
            self._line(f"finished {d['status']}{msg}")


# ------------------------------------------------------------------------ service start/stop


def _service_options(args):
    from pathlib import Path

    from rig.service.server import ServiceOptions

    if args.backend != "sim" and (args.truth or args.seed is not None or args.realtime):
        raise ValueError("--truth, --seed and --realtime apply to --backend sim only")
    backend_options: dict[str, Any] = {}
    if args.backend == "sim":
        backend_options["truth"] = args.truth or "reference"
        if args.seed is not None:
            backend_options["seed"] = args.seed
        if args.realtime:
            backend_options["realtime"] = True
    return ServiceOptions(
        backend=args.backend,
        setup=args.setup,
        backend_options=backend_options,
        host=args.host,
        port=args.port,
        service_dir=Path(args.service_dir) if args.service_dir else None,
        results_dir=Path(args.results_dir) if args.results_dir else None,
        lock_dir=Path(args.lock_dir) if args.lock_dir else None,
        amplifier_port=args.amplifier_port,
    )


def _start_detached(args) -> int:
    from rig.service.launch import start_service

    try:
        info = start_service(
            args.service_dir,
            timeout_s=args.start_timeout,
            backend=args.backend,
            setup=args.setup,
            host=args.host,
            port=args.port,
            truth=args.truth,
            seed=args.seed,
            realtime=args.realtime,
            results_dir=args.results_dir,
            lock_dir=args.lock_dir,
            amplifier_port=args.amplifier_port,
            verbose=args.verbose,
        )
    except RuntimeError as exc:
        _err(str(exc))
        return EXIT_USAGE
    log = ServiceDir(args.service_dir).log_path
    print(
        f"rig service started: process {info['pid']}, http://{info['host']}:{info['port']}, "
        f"log {log}"
    )
    return EXIT_OK


def cmd_service_start(args) -> int:
    import logging

    if args.detach:
        return _start_detached(args)
    from rig.service.server import serve

    if not args.verbose:  # a run's warnings and faults go to its event stream
        logging.getLogger("rig").setLevel(logging.ERROR)
    logging.getLogger("rig.service").setLevel(logging.INFO)  # runs queued, started, ended
    return serve(_service_options(args))


@_guarded
def cmd_service_stop(args) -> int:
    client = _client(args)
    status = client.status()
    current = status.get("current")
    client.stop_service()
    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline:
        try:
            client.status()
        except ServiceUnavailable:
            break
        except ServiceError:
            pass
        time.sleep(0.1)
    else:
        _err(f"the service still answers {args.timeout:g} s after the stop request")
        return EXIT_USAGE
    result = {"stopped": True, "pid": status["service"]["pid"], "interrupted": None}
    if current is not None:
        result["interrupted"] = current["id"]
        result["output_at_zero"], said = _output_state(current.get("path"))
    if args.json:
        print(json.dumps(result))
    else:
        print(f"rig service stopped (process {result['pid']})")
        if current is not None:
            print(
                f"run {current['id']} ({current['plan']}) was under way: "
                f"{said}; its completed steps are kept; after "
                f"the next start, 'rig resume {current['id']}' completes it"
            )
    return EXIT_OK


def _output_state(path: str | None) -> tuple[bool | None, str]:
    """What the interrupted run's file says of the output: ramped to 0 V, not, or unknown
    (None: the engine records it as it stops; a file that cannot be read says nothing)."""
    try:
        import h5py

        with h5py.File(path, "r") as f:
            at_zero = f.attrs.get("output_at_zero")
    except (OSError, TypeError, ValueError):
        at_zero = None
    if at_zero is None:
        return None, "the run was ended; its file does not say whether the output reached 0 V"
    if bool(at_zero):
        return True, "the output was ramped to 0 V (its file records it)"
    return False, (
        "ramping the output to 0 V FAILED (its file records it): the output may not be at 0 V"
    )


def cmd_service_status(args) -> int:
    try:
        status = _client(args).status()
    except ServiceUnavailable as exc:
        if args.json:
            print(json.dumps({"running": False, "message": str(exc)}))
        else:
            print(f"not running: {exc}")
        return EXIT_NOT_RUNNING
    except ServiceError as exc:
        _err(str(exc))
        return EXIT_USAGE
    if args.json:
        print(json.dumps({"running": True, **status}))
        return EXIT_OK
    s = status["service"]
    print(
        f"rig service {s['state']} at http://{s['host']}:{s['port']} (process {s['pid']}), "
        f"{s['backend']} backend, setup {s['setup']}"
    )
    print(f"results   {s['results_dir']}")
    cur = status["current"]
    print("current   " + (_run_line(cur) if cur else "none"))
    print(f"queued    {' '.join(status['queued']) or 'none'}")
    if status["interrupted"]:
        print(f"interrupted {' '.join(status['interrupted'])} (rig resume RUN completes one)")
    return EXIT_OK


# ------------------------------------------------------------------------ clients


def _watch(client: ServiceClient, run_id: str | None, args) -> int:
    printer = None if args.json else EventPrinter(iterations=getattr(args, "iterations", False))
    with client.events(run_id, since=getattr(args, "since", 0)) as stream:
        for event in stream:
            if printer is None:
                print(json.dumps(event), flush=True)
            else:
                printer(event)
        end = stream.end or {}
    state = end.get("state", "")
    if end.get("reason") == "service stopped" and printer is not None:
        print("the service stopped")
    return EXIT_OK if state == "success" else EXIT_RUN_ENDED


@_guarded
def cmd_submit(args) -> int:
    client = _client(args)
    run_id = client.submit(
        args.plan, out=args.out, label=args.label or "", pause_on_fault=args.pause_on_fault
    )
    record = client.run(run_id)
    if args.json and not args.watch:
        print(json.dumps(record))
    elif not args.json:
        print(
            f"run {run_id} {record['state']}: {record['plan']}, {record['n_steps']} steps, "
            f"file {record['path']}"
        )
    if args.watch:
        return _watch(client, run_id, args)
    return EXIT_OK


@_guarded
def cmd_list(args) -> int:
    runs = _client(args).runs()
    if args.json:
        print(json.dumps(runs))
    elif not runs:
        print("no runs")
    else:
        for r in runs:
            print(_run_line(r))
    return EXIT_OK


@_guarded
def cmd_watch(args) -> int:
    return _watch(_client(args), args.run, args)


def _control(action: str):
    @_guarded
    def command(args) -> int:
        client = _client(args)
        if action == "abort":
            record = client.abort(args.run, reason=args.reason or "")
        else:
            record = getattr(client, action)(args.run)
        if args.json:
            print(json.dumps(record))
        else:
            print(f"{action}: run {record['id']} is {record['state']}")
        return EXIT_OK

    command.__name__ = f"cmd_{action}"
    return command


@_guarded
def cmd_result(args) -> int:
    result = _client(args).result(args.run)
    if args.json:
        print(json.dumps(result))
        return EXIT_OK
    print(_run_line(result["run"]))
    print(f"file      {result['path']}" + ("" if result["exists"] else " (not written)"))
    s = result.get("summary")
    if s and "error" not in s:
        print(f"status    {s['status']}; {s['n_done']} of {s['n_planned']} steps on disk")
        if s.get("message"):
            print(f"ended     {s['message']}")
    return EXIT_OK


# ------------------------------------------------------------------------ parser


def _client_options(sp: argparse.ArgumentParser) -> None:
    sp.add_argument(
        "--service-dir",
        help="service directory (default $RIG_SERVICE_DIR or ~/.local/state/clearance-rig/service)",
    )
    sp.add_argument("--url", help="service address http://HOST:PORT (default from the directory)")
    sp.add_argument("--json", action="store_true", help="print JSON")


def _add_service_subcommands(ssub) -> None:
    """``service start``, ``service stop`` and ``service status``."""
    st = ssub.add_parser("start", help="start the service")
    st.add_argument("--backend", choices=("sim", "ni"), default="sim", help="DAQ backend")
    st.add_argument("--setup", default="reference", help="lab setup: built-in name or TOML file")
    st.add_argument("--truth", help="simulated rig: truth structure name or file")
    st.add_argument("--seed", type=int, help="simulated rig: noise seed")
    st.add_argument("--realtime", action="store_true", help="simulated rig: pace to the clock")
    st.add_argument("--host", default=DEFAULT_HOST, help=f"address to listen on ({DEFAULT_HOST})")
    st.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"port ({DEFAULT_PORT}; 0 picks a free one)"
    )
    st.add_argument("--service-dir", help="service directory (token, state, results)")
    st.add_argument("--results-dir", help="folder of the measurement files")
    st.add_argument("--lock-dir", help="directory of the device locks")
    st.add_argument("--amplifier-port", help="serial port of the amplifier (overrides the setup)")
    st.add_argument(
        "--detach", action="store_true", help="run in the background (log in the service directory)"
    )
    st.add_argument("--start-timeout", type=float, default=60.0, help=argparse.SUPPRESS)
    st.set_defaults(func=cmd_service_start, json=False)
    so = ssub.add_parser("stop", help="stop the service (the run under way ramps down)")
    _client_options(so)
    so.add_argument("--timeout", type=float, default=120.0, help="wait at most this long [s]")
    so.set_defaults(func=cmd_service_stop)
    ss = ssub.add_parser("status", help="is it running, what runs, what is queued")
    _client_options(ss)
    ss.set_defaults(func=cmd_service_status)


def add_service_commands(sub) -> None:
    """Add ``service``, ``submit``, ``list``, ``watch``, ``pause``, ``resume``, ``abort`` and
    ``result`` to the ``rig`` parser's subcommands."""
    sp = sub.add_parser(
        "service",
        help="the acquisition service: one process owns the rig (start, stop, status)",
        description="Start, stop or query the acquisition service: a process that owns the rig "
        "(device lock, backend, amplifier), runs queued plans one at a time and serves an "
        "HTTP API on the loopback address (docs/service-api.md). 'start' stays in the "
        "foreground unless --detach; SIGTERM or Ctrl-C stop it cleanly.",
    )
    _add_service_subcommands(sp.add_subparsers(dest="service_command", required=True))

    sp = sub.add_parser("submit", help="queue a plan on the acquisition service")
    sp.add_argument("plan", help="built-in plan name or plan file")
    sp.add_argument("--out", help="file name in the service's results folder")
    sp.add_argument("--label", help="free text shown in 'rig list'")
    sp.add_argument(
        "--pause-on-fault",
        action="store_true",
        help="pause on recoverable faults instead of ending the run",
    )
    sp.add_argument("--watch", action="store_true", help="then follow it like 'rig watch'")
    _client_options(sp)
    sp.set_defaults(func=cmd_submit, since=0, iterations=False)

    sp = sub.add_parser("list", help="runs known to the acquisition service")
    _client_options(sp)
    sp.set_defaults(func=cmd_list)

    sp = sub.add_parser("watch", help="follow a run's events (default the current run)")
    sp.add_argument("run", nargs="?", help="run id (default the current run)")
    sp.add_argument("--since", type=int, default=0, help="last event number already seen")
    sp.add_argument("--iterations", action="store_true", help="show force-control iterations")
    _client_options(sp)
    sp.set_defaults(func=cmd_watch)

    for action, text in (
        ("pause", "pause the current run (the output ramps to 0 V)"),
        ("resume", "continue a paused run, or queue an interrupted one again"),
        ("abort", "end a run (ramped down, steps kept) or cancel a queued one"),
    ):
        sp = sub.add_parser(action, help=text)
        sp.add_argument("run", nargs="?", help="run id (default the current run)")
        if action == "abort":
            sp.add_argument("--reason", help="recorded in the file's exit message")
        _client_options(sp)
        sp.set_defaults(func=_control(action))

    sp = sub.add_parser("result", help="where a run's file is and what it holds")
    sp.add_argument("run", help="run id")
    _client_options(sp)
    sp.set_defaults(func=cmd_result)
