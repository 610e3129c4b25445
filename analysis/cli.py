"""Command line of the analysis side: ``python -m analysis COMMAND ...``.

Commands
--------
modes            natural frequencies of a model and the beam's share of each mode
sweep            stepped multi-harmonic FRFs by MHB (the paper's frequency plan by default)
continuation     a frequency-response curve of any model through its folds (located)
export-matrices  write M and K of a model (npz, mtx or mat) with its DOF map
calibrate-linear linear calibration of a random run (damping equalization)
plan             pretest planning: rank test configurations by det(FIM)
calibrate        nonlinear calibration of a stepped-sine run (LHS + Levenberg-Marquardt)
crossval         k-fold cross-validation of a calibration
validate         prediction of a held-out level with uncertainty bands, pass/fail
report           one report (HTML + Markdown) from a calibration folder
compare          residual blocks and maps of a model against a stepped-sine run
diagnose         which physical effect the model misses (evidence, candidates, ranking)
augment          add the chosen effect, recalibrate, show the error falling
demo             the analysis part of the paper on the published model (figures + summary)
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

from analysis.logs import (
    add_debug_option,
    configure_logging,
    note_inputs,
    parse_assignments,
    summarise_repeats,
)
from analysis.mhb.continuation import continue_branch
from analysis.mhb.sweep import solve_steps
from analysis.model import load_model
from analysis.paper import PAPER_CALIBRATED, paper_frequencies_hz
from analysis.system import build_linear, build_problem

log = logging.getLogger("analysis")


def _model(args):
    model = load_model(args.model)
    values = parse_assignments(args.set)
    if getattr(args, "paper", False):
        values = {**PAPER_CALIBRATED, **values}
    return model.with_values(values) if values else model


def _levels(text: str) -> list[float]:
    try:
        levels = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise SystemExit(f"--levels {text!r}: expected numbers separated by commas") from None
    if not levels or min(levels) <= 0:
        raise SystemExit("--levels: give positive force amplitudes in N, e.g. 2,4,6,8")
    return levels


def cmd_modes(args) -> dict:
    model = _model(args)
    asm = model.assemble()
    f, phi = asm.normal_modes(args.n)
    M_beam = None
    try:
        M_beam = asm.group_mass_matrix(["beam", "clamp"])
    except ValueError:
        pass
    rows = []
    for i in range(f.size):
        share = None
        if M_beam is not None:
            share = float(phi[:, i] @ M_beam @ phi[:, i])
        rows.append({"mode": i + 1, "frequency_hz": float(f[i]), "beam_energy_share": share})
    if not args.json:
        print(f"{'mode':>4} {'f [Hz]':>10} {'beam share':>11}")
        for r in rows:
            s = "" if r["beam_energy_share"] is None else f"{100 * r['beam_energy_share']:10.1f}%"
            print(f"{r['mode']:4d} {r['frequency_hz']:10.2f} {s:>11}")
    return {"modes": rows, "mass_report": asm.mass_report()}


def _sweep(model, levels, freqs, direction, points, h, n):
    pb = build_problem(model, output_points=points, n_harmonics=h, n_time=n)
    f = freqs if direction == "up" else freqs[::-1]
    out = {}
    for level in levels:
        F = np.array([level, 0.02 * level, 0.02 * level])
        out[level] = solve_steps(pb, 2 * np.pi * f, F)
    return pb, f, out


def cmd_sweep(args) -> dict:
    from analysis.report import plot_multiharmonic_frfs

    model = _model(args)
    levels = _levels(args.levels)
    points = [int(p) for p in args.points.split(",")]
    freqs = paper_frequencies_hz()
    t0 = time.perf_counter()
    pb, f, res = _sweep(model, levels, freqs, args.direction, points, args.harmonics, args.samples)
    wall = time.perf_counter() - t0
    n_pts = sum(len(r.points) for r in res.values())
    n_ok = sum(int(r.converged.sum()) for r in res.values())
    summary = {
        "points": n_pts,
        "converged": n_ok,
        "wall_s": round(wall, 3),
        "failures": {str(k): r.failures() for k, r in res.items() if r.failures()},
    }
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        frfs = {f"{lv:g} N": r.frf() for lv, r in res.items()}
        png = plot_multiharmonic_frfs(
            f,
            frfs,
            ["1", "2", "3"],
            [f"point {p}" for p in points],
            out / "mhb_frfs.png",
            title="Multi-harmonic receptances (MHB)",
        )
        summary["figure"] = str(png)
    if not args.json:
        print(f"{n_pts} steps at levels {levels} N in {wall:.2f} s; converged {n_ok}/{n_pts}")
        for lv, r in res.items():
            tip = np.abs(r.outputs()[:, 0, -1])
            i = int(np.argmax(tip))
            print(
                f"  {lv:g} N: peak order-1 response at point {points[-1]} "
                f"{1e3 * tip[i]:.3f} mm at {f[i]:.2f} Hz"
            )
        if "figure" in summary:
            print(f"figure: {summary['figure']}")
    return summary


def cmd_export(args) -> dict:
    from analysis.matrix_io import export_linear

    files = export_linear(_model(args), args.out, args.format)
    if not args.json:
        for p in files:
            print(p)
    return {"files": [str(p) for p in files]}


def cmd_demo(args) -> dict:
    """The analysis side of the paper on its published model: modes, sweep, branches."""
    from analysis.report import plot_branches, plot_multiharmonic_frfs

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model = load_model().with_values(PAPER_CALIBRATED)
    print("Reference rig with the paper's calibrated values (Tables 2 and 5)")
    args.model, args.set, args.paper, args.n = None, [], True, 8
    modes = cmd_modes(args)
    levels = [2.0, 4.0, 6.0, 8.0]
    freqs = paper_frequencies_hz()
    t0 = time.perf_counter()
    pb, f, res = _sweep(model, levels, freqs, "up", [3, 6, 7], 9, 128)
    wall = time.perf_counter() - t0
    n_pts = sum(len(r.points) for r in res.values())
    n_ok = sum(int(r.converged.sum()) for r in res.values())
    print(f"\nPaper sweep by MHB: {n_pts} steps in {wall:.2f} s, converged {n_ok}/{n_pts}")
    fig1 = plot_multiharmonic_frfs(
        f,
        {f"{lv:g} N": r.frf() for lv, r in res.items()},
        ["1", "2", "3"],
        ["point 3", "point 6", "point 7 (tip)"],
        out / "paper_sweep_frfs.png",
        title="Multi-harmonic receptances, paper sweep (MHB)",
    )
    branches, steps = {}, {}
    lin = build_linear(model)
    pb7 = build_problem(model, output_points=[7], linear=lin)
    for lv in (2.0, 8.0):
        F = np.array([lv, 0.02 * lv, 0.02 * lv])
        br = continue_branch(pb7, 2 * np.pi * 22.0, 2 * np.pi * 34.0, F)
        fz = br.omega / (2 * np.pi)
        branches[f"{lv:g} N"] = (fz, 1e3 * np.abs(br.outputs()[:, 0, 0]), br.stable)
        steps[f"{lv:g} N"] = (f, 1e3 * np.abs(res[lv].outputs()[:, 0, 2]))
        folds = ", ".join(f"{f.omega / (2 * np.pi):.3f} Hz" for f in br.turning_points()) or "none"
        print(
            f"Branch at {lv:g} N: folds at {folds}; "
            f"{int((~br.stable).sum())} of {len(br.points)} points unstable"
        )
    fig2 = plot_branches(
        branches,
        out / "tip_branches.png",
        steps=steps,
        title="Tip response: continuation with Hill stability vs stepped sweep",
    )
    print(f"\nFigures: {fig1}\n         {fig2}")
    return {
        "modes": modes["modes"][:8],
        "sweep_points": n_pts,
        "converged": n_ok,
        "sweep_wall_s": round(wall, 3),
        "figures": [str(fig1), str(fig2)],
    }


def build_parser() -> argparse.ArgumentParser:
    # The commands are listed once, by argparse from each command's help (the module
    # docstring's table is for readers of the code, not for --help).
    p = argparse.ArgumentParser(
        prog="python -m analysis",
        description="Command line of the analysis side: python -m analysis COMMAND ...",
        epilog="Every command has --help.",
    )
    add_debug_option(p)
    sub = p.add_subparsers(dest="command", required=True, title="commands", metavar="COMMAND")

    def common(sp, model=True):
        if model:
            sp.add_argument("--model", help="model file (default: the reference rig)")
            sp.add_argument(
                "--set",
                action="append",
                metavar="NAME=VALUE",
                help="override a parameter value (repeatable)",
            )
            sp.add_argument(
                "--paper",
                action="store_true",
                help="use the paper's calibrated values (Tables 2 and 5)",
            )
        sp.add_argument("--json", action="store_true", help="print one JSON object")

    sp = sub.add_parser("modes", help="natural frequencies")
    common(sp)
    sp.add_argument("--n", type=int, default=10, help="number of modes")
    sp.set_defaults(func=cmd_modes)

    sp = sub.add_parser("sweep", help="stepped multi-harmonic FRFs by MHB")
    common(sp)
    sp.add_argument("--levels", default="2,4,6,8", help="force amplitudes [N]")
    sp.add_argument("--points", default="3,6,7", help="output points")
    sp.add_argument("--direction", choices=["up", "down"], default="up")
    sp.add_argument("--harmonics", type=int, default=9)
    sp.add_argument("--samples", type=int, default=128, help="AFT samples per period")
    sp.add_argument("--out", help="folder for the figure")
    sp.set_defaults(func=cmd_sweep)

    from analysis.continuation_cli import add_parser as add_continuation_parser

    add_continuation_parser(sub)

    sp = sub.add_parser("export-matrices", help="write M, K with the DOF map")
    common(sp)
    sp.add_argument("--out", required=True, help="output file (.npz, .mtx or .mat)")
    sp.add_argument("--format", choices=["npz", "mtx", "mat"], default=None)
    sp.set_defaults(func=cmd_export)

    from analysis.calibration.cli import add_parsers as add_calibration
    from analysis.calibration.linear.cli import add_parser as add_linear_parser
    from analysis.planning.cli import add_parser as add_plan_parser

    add_plan_parser(sub)
    add_linear_parser(sub)
    add_calibration(sub)

    from analysis.diagnosis.cli import add_parsers as add_diagnosis

    add_diagnosis(sub)

    sp = sub.add_parser("demo", help="the analysis part of the paper on its published model")
    common(sp, model=False)
    sp.add_argument("--out", default="demo-output", help="output folder")
    sp.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    configure_logging(args)
    note_inputs(args)
    try:
        # the command is one stage; the diagnosis and planning commands name their own inside
        with summarise_repeats(args.command):
            result = args.func(args)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, default=str))
    return 0
