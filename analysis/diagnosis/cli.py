"""Command-line commands of the diagnosis: compare, diagnose, augment.

``python -m analysis compare RUN.h5 --model M.toml``
    residual blocks and maps of a model against a stepped-sine file;
``python -m analysis diagnose RUN.h5 --model M.toml [--linear-run RANDOM.h5]``
    which physical effect is missing (evidence, screen, verification, ranking);
``python -m analysis augment RUN.h5 --model M.toml --out NEW.toml [--candidate LABEL]``
    add it (the best of a diagnosis by default), recalibrate, show the error falling.

Progress goes to stderr, the summary to stdout; ``--json`` prints one JSON object instead.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from analysis.diagnosis.augment import augment
from analysis.diagnosis.candidates import LOCATION_SCOPES, default_candidates
from analysis.diagnosis.compare import compare, uncalibrated_note
from analysis.diagnosis.diagnose import diagnose
from analysis.diagnosis.result import DiagnosisSettings
from analysis.diagnosis.separate import write_separating_plan
from analysis.events import StageDone
from analysis.logs import add_debug_option, configure_logging, note_inputs, summarise_repeats
from analysis.measurement_file import SteppedSineData, read_measurement, require_steps
from analysis.model import load_model
from analysis.predict_branches import BranchMatchedPredictor
from analysis.progress import ProgressReporter

__all__ = ["add_parsers"]


def _progress(quiet: bool) -> ProgressReporter:
    """Progress of the diagnosis commands on stderr (none with ``--json``): counted stages
    (the screen, the starts) as a count, Levenberg-Marquardt's iterations, each milestone on
    a line of its own."""
    return ProgressReporter("none" if quiet else "text", prefix="diagnosis: ")


def read_stepped(path: str) -> SteppedSineData:
    """The stepped-sine run in ``path`` (a random run or a file without steps refused)."""
    data = read_measurement(path)
    if not isinstance(data, SteppedSineData):
        raise ValueError(f"{path}: a stepped-sine run is needed (this is a random run)")
    return require_steps(data)


def _model(args):
    model = load_model(args.model)
    values = {}
    for item in args.set or []:
        name, _, value = item.partition("=")
        values[name.strip()] = float(value)
    return model.with_values(values) if values else model


def _note_uncalibrated(model) -> None:
    """Say on stderr when the model has not been calibrated (a diagnosis would find that)."""
    note = uncalibrated_note(model)
    if note:
        print(f"note: {note}", file=sys.stderr)


def cmd_compare(args) -> dict:
    """Residual blocks of a model against a file; figures with ``--figures``."""
    model, data = _model(args), read_stepped(args.run)
    pred = BranchMatchedPredictor(model, data, n_harmonics=args.harmonics, n_time=args.samples)
    with summarise_repeats("compare"):
        cmp = compare(model, data, predictor=pred, sigma=args.sigma)
    if args.figures:
        from analysis.report.diagnosis_figures import (
            plot_frequency_level_map,
            plot_measured_vs_model_levels,
            plot_sensor_order_level_map,
        )

        out = Path(args.figures)
        out.mkdir(parents=True, exist_ok=True)
        plot_sensor_order_level_map(cmp, out / "residual_sensor_order_level.png")
        plot_frequency_level_map(cmp, out / "residual_frequency_level.png")
        plot_measured_vs_model_levels(cmp, out / "measured_vs_model.png")
    if not args.json:
        print(cmp.summary(args.top))
    return cmp.to_json()


def _settings(args) -> DiagnosisSettings:
    return DiagnosisSettings(
        workers=args.workers,
        n_starts=args.starts,
        n_harmonics=args.harmonics,
        n_time=args.samples,
        rescreen_ratio=args.rescreen_ratio,
        locations=args.locations,
    )


def cmd_diagnose(args) -> dict:
    """Which effect is missing."""
    model, data = _model(args), read_stepped(args.run)
    _note_uncalibrated(model)
    with summarise_repeats("diagnose"):
        result = diagnose(
            model,
            data,
            linear_run=args.linear_run,
            settings=_settings(args),
            progress=_progress(args.json).event,
        )
    if args.figures:
        from analysis.report.diagnosis_figures import plot_diagnosis

        plot_diagnosis(result, args.figures)
    if not args.json:
        print(result.summary())
        print(f"({result.timings.get('total_s', 0):.1f} s)")
    out = result.to_json()
    if args.separate_plan:
        out["separate_plan"] = _write_separate_plan(args.separate_plan, result, data)
    return out


def _write_separate_plan(path: str, result, data) -> str | None:
    """Write the measurement separating a tie as a plan file; say so when there is no tie."""
    if not result.recommendation:
        reason = "no tie" if len(result.group) < 2 else "no configuration separates the tie"
        print(f"note: no separating plan written ({reason})", file=sys.stderr)
        return None
    written = write_separating_plan(path, result.recommendation, data)
    print(f"separating plan written to {written}", file=sys.stderr)
    return str(written)


def cmd_augment(args) -> dict:
    """Add the chosen effect (or the best of a diagnosis), recalibrate, compare."""
    model, data = _model(args), read_stepped(args.run)
    _note_uncalibrated(model)
    show = _progress(args.json).event
    values = known = None
    if args.candidate:
        matches = [
            c for c in default_candidates(model, scope="structure") if c.label == args.candidate
        ]
        if not matches:
            labels = "; ".join(
                c.label for c in default_candidates(model, scope=args.locations)[:12]
            )
            raise ValueError(f"no candidate {args.candidate!r} (e.g. {labels}; ...)")
        cand = matches[0]
    else:
        with summarise_repeats("diagnose"):
            diag = diagnose(
                model, data, linear_run=args.linear_run, settings=_settings(args), progress=show
            )
        if diag.verdict != "explained":
            raise RuntimeError(
                f"the diagnosis claims nothing to add (verdict: {diag.verdict}); name a "
                "--candidate to add one anyway"
            )
        best = diag.group[0]
        cand = best.candidate
        values, known = best.start_values()
        show(StageDone("chosen", note=cand.label))
    with summarise_repeats("augment"):
        result = augment(
            model,
            data,
            cand,
            values=values,
            known=known,
            linear_run=args.linear_run,
            n_starts=args.starts,
            reweight_passes=args.reweight,
            out=args.out,
            progress=show,
            n_harmonics=args.harmonics,
            n_time=args.samples,
        )
    if args.figures:
        from analysis.report.diagnosis_figures import plot_before_after, plot_error_history

        out = Path(args.figures)
        out.mkdir(parents=True, exist_ok=True)
        plot_before_after(
            result.before, result.after, out / "before_after.png", title=f"added: {cand.label}"
        )
        plot_error_history(result.history, out / "error_history.png", title=cand.label)
    if not args.json:
        print(result.summary())
    return result.to_json()


def add_parsers(subparsers) -> None:
    """Add ``compare``, ``diagnose`` and ``augment`` to an ``argparse`` sub-parser collection."""

    def common(sp):
        sp.add_argument("run", help="stepped-sine measurement file (.h5)")
        sp.add_argument("--model", help="calibrated model file (default: the reference rig)")
        sp.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a value")
        sp.add_argument("--figures", metavar="DIR", help="write the figures into DIR")
        sp.add_argument("--json", action="store_true", help="print one JSON object")
        sp.add_argument("--harmonics", type=int, default=9, help="harmonics of the balance")
        sp.add_argument("--samples", type=int, default=128, help="AFT samples per period")

    sp = subparsers.add_parser("compare", help="residual maps of a model against a file")
    common(sp)
    sp.add_argument("--top", type=int, default=8, help="failing blocks listed")
    sp.add_argument(
        "--sigma",
        choices=("model", "file"),
        default="model",
        help="standard errors: the force's carried through the model (default) "
        "or the file's first-order FRF errors",
    )
    sp.set_defaults(func=cmd_compare)

    def rescreen(sp) -> None:
        sp.add_argument(
            "--rescreen-ratio",
            type=float,
            default=DiagnosisSettings.rescreen_ratio,
            metavar="R",
            help="screen again from the model with its own parameters recalibrated when that "
            f"brings the residual to R of the model's or below (default "
            f"{DiagnosisSettings.rescreen_ratio}; 0: never)",
        )

    def locations(sp) -> None:
        sp.add_argument(
            "--locations",
            choices=sorted(LOCATION_SCOPES),
            default=DiagnosisSettings.locations,
            help="candidate places: 'structure' (every direction of each point, each spring "
            "alone and each group, joint directions, pairs of nodes; default) or 'measured' "
            "(each point in its measured direction, spring groups, joint rotations: faster, "
            "but blind to one spring of a group and to elements between two nodes)",
        )

    sp = subparsers.add_parser("diagnose", help="which physical effect the model misses")
    common(sp)
    sp.add_argument("--linear-run", help="random-excitation test (for linear candidates)")
    sp.add_argument("--starts", type=int, default=4, help="extra starts for strong effects")
    sp.add_argument("--workers", type=int, default=2, help="processes for verifications")
    sp.add_argument(
        "--separate-plan",
        metavar="PLAN.toml",
        help="on a tie, write the measurement that separates it as a rig plan file",
    )
    rescreen(sp)
    locations(sp)
    sp.set_defaults(func=cmd_diagnose)

    sp = subparsers.add_parser("augment", help="add an effect, recalibrate, compare")
    common(sp)
    sp.add_argument("--out", required=True, help="the new model file (the old one is kept)")
    sp.add_argument("--candidate", help="candidate label (default: the diagnosis' best)")
    sp.add_argument("--linear-run", help="random-excitation test (for a linear effect)")
    sp.add_argument("--starts", type=int, default=0, help="further Latin hypercube starts")
    sp.add_argument(
        "--reweight",
        type=int,
        default=1,
        metavar="N",
        help="fits again with the weights at the fitted values (default 1)",
    )
    sp.add_argument("--workers", type=int, default=2, help="processes for verifications")
    rescreen(sp)
    locations(sp)
    sp.set_defaults(func=cmd_augment)


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry: ``python -m analysis.diagnosis.cli diagnose ...``."""
    import json

    parser = argparse.ArgumentParser(prog="python -m analysis.diagnosis.cli")
    add_debug_option(parser)
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    configure_logging(args)
    note_inputs(args)
    try:
        result = args.func(args)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
