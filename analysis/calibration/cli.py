"""Command-line commands of the nonlinear calibration: calibrate, crossval, validate, report.

Each command reads files and writes files into an output folder, so they chain:
``calibrate RUN.h5 --model M --out R`` (the calibration, its cross-validation and its stated
uncertainty); ``crossval --result R/calibration.json`` (again, e.g. on another file);
``validate --result R/calibration.json``; ``report R``.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from analysis.calibration.crossval import cross_validate
from analysis.calibration.nonlinear import (
    CalibrationSettings,
    calibrate_nonlinear,
    level_rows,
    make_predictor,
)
from analysis.calibration.results import load_calibration, save_calibration
from analysis.calibration.uncertainty import (
    ADEQUATE_RMS,
    HeldParameters,
    held_for_run,
    held_from_priors,
    load_linear_result,
)
from analysis.calibration.validation import validate
from analysis.executors import open_executor
from analysis.measurement_file import SteppedSineData, read_measurement
from analysis.measurement_file.status import require_steps
from analysis.model import load_model
from analysis.progress import ProgressReporter

__all__ = ["add_parsers"]

log = logging.getLogger(__name__)


def _reporter(args) -> ProgressReporter:
    """Progress as text for a person, as JSON lines with ``--json`` (for ``rig workflow``)."""
    return ProgressReporter("json" if args.json else "text", prefix="calibration: ")


def _stepped(path: str) -> SteppedSineData:
    data = read_measurement(path)
    if not isinstance(data, SteppedSineData):
        raise ValueError(
            f"{path}: a stepped-sine run is needed (this file is kind {data.kind!r})"
            if hasattr(data, "kind")
            else f"{path}: not a stepped-sine run"
        )
    return require_steps(data)


def _fit_figure(model, data, params, st, out: Path, levels, name: str, title: str):
    from analysis.report import plot_measured_vs_model

    pred = make_predictor(model, data, st)
    H, _ = pred.measured()
    rows = level_rows(data, levels)
    p = pred.predict(params, rows=rows)
    curves = {}
    for lv in levels:
        r = level_rows(data, [lv])
        curves[f"{lv:g} N"] = (data.frequency_hz[r], H[r], p.frf[r])
    return plot_measured_vs_model(
        curves, pred.channel_names, [str(o) for o in data.orders], out / name, title=title
    )


#: The linear calibration's result beside its model file (``analysis calibrate-linear``).
LINEAR_RESULT = "linear_calibration.json"


def _held(args, model, data: SteppedSineData) -> HeldParameters | None:
    """The held values' uncertainty: the linear calibration's result (``--linear-result``,
    or the one beside the model file), else the model file's priors."""
    if args.linear_result:  # named: it must be the model's
        path = args.linear_result
        return held_for_run(load_linear_result(path), model, data, source=path)
    beside = Path(args.model).parent / LINEAR_RESULT if args.model and not args.set else None
    if beside is not None and beside.exists():
        try:
            return held_for_run(load_linear_result(beside), model, data, source=str(beside))
        except ValueError as exc:  # found, not named: another model's result
            log.warning("%s; the model file's priors are used instead", exc)
    return held_from_priors(model)


def _held_refined(res) -> dict:
    """The held values as the joint refinement left them: name -> value, 1 sigma, the value
    it started from (the linear calibration's) ({} without a joint refinement)."""
    if not res.held_posterior or res.joint_names is None:
        return {}
    sd = np.sqrt(np.diag(res.cov_joint))
    index = {n: i for i, n in enumerate(res.joint_names)}
    return {
        n: {"value": v, "std": float(sd[index[n]]), "start": res.held.values.get(n)}
        for n, v in res.held_posterior.items()
    }


def _write_crossval(cv, out: Path) -> Path:
    from analysis.report import plot_crossval

    (out / "crossval.json").write_text(json.dumps(cv.to_json(), indent=1))
    return plot_crossval(
        cv.names, cv.folds, cv.estimates, cv.mean, cv.std, cv.fim_std, out / "crossval.png"
    )


def _print_result(res, model) -> None:
    print("calibrated parameters (1 sigma: noise, misfit and held values together):")
    for n, v in res.parameters.items():
        unit = model.parameters[n].unit
        print(
            f"  {n:10s} {v:12.5g} +- {res.std[n]:.3g} {unit}  (noise alone {res.std_noise[n]:.3g})"
        )
    for n, parts in res.contributions().items():
        top = sorted(parts.items(), key=lambda kv: -kv[1])[:3]
        print(f"    {n}: largest sources " + ", ".join(f"{k} {v:.3g}" for k, v in top))
    if res.held is None:
        print("  the held values (linear parameters, modal damping) are taken as exact")
    else:
        print(f"  held values' uncertainty from {res.held.source}")
        for note in res.held.notes:
            print(f"    note: {note}")
    for why in res.misfit:
        print(
            f"  MISFIT: {why}: the intervals are not to be trusted; `analysis diagnose` looks "
            "for the missing effect"
        )


def _crossval_into(res, model, data, executor, out: Path, reporter: ProgressReporter):
    """Cross-validate ``res``, widen its intervals by the folds' evidence, write the files."""
    cv = cross_validate(model, data, res, executor=executor, progress=reporter.event)
    res.widen_with_folds(cv.std_ratio, [cv.folds[j] for j in cv.misfit_folds()])
    return cv, _write_crossval(cv, out)


def cmd_calibrate(args) -> dict:
    from analysis.report import plot_convergence

    model = load_model(args.model)
    if args.set:
        model = model.with_values({k: float(v) for k, v in (s.split("=", 1) for s in args.set)})
    data = _stepped(args.run)
    held = _held(args, model, data)
    st = CalibrationSettings(
        n_starts=args.starts,
        seed=args.seed,
        weighting="identity" if args.identity else "uncertainty",
        max_iterations=args.max_iterations,
        match_branches=not args.plain_continuation,
        include_unconverged=args.include_unconverged,
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cv = None
    reporter = _reporter(args)
    with open_executor(args.workers, args.scheduler) as ex:
        res = calibrate_nonlinear(model, data, st, executor=ex, progress=reporter.event, held=held)
        if not args.no_crossval:
            t1 = time.perf_counter()
            cv, cv_fig = _crossval_into(res, model, data, ex, out, reporter)
            res.timings["crossval_s"] = time.perf_counter() - t1
    reporter.close()
    files = save_calibration(res, model, out, args.run)
    fig1 = plot_convergence([h["cost"] for h in res.lm.history], out / "convergence.png")
    fig2 = _fit_figure(
        model,
        data,
        res.parameters,
        st,
        out,
        res.calibration_levels_n,
        "calibration_fit.png",
        "Calibration levels: measured vs calibrated model",
    )
    summary = {
        "parameters": res.parameters,
        "std": res.std,
        "std_noise": res.std_noise,
        "interval_95": {
            n: [v - 1.96 * res.std[n], v + 1.96 * res.std[n]] for n, v in res.parameters.items()
        },
        "chi2_per_dof": res.chi2_per_dof,
        "misfit": res.misfit,
        "held": None if held is None else held.source,
        "held_refined": _held_refined(res),
        "lm_iterations": res.lm.nit,
        "timings": res.timings,
        "total_s": time.perf_counter() - t0,
        "files": [str(p) for p in (*files.values(), fig1, fig2)],
    }
    if cv is not None:
        summary["crossval"] = cv.to_json()
        summary["files"].append(str(cv_fig))
    if not args.json:
        _print_result(res, model)
        print(f"chi2/dof {res.chi2_per_dof:.3f}; LM {res.lm.nit} iterations ({res.lm.message})")
        if cv is not None:
            _print_crossval(cv)
        print(f"model: {files['model']}\nresult: {files['result']}")
    return summary


def _print_crossval(cv) -> None:
    print(f"{len(cv.folds)}-fold cross-validation ({cv.seconds:.1f} s):")
    for j, n in enumerate(cv.names):
        print(
            f"  {n:10s} mean {cv.mean[j]:12.5g}  std {cv.std[j]:.3g}  "
            f"FIM^-1 std {cv.fim_std[j]:.3g}  ratio {cv.std_ratio[j]:.2f}"
        )
    if cv.stuck:
        print(
            f"  warning: {len(cv.stuck)} fold(s) could not leave the calibrated optimum "
            f"({', '.join(cv.stuck)}): the standard deviations understate the uncertainty"
        )
    for line in cv.notes():
        print(f"  note: {line}")


def cmd_crossval(args) -> dict:
    res, model, data_path = load_calibration(args.result)
    data = _stepped(args.run or data_path)
    out = Path(args.result).parent
    reporter = _reporter(args)
    with open_executor(args.workers, args.scheduler) as ex:
        cv, fig = _crossval_into(res, model, data, ex, out, reporter)
    reporter.close()
    if not args.run:  # the calibration's own data: its stated intervals take the evidence
        save_calibration(res, model, out, data_path)
    if not args.json:
        _print_crossval(cv)
        if not args.run:
            print(f"{args.result}: intervals now include the folds' scatter")
    return {**cv.to_json(), "figure": str(fig)}


def cmd_validate(args) -> dict:
    from analysis.report import plot_validation

    res, model, data_path = load_calibration(args.result)
    data = _stepped(args.run or data_path)
    v = validate(model, data, res, level_n=args.level, threshold=args.threshold)
    out = Path(args.result).parent
    (out / "validation.json").write_text(json.dumps(v.to_json(), indent=1))
    fig = plot_validation(
        v.frequency_hz,
        v.measured,
        v.measured_std,
        v.predicted,
        v.predicted_std,
        v.channels,
        [str(o) for o in data.orders],
        out / "validation.png",
        title=f"Validation at {v.level_n:g} N (not used in calibration)",
    )
    if not args.json:
        print(v.summary())
    return {**v.to_json(), "figure": str(fig)}


def cmd_report(args) -> dict:
    from analysis.report.calibration_report import write_report

    paths = write_report(Path(args.folder), reference=args.reference)
    if not args.json:
        print(f"report: {paths['html']}")
    return {k: str(v) for k, v in paths.items()}


def add_parsers(sub) -> None:
    """Add the calibration commands to an ``argparse`` sub-parser collection."""
    sp = sub.add_parser("calibrate", help="nonlinear calibration (LHS + Levenberg-Marquardt)")
    sp.add_argument("run", help="stepped-sine measurement file (.h5)")
    sp.add_argument("--model", help="model file, linear part calibrated (default: reference rig)")
    sp.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a value")
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--starts", type=int, default=100, help="Latin hypercube starts")
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument(
        "--lm-starts",
        type=int,
        default=1,
        help="best Latin hypercube candidates refined by LM (the paper: 1)",
    )
    sp.add_argument("--max-iterations", type=int, default=50)
    sp.add_argument(
        "--plain-continuation",
        action="store_true",
        help="predict by forward continuation in the sweep order only (default: on the "
        "branch the test was on, where the rig left a resonant branch before its fold)",
    )
    sp.add_argument(
        "--include-unconverged",
        action="store_true",
        help="also fit the steps not converged under force control",
    )
    sp.add_argument(
        "--identity", action="store_true", help="W = I (the paper) instead of 1/sigma^2"
    )
    sp.add_argument(
        "--linear-result",
        metavar="FILE",
        help="the linear calibration's linear_calibration.json, whose parameters' and modal "
        "damping's uncertainty the stated intervals carry (default: the one beside --model, "
        "else the model file's priors)",
    )
    sp.add_argument(
        "--no-crossval",
        action="store_true",
        help="skip the cross-validation (its folds' scatter then does not widen the intervals)",
    )
    sp.set_defaults(func=cmd_calibrate)

    sp = sub.add_parser("crossval", help="k-fold cross-validation of a calibration")
    sp.add_argument("--result", required=True, help="calibration.json")
    sp.add_argument("--run", help="measurement file (default: the one calibrated)")
    sp.set_defaults(func=cmd_crossval)

    sp = sub.add_parser("validate", help="predict a held-out level with bands, pass/fail")
    sp.add_argument("--result", required=True, help="calibration.json")
    sp.add_argument("--run", help="measurement file (default: the one calibrated)")
    sp.add_argument("--level", type=float, help="level [N] (default: the one held out)")
    sp.add_argument(
        "--threshold",
        type=float,
        default=ADEQUATE_RMS**2,
        help=f"largest chi2/dof that passes (default {ADEQUATE_RMS**2:g}: the RMS residual "
        f"within {ADEQUATE_RMS:g} x the noise, as every analysis judges a model)",
    )
    sp.set_defaults(func=cmd_validate)

    sp = sub.add_parser("report", help="collect a folder's results into one report")
    sp.add_argument("folder", help="folder written by calibrate/crossval/validate")
    sp.add_argument(
        "--reference",
        metavar="FILE",
        help="reference values (JSON with 'parameters', e.g. a simulated rig's truth.json): "
        "tables add the reference, the error, z and whether it lies in the 95 %% interval",
    )
    sp.set_defaults(func=cmd_report)

    for name in ("calibrate", "crossval", "validate", "report"):
        p = sub.choices[name]
        p.add_argument("--json", action="store_true", help="print one JSON object")
        if name in ("calibrate", "crossval"):
            p.add_argument(
                "--workers",
                type=int,
                default=None,
                help="local worker processes (default: all CPUs; 1 = serial)",
            )
            p.add_argument("--scheduler", help="Dask scheduler address (a trusted lab cluster)")
