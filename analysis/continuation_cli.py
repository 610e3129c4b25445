"""``python -m analysis continuation``: a frequency-response curve of any model through its folds.

Any model file, any drive DOF and force orders and amplitudes, any number of harmonics and
samples, a frequency range in Hz or rad/s; the curve goes to a CSV or HDF5 file with its folds
and peaks located to the solver's tolerance, and to a figure. Without a model file it continues
the reference rig's tip response between 22 and 34 Hz, driven at point 3 by 8 N at order 1
and 2 % at orders 2 and 3, as in the paper.
"""

from __future__ import annotations

import argparse
import csv
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from analysis.logs import parse_assignments
from analysis.mhb.continuation import Branch, ContinuationSettings, continue_branch
from analysis.model import Model, load_model
from analysis.paper import PAPER_CALIBRATED
from analysis.system import DEFAULT_HARMONICS, DEFAULT_TIME_SAMPLES, build_problem_dofs

__all__ = [
    "add_parser",
    "cmd_continuation",
    "compute_curve",
    "parse_dof",
    "save_curve",
    "write_curve",
]

_DATA_SUFFIXES = (".csv", ".h5", ".hdf5")


def parse_dof(model: Model, text: str, option: str) -> tuple[int, str]:
    """A structural DOF index and its label from ``7`` (measurement point 7 in its direction),
    ``tip/y`` (node and direction) or ``dof:12`` (a DOF index of the assembled model)."""
    asm = model.assemble()
    text = text.strip()
    try:
        if text.startswith("dof:"):
            i = int(text[4:])
            if not 0 <= i < asm.n_dofs:
                raise KeyError(f"DOF indices run 0..{asm.n_dofs - 1}")
            node, d = asm.dofs[i]
            return i, f"{node}/{d}"
        if text.isdigit():
            return asm.point_dof(int(text)), f"point {text}"
        node, sep, direction = text.partition("/")
        if not sep:
            raise KeyError("expected a point number, node/direction or dof:INDEX")
        return asm.dof_index(node, direction), text
    except (KeyError, ValueError) as exc:
        msg = exc.args[0] if exc.args else exc
        raise SystemExit(f"{option} {text!r}: {msg}") from None


def _numbers(text: str, option: str, kind=float) -> list:
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except (ValueError, ZeroDivisionError):
        raise SystemExit(f"{option} {text!r}: expected numbers separated by commas") from None
    if not values:
        raise SystemExit(f"{option}: give at least one value")
    return values


def _range(text: str, unit: str) -> tuple[float, float]:
    a, sep, b = text.partition(":")
    try:
        lo, hi = float(a), float(b)
    except ValueError:
        lo = hi = None
    if not sep or lo is None or not (lo > 0 and hi > 0 and lo != hi):
        raise SystemExit(
            f"--range {text!r}: expected START:END, two different positive frequencies "
            f"in {unit} (END < START continues downwards)"
        )
    scale = 2 * np.pi if unit == "hz" else 1.0
    return lo * scale, hi * scale


def _model(args) -> Model:
    path = args.model_file or args.model
    model = load_model(path)
    values = {**PAPER_CALIBRATED} if args.paper else {}
    values |= parse_assignments(args.set)
    if path is not None and args.drive is None:
        raise SystemExit("--drive: required with a model file (a point, node/direction or dof:N)")
    return model.with_values(values) if values else model


def compute_curve(args) -> tuple[Branch, object, list[str], float]:
    """The continued branch of the command's arguments, the problem, the output labels and
    the wall time [s]."""
    model = _model(args)
    rig = (args.model_file or args.model) is None
    # the reference rig's defaults are the paper's: driven at point 3, the tip's response,
    # 8 N at order 1 with 2 % at orders 2 and 3; another model names its drive and force
    drive, _ = parse_dof(model, args.drive or "3", "--drive")
    outputs_text = args.outputs or ("7" if rig else args.drive)
    outputs = [parse_dof(model, t, "--outputs") for t in outputs_text.split(",")]
    orders_text = args.force_orders or ("1,2,3" if rig else "1")
    orders = _numbers(orders_text, "--force-orders", Fraction)
    if min(orders) <= 0:
        raise SystemExit(f"--force-orders {orders_text!r}: orders must be positive")
    if args.amplitudes is None and not rig:
        raise SystemExit("--amplitudes: required with a model file (force per order [N])")
    amps_text = args.amplitudes or "8,0.16,0.16"
    amps = _numbers(amps_text, "--amplitudes")
    if len(amps) != len(orders):
        raise SystemExit(
            f"--amplitudes {amps_text!r}: one amplitude per force order "
            f"({len(orders)}: {orders_text})"
        )
    if args.H < 1 or args.N < 4 * args.H + 1:
        raise SystemExit(f"--H {args.H} --N {args.N}: need H >= 1 and N >= 4 H + 1 samples")
    if args.range is None and not rig:
        raise SystemExit("--range: required with a model file (START:END in --unit)")
    w0, w1 = _range(args.range or "22:34", args.unit)
    if not 0 < args.ds <= 0.2:
        raise SystemExit(f"--ds {args.ds!r}: expected 0 < ds <= 0.2 (scaled arclength)")
    if args.max_angle is not None and not 0 < args.max_angle < np.pi / 2:
        raise SystemExit(f"--max-angle {args.max_angle!r}: expected 0 < angle < pi/2 rad")
    pb = build_problem_dofs(
        model, [drive], [i for i, _ in outputs], orders=orders, n_harmonics=args.H, n_time=args.N
    )
    settings = ContinuationSettings(
        ds=args.ds, ds_max=0.2, max_points=args.max_points, max_angle=args.max_angle
    )
    t0 = time.perf_counter()
    branch = continue_branch(pb, w0, w1, np.array(amps, dtype=complex), settings)
    return branch, pb, [label for _, label in outputs], time.perf_counter() - t0


def _columns(branch: Branch, pb, labels: list[str]) -> dict[str, np.ndarray]:
    w = branch.omega
    cols = {"frequency_hz": w / (2 * np.pi), "omega_rad_s": w}
    if branch.stable is not None:
        cols["stable"] = branch.stable.astype(int)
    q = branch.outputs()  # (n, n_orders, n_out)
    for j, label in enumerate(labels):
        for o, order in enumerate(pb.orders):
            key = f"{label.replace(' ', '')} order {order}"
            cols[f"amplitude [m] {key}"] = np.abs(q[:, o, j])
            cols[f"phase [deg] {key}"] = np.degrees(np.angle(q[:, o, j]))
    return cols


def _located(branch: Branch, n_out: int) -> list[dict]:
    rows = [("fold", f, 0) for f in branch.turning_points()]
    rows += [("peak", p, j) for j in range(n_out) for p in branch.peaks(output=j)]
    return [
        {
            "kind": kind,
            "output": j,
            "frequency_hz": loc.omega / (2 * np.pi),
            "omega_rad_s": loc.omega,
            "amplitude_m": float(abs(loc.point.outputs()[0, j])),
            "after_point": loc.after,
        }
        for kind, loc, j in rows
    ]


def write_curve(path: Path, cols: dict[str, np.ndarray], located: list[dict]) -> list[Path]:
    """The curve as CSV (with ``<stem>.located.csv`` for folds and peaks) or HDF5."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".csv":
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            w.writerows(zip(*(c.tolist() for c in cols.values()), strict=True))
        loc_path = path.with_name(f"{path.stem}.located.csv")
        with loc_path.open("w", newline="") as fh:
            keys = ["kind", "output", "frequency_hz", "omega_rad_s", "amplitude_m", "after_point"]
            table = csv.DictWriter(fh, fieldnames=keys)
            table.writeheader()
            table.writerows(located)
        return [path, loc_path]
    import h5py

    with h5py.File(path, "w") as f:
        g = f.create_group("curve")
        for k, v in cols.items():
            g.create_dataset(k, data=v)
        g = f.create_group("located")
        for k in ("kind", "output", "frequency_hz", "omega_rad_s", "amplitude_m", "after_point"):
            data = [r[k] for r in located]
            g.create_dataset(k, data=np.array(data, dtype="S8" if k == "kind" else None))
    return [path]


def save_curve(
    branch: Branch,
    pb,
    labels: list[str],
    out: Path | None,
    figure: Path | None,
    unit: str = "hz",
    title: str = "",
) -> dict:
    """Write a branch's curve (CSV or HDF5, with its located folds and peaks) and its figure
    (amplitude of the first output at the first order against frequency in ``unit``).

    Returns
    -------
    dict
        ``located`` (the folds and peaks), ``files`` written and ``figure``.
    """
    located = _located(branch, len(labels))
    result: dict[str, Any] = {"located": located, "files": [], "figure": None}
    if out is not None:
        result["files"] = [str(p) for p in write_curve(out, _columns(branch, pb, labels), located)]
    if figure is not None:
        from analysis.report import plot_branches

        hz = unit == "hz"
        key = "frequency_hz" if hz else "omega_rad_s"
        x = branch.omega / (2 * np.pi) if hz else branch.omega
        folds = [r for r in located if r["kind"] == "fold" and r["output"] == 0]
        figure.parent.mkdir(parents=True, exist_ok=True)
        png = plot_branches(
            {labels[0]: (x, np.abs(branch.outputs()[:, 0, 0]), branch.stable)},
            figure,
            title=title,
            ylabel=f"{labels[0]}, order {pb.orders[0]} amplitude [m]",
            xlabel="fundamental frequency [Hz]" if hz else "fundamental frequency [rad/s]",
            marks={"folds": ([r[key] for r in folds], [r["amplitude_m"] for r in folds])},
        )
        result["figure"] = str(png)
    return result


def cmd_continuation(args) -> dict:
    branch, pb, labels, wall = compute_curve(args)
    out = Path(args.out) if args.out else None
    figure = Path(args.figure) if args.figure else None
    if out is not None and out.suffix not in _DATA_SUFFIXES:
        out.mkdir(parents=True, exist_ok=True)  # a folder: the curve and its figure in it
        out, figure = out / "curve.csv", figure or out / "branch.png"
    title = f"Continuation, drive {args.drive or '3'}, force {args.amplitudes or '8,0.16,0.16'} N"
    saved = save_curve(branch, pb, labels, out, figure, args.unit, title)
    located = saved["located"]
    summary = {
        "points": len(branch.points),
        "message": branch.message,
        "folds_hz": [r["frequency_hz"] for r in located if r["kind"] == "fold"],
        "peaks_hz": [r["frequency_hz"] for r in located if r["kind"] == "peak"],
        "unstable_points": None if branch.stable is None else int((~branch.stable).sum()),
        "wall_s": round(wall, 3),
        "files": saved["files"],
    }
    if saved["figure"]:
        summary["figure"] = saved["figure"]
    if not args.json:
        hz = args.unit == "hz"
        scale = 1.0 if hz else 2 * np.pi
        folds = ", ".join(f"{f * scale:.6g}" for f in summary["folds_hz"]) or "none"
        print(
            f"{len(branch.points)} points ({branch.message}) in {wall:.2f} s; "
            f"folds at {folds} {'Hz' if hz else 'rad/s'}; "
            f"{summary['unstable_points']} unstable points"
        )
        for f in summary["files"] + ([summary["figure"]] if "figure" in summary else []):
            print(f"wrote {f}")
    return summary


def add_parser(sub) -> argparse.ArgumentParser:
    """Add ``continuation`` to the analysis command line's subparsers."""
    sp = sub.add_parser(
        "continuation",
        help="frequency-response curve of any model through its folds",
        description=__doc__.split("\n\n")[1],
    )
    sp.add_argument("model_file", nargs="?", metavar="MODEL", help="model file (default: the rig)")
    sp.add_argument("--model", help=argparse.SUPPRESS)
    sp.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter")
    sp.add_argument("--paper", action="store_true", help="the paper's calibrated values (rig)")
    sp.add_argument("--drive", help="driven DOF: a point number, node/direction or dof:N")
    sp.add_argument("--outputs", help="response DOFs, comma separated (default: the drive)")
    sp.add_argument("--force-orders", help="excitation orders, e.g. 1 or 1,2,3 (default 1)")
    sp.add_argument("--amplitudes", help="force per order [N], comma separated")
    sp.add_argument("--H", type=int, default=DEFAULT_HARMONICS, help="harmonics of the base")
    sp.add_argument("--N", type=int, default=DEFAULT_TIME_SAMPLES, help="AFT samples per period")
    sp.add_argument("--range", help="START:END frequency (the rig: 22:34 Hz)")
    sp.add_argument("--unit", choices=["hz", "rad/s"], default="hz", help="of --range and output")
    sp.add_argument("--ds", type=float, default=0.02, help="initial arclength step")
    sp.add_argument(
        "--max-angle", type=float, default=0.1, help="largest turn between points [rad]"
    )
    sp.add_argument("--max-points", type=int, default=2000)
    sp.add_argument("--out", help="curve.csv or curve.h5 (or a folder for curve.csv + figure)")
    sp.add_argument("--figure", help="PNG of the curve with its folds")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_continuation)
    return sp
