"""``python -m analysis plan``: pretest planning by the Fisher information matrix.

``add_parser(subparsers)`` adds the command to the analysis command line; the command returns
a JSON-friendly dict (printed by the caller with ``--json``) and prints the report otherwise.
``python -m analysis.planning.cli`` runs it on its own.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys

from analysis.executors import open_executor
from analysis.logs import add_debug_option, configure_logging, summarise_repeats
from analysis.model import load_model
from analysis.planning.candidates import (
    Candidates,
    Configuration,
    NoiseModel,
    paper_candidates,
    quick_candidates,
)
from analysis.planning.plan import PAPER_LINEAR, PlanSettings, plan_tests

__all__ = ["add_parser", "cmd_plan", "main"]

log = logging.getLogger(__name__)

_HELP = """Rank every candidate test configuration (actuator, sensors, force levels, frequency
range) by det(FIM) of the multi-harmonic FRFs it would measure, print the best ones as the
paper's Table 4, FIM^-1 of the chosen one and its parameter correlation indices (1 Hz steps
and refined). Default: the reference rig with the paper's calibrated linear values (Table 2)
and nominal nonlinear values, the paper's 14 700 candidates (Table 3)."""


def _values(items: list[str] | None) -> dict[str, float]:
    values = {}
    for item in items or []:
        name, _, val = item.partition("=")
        try:
            values[name.strip()] = float(val)
        except ValueError:
            raise ValueError(f"--set {item!r}: expected NAME=NUMBER") from None
    return values


def _ints(text: str, what: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise ValueError(f"{what} {text!r}: expected integers separated by commas") from None


def _choice(text: str, cand: Candidates) -> Configuration:
    """``ACTUATOR:SENSORS:LEVELS:RANGE``, e.g. ``3:3,6,7:2,4,6:21-40``."""
    parts = text.split(":")
    if len(parts) != 4:
        raise ValueError(f"--choose {text!r}: expected ACTUATOR:SENSORS:LEVELS:RANGE")
    try:
        levels = tuple(float(v) for v in parts[2].split(","))
        lo, hi = (float(v) for v in parts[3].split("-"))
    except ValueError:
        raise ValueError(
            f"--choose {text!r}: levels and range are numbers (2,4,6 and 21-40)"
        ) from None
    ranges = [r for r in cand.ranges if (r.start_hz, r.stop_hz) == (lo, hi)]
    if not ranges:
        raise ValueError(f"--choose {text!r}: no candidate range {lo:g}-{hi:g} Hz")
    return Configuration(
        actuator=int(parts[0]),
        sensors=_ints(parts[1], "--choose sensors"),
        levels_n=levels,
        frequency_range=ranges[0],
    )


def cmd_plan(args: argparse.Namespace) -> dict:
    """Run the plan of the parsed arguments; print the report unless ``--json``."""
    model = load_model(args.model)
    values = {} if args.model else dict(PAPER_LINEAR)
    values.update(_values(args.set))
    if values:
        model = model.with_values(values)
    params = tuple(p.strip() for p in args.params.split(",") if p.strip())
    cand = quick_candidates(params) if args.quick else paper_candidates(params)
    noise = NoiseModel(relative=args.noise_relative, floor=args.noise_floor)
    settings = PlanSettings(top=args.top, refine_band_hz=None if args.no_refine else (24.0, 28.0))
    chosen = _choice(args.choose, cand) if args.choose else None
    with summarise_repeats("plan"), open_executor(args.workers, args.scheduler) as executor:
        result = plan_tests(model, cand, noise, settings, executor=executor, chosen=chosen)
    if not args.json:
        print(result.format_table())
    return result.to_dict()


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``plan`` command to an ``argparse`` subparsers object; returns its parser."""
    sp = subparsers.add_parser(
        "plan",
        help="pretest planning: rank test configurations by det(FIM)",
        description=_HELP,
    )
    sp.add_argument(
        "--model", help="model file (default: the reference rig with Table 2's linear values)"
    )
    sp.add_argument(
        "--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)"
    )
    sp.add_argument("--params", default="k_c,gap,v_c", help="parameters to plan for")
    sp.add_argument("--top", type=int, default=5, help="configurations to list")
    sp.add_argument("--workers", type=int, default=None, help="local worker processes (1: serial)")
    sp.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask scheduler address (a trusted lab cluster only: Dask moves pickles)",
    )
    sp.add_argument(
        "--noise-relative", type=float, default=0.02, help="relative phasor noise (0.02: 2 %%)"
    )
    sp.add_argument(
        "--noise-floor", type=float, default=0.01, help="noise floor per component [m/s^2]"
    )
    sp.add_argument(
        "--choose",
        metavar="A:S:L:R",
        help="study this configuration, e.g. 3:3,6,7:2,4,6:21-40 (default: the best)",
    )
    sp.add_argument("--no-refine", action="store_true", help="skip the refined-step study")
    sp.add_argument(
        "--quick", action="store_true", help="levels 2/4/6 N choose 2, first and last range"
    )
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_plan)
    return sp


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry: ``python -m analysis.planning.cli plan ...``."""
    parser = argparse.ArgumentParser(prog="python -m analysis.planning.cli")
    add_debug_option(parser)
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    configure_logging(args)
    try:
        result = args.func(args)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
