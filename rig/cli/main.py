"""Command line of the acquisition side: ``python -m rig COMMAND ...``.

Commands
--------
run         run a stepped-sine plan (``rig run paper --backend sim --out run.h5``)
linear      run the low-level random test (``rig linear --backend sim --out linear.h5``)
export-uff  export a measurement file's FRFs to UFF 58 (``rig export-uff run.h5 out.uff``)
plans       list the built-in plans
backends    list the DAQ backends and check that each can be opened here
workflow    the paper's whole workflow on a backend (simulated by default)
reference   what a simulated rig knows of its structure (the truth) as truth.json
gui         the lab GUI: acquisition window and model workbench (simulated rig by default)
amplifier   talk to the serial power amplifier (status, enable, mute, gain, clear)
service     the acquisition service that owns the rig (``rig service start|stop|status``)
submit      queue a plan on the service; list, watch, pause, resume, abort, result: its runs

Every command has ``--help``.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import sys

from rig.backends import available_backends, open_backend
from rig.backends.protocol import BackendError, reference_values
from rig.cli.run import EXIT_INTERRUPTED, EXIT_USAGE, add_run_commands
from rig.cli.separate import add_separate_command
from rig.cli.service import add_service_commands


def cmd_backends(args) -> dict:
    report = {}
    for name in available_backends():
        try:
            backend = open_backend(name, **({"device": args.device} if name == "ni" else {}))
        except BackendError as exc:
            report[name] = {"available": False, "message": str(exc)}
            continue
        backend.close()
        report[name] = {"available": True, "message": "ok"}
    if not args.json:
        for name, r in report.items():
            print(f"{name:4s} {'available' if r['available'] else 'not available'}: {r['message']}")
    return report


def cmd_reference(args) -> dict:
    """Write what the backend knows of the structure under test (a simulated rig's truth)."""
    from pathlib import Path

    options = {"truth": args.truth, "seed": args.seed} if args.backend == "sim" else {}
    backend = open_backend(args.backend, **options)
    try:
        ref = reference_values(backend)
    finally:
        backend.close()
    if ref is None:
        raise ValueError(
            f"backend {args.backend!r} knows no reference values: only a simulated rig knows "
            "the structure it simulates"
        )
    if args.out:
        out = Path(args.out)
        if out.exists() and not args.overwrite:
            raise ValueError(f"{out} exists: pass --overwrite to replace it")
        out.write_text(json.dumps(ref, indent=1) + "\n")
    if not args.json:
        print(f"{ref['source']}:")
        for name, value in ref["parameters"].items():
            print(f"  {name:12s} {value:.6g} {ref['units'].get(name, '')}")
    return ref


def cmd_amplifier(args) -> dict:
    from rig.instruments.amplifier import PowerAmplifier

    with PowerAmplifier(args.port, timeout_s=args.timeout) as amp:
        if args.action == "enable":
            amp.enable()
        elif args.action == "mute":
            amp.mute()
        elif args.action == "clear":
            amp.clear_overload()
        elif args.action == "gain":
            if args.value is None:
                raise SystemExit("amplifier gain: give the gain in V/V, e.g. 'gain 5'")
            amp.set_gain(args.value)
        ident = amp.identify()
        status = amp.status()
    result = {
        "instrument": f"{ident.manufacturer} {ident.model} (serial {ident.serial})",
        "enabled": status.enabled,
        "muted": status.muted,
        "overload": status.overload,
        "gain_v_per_v": status.gain_v_per_v,
        "current_a": status.current_a,
    }
    if not args.json:
        for k, v in result.items():
            print(f"{k:13s} {v}")
    return result


def build_parser() -> argparse.ArgumentParser:
    # The commands are listed once, by argparse from each command's help; the module
    # docstring's own table stays out of --help (it listed every command a second time).
    p = argparse.ArgumentParser(
        prog="rig",
        description="Command line of the acquisition side: rig COMMAND ...",
        epilog="Every command has --help.",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = p.add_subparsers(dest="command", required=True, title="commands", metavar="COMMAND")

    sp = sub.add_parser("backends", help="list DAQ backends and check them")
    sp.add_argument("--device", default="Dev1", help="NI device name (default Dev1)")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_backends)

    sp = sub.add_parser("amplifier", help="serial power amplifier")
    sp.add_argument("action", choices=["status", "enable", "mute", "gain", "clear"])
    sp.add_argument("value", nargs="?", type=float, help="gain in V/V (for 'gain')")
    sp.add_argument("--port", required=True, help="serial port or pyserial URL")
    sp.add_argument("--timeout", type=float, default=1.0, help="reply timeout [s]")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_amplifier)
    add_run_commands(sub)
    add_separate_command(sub)
    add_service_commands(sub)

    sp = sub.add_parser(
        "workflow",
        help="the paper's whole workflow (random test to validated model) into one folder",
        description="Random test, linear calibration, pretest planning, the stepped-sine run "
        "under force control, nonlinear calibration, cross-validation, validation and a report, "
        "each stage the command a user would type; summary.md compares with the paper.",
    )
    sp.add_argument("--out", default="demo-output", help="output folder (default demo-output)")
    sp.add_argument("--backend", choices=("sim", "ni"), default="sim")
    sp.add_argument("--truth", default="reference", help="simulated rig: truth structure")
    sp.add_argument("--seed", type=int, default=1, help="simulated rig: noise seed")
    sp.add_argument("--starts", type=int, default=100, help="Latin hypercube starts")
    sp.add_argument("--plan", default="paper", help="stepped-sine plan: name or file")
    sp.add_argument("--linear-plan", default="linear", help="random-test plan: name or file")
    sp.add_argument("--lock-dir", help="directory of the device locks")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_workflow)

    sp = sub.add_parser(
        "reference",
        help="a simulated rig's truth (parameter values, modal damping) as JSON",
        description="Ask the backend what it knows of the structure under test. A simulated "
        "rig knows its truth; write it beside the results (truth.json) to judge a calibration "
        "against it. Hardware knows nothing of the kind.",
    )
    sp.add_argument("--backend", choices=("sim", "ni"), default="sim")
    sp.add_argument("--truth", default="reference", help="simulated rig: truth structure")
    sp.add_argument("--seed", type=int, default=None, help="simulated rig: noise seed")
    sp.add_argument("--out", help="write the JSON here (e.g. truth.json)")
    sp.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_reference)
    add_gui_command(sub)
    return p


def cmd_workflow(args) -> dict:
    from rig.cli.workflow import run_workflow

    summary = run_workflow(
        args.out,
        backend=args.backend,
        truth=args.truth,
        seed=args.seed,
        starts=args.starts,
        quiet=args.json,
        plan=args.plan,
        linear_plan=args.linear_plan,
        lock_dir=args.lock_dir,
    )
    return {
        "folder": str(args.out),
        "calibration": summary["calibration"]["parameters"],
        "validation_passed": summary["validation"]["passed"],
    }


def add_gui_command(sub) -> None:
    """Add ``gui``: the GUI module is imported only when the command runs (it needs Qt)."""
    sp = sub.add_parser(
        "gui",
        help="the lab GUI: acquisition window, run browser and model workbench",
        description="Set up, run and watch stepped-sine tests (on the simulated rig in this "
        "process by default, or on the acquisition service with --service), browse "
        "measurement files, and compare, diagnose and augment a model in the workbench.",
    )
    sp.add_argument(
        "--backend", choices=("sim", "ni"), default="sim", help="DAQ backend (default sim)"
    )
    sp.add_argument("--plan", help="plan to preselect: built-in name or file (default quick)")
    sp.add_argument("--setup", help="lab setup to preselect (default: the plan's)")
    sp.add_argument("--truth", help="simulated rig: truth structure name or file")
    sp.add_argument("--seed", type=int, help="simulated rig: noise seed")
    sp.add_argument(
        "--out",
        help="measurement file of the next run (default: a new run-YYYYmmdd-HHMMSS.h5 in "
        "~/clearance-rig-runs, or in the folder CLEARANCE_RIG_RUNS names)",
    )
    sp.add_argument("--open", dest="open_file", metavar="FILE", help="show FILE in the browser")
    sp.add_argument("--model", help="model file for the workbench")
    sp.add_argument(
        "--service",
        action="store_true",
        help="run tests on the acquisition service ('rig service start') instead of here",
    )
    sp.add_argument("--service-dir", help="service directory (default as 'rig service')")
    sp.add_argument("--url", help="service address http://HOST:PORT (default from the directory)")
    sp.set_defaults(func=cmd_gui)


def cmd_gui(args) -> int:
    try:
        from rig.gui.app import run_gui
    except ImportError as exc:
        raise RuntimeError(
            f"the GUI needs PySide6 and pyqtgraph ({exc}): pip install 'clearance-rig[gui]'"
        ) from exc
    return run_gui(
        backend=args.backend,
        plan=args.plan,
        setup=args.setup,
        truth=args.truth,
        seed=args.seed,
        out=args.out,
        open_file=args.open_file,
        model=args.model,
        service=args.service or bool(args.url) or bool(args.service_dir),
        service_dir=args.service_dir,
        service_url=args.url,
    )


def file_exists_message(exc: FileExistsError) -> str:
    """An existing output file in the words of the command line: ``--overwrite`` replaces it.

    The library names its argument (``overwrite=True``); every ``rig`` command that writes a
    file offers ``--overwrite``.
    """
    from analysis.measurement_file import OutputExistsError

    if isinstance(exc, OutputExistsError):
        return exc.rephrased("--overwrite")
    # rig.run.session and rig.export.uff raise a plain FileExistsError with the library's wording
    return re.sub(r"(pass|use) (--)?overwrite(=True)?\b", "pass --overwrite", str(exc))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except FileExistsError as exc:
        print(f"error: {file_exists_message(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except (OSError, ValueError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if isinstance(result, int):
        return result
    if args.json:
        print(json.dumps(result))
    return 0
