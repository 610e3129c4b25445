"""The ``calibrate-linear`` command: linear calibration from a random-excitation run.

``python -m analysis calibrate-linear RUN.h5 [--model FILE] --out DIR [--json]`` writes
``DIR/calibrated_model.toml`` (a new model file: the input's values replaced, the identified
modal damping in ``[damping.per_mode]``) and ``DIR/linear_calibration.json`` (the result).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from analysis.calibration.linear.calibrate import (
    METHODS,
    LinearCalibrationSettings,
    calibrate_linear,
)
from analysis.model import load_model

__all__ = ["add_parser", "cmd_calibrate_linear"]

MODEL_FILE = "calibrated_model.toml"
RESULT_FILE = "linear_calibration.json"


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``calibrate-linear`` command to an argparse sub-parser set."""
    sp = subparsers.add_parser(
        "calibrate-linear",
        help="linear calibration from a random run (damping equalization)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sp.add_argument("run", help="random-excitation measurement file (kind 'random')")
    sp.add_argument("--model", help="model file (default: the reference rig)")
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.add_argument("--band", metavar="LO,HI", help="identification band [Hz]")
    sp.add_argument("--zeta0", type=float, help="equalized damping (default: mean identified)")
    sp.add_argument(
        "--points",
        metavar="P,P,...",
        help="calibration points, or 'information' (default: 1-8 and 11)",
    )
    sp.add_argument(
        "--parameters",
        metavar="NAME,...",
        help="calibrated parameters (default: linear ones flagged calibrate)",
    )
    sp.add_argument("--method", choices=sorted(METHODS), default="lm")
    sp.add_argument("--phase", action="store_true", help="compare phase as well")
    sp.add_argument(
        "--keep-sensor-masses",
        action="store_true",
        help="keep the run's sensor masses in the calibrated model",
    )
    sp.set_defaults(func=cmd_calibrate_linear)
    return sp


def _settings(args: argparse.Namespace) -> LinearCalibrationSettings:
    kw: dict[str, Any] = {
        "method": args.method,
        "use_phase": args.phase,
        "keep_sensor_masses": args.keep_sensor_masses,
        "zeta0": args.zeta0,
    }
    try:
        if args.band:
            lo, hi = (float(v) for v in args.band.split(","))
            kw["band_hz"] = (lo, hi)
        if args.points:
            pts = args.points.strip()
            kw["calibration_points"] = (
                pts if pts == "information" else tuple(int(p) for p in pts.split(",") if p)
            )
    except ValueError:
        raise ValueError("--band LO,HI in Hz; --points P,P,... or 'information'") from None
    if args.parameters:
        kw["parameters"] = tuple(n.strip() for n in args.parameters.split(",") if n.strip())
    return LinearCalibrationSettings(**kw)


def cmd_calibrate_linear(args: argparse.Namespace) -> dict[str, Any]:
    """Run the calibration, write the model and the result files, return the result as JSON."""
    model = load_model(args.model)
    result = calibrate_linear(model, args.run, _settings(args))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc = result.to_json()
    doc["model_source"] = str(model.source)
    model_path = result.save_model(out / MODEL_FILE)
    doc["files"] = {"model": str(model_path), "result": str(out / RESULT_FILE)}
    (out / RESULT_FILE).write_text(json.dumps(doc, indent=1))
    if not args.json:
        print(_summary(result, doc["files"]))
    return doc


def _summary(result, files: dict[str, str]) -> str:
    lines = [
        f"linear calibration of {result.source}: {result.message} "
        f"({result.nit} iterations, zeta0 = {result.zeta0:.4f})"
    ]
    for n in result.names:
        lines.append(
            f"  {n:12s} {result.start[n]:12.5g} -> {result.parameters[n]:12.5g}"
            f"  (std {result.std[n]:.3g})"
        )
    lines.append("  identified modes (Hz, damping %, model mode, MAC):")
    for m in result.modes:
        lines.append(
            f"    {m.frequency_hz:9.3f}  {100 * m.zeta:6.3f}  {m.model_mode!s:>4}  {m.mac:.3f}"
        )
    v0, v1 = result.validation["before"], result.validation["after"]
    for key in ("equalized", "measured"):
        b, a = v0[key]["validation"], v1[key]["validation"]
        if a is not None:
            lines.append(f"  validation rms log10 deviation ({key}): {b:.4f} -> {a:.4f}")
    lines += result.identifiability_notes()
    lines += [f"  model:  {files['model']}", f"  result: {files['result']}"]
    return "\n".join(lines)
