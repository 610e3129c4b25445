"""``rig separate RUN --model M``: settle a diagnosis's tie by running the test that separates it.

The diagnosis of ``RUN`` (:func:`analysis.diagnosis.diagnose`) either names one effect, finds
nothing, or ties candidates that the run cannot tell apart. On a tie the separating measurement
is written as a plan file (:func:`analysis.diagnosis.separate.write_separating_plan`), run on
the backend exactly as ``rig run PLAN`` runs a plan (on the simulated rig the truth and seed of
``RUN`` unless given), and the tied candidates are ranked again on the new file
(:func:`analysis.diagnosis.separate.rank_on_separating_run`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from rig.cli.run import EXIT_OK, _add_rig_options, _run


def _previous_sim_options(run_config: Any, args) -> None:
    """Take the simulated rig's truth and seed from the first run when not given."""
    from rig.run.session import previous_rig

    backend, previous = previous_rig(run_config)
    if args.backend != "sim" or backend != "sim":
        return
    if args.truth is None and "truth" in previous:
        args.truth = previous["truth"]
    if args.seed is None and "seed" in previous:
        args.seed = previous["seed"]


def cmd_separate(args) -> int:
    from analysis.diagnosis import DiagnosisSettings, diagnose
    from analysis.diagnosis.cli import read_stepped
    from analysis.diagnosis.separate import rank_on_separating_run, write_separating_plan
    from analysis.model import load_model

    data = read_stepped(args.run)
    model = load_model(args.model)
    settings = DiagnosisSettings(workers=args.workers)
    diag = diagnose(model, data, linear_run=args.linear_run, settings=settings)
    report: dict[str, Any] = {"verdict": diag.verdict, "tie": len(diag.group) > 1}
    if len(diag.group) < 2 or not diag.recommendation:
        reason = "no tie to separate" if len(diag.group) < 2 else "no separating measurement"
        report["note"] = reason
        print(json.dumps(report) if args.json else f"{diag.summary()}\n{reason}")
        return EXIT_OK
    out = Path(args.out)
    plan_path = Path(args.plan_out) if args.plan_out else out.with_suffix(".plan.toml")
    if plan_path.exists() and not args.overwrite:
        raise FileExistsError(f"{plan_path} exists; pass --overwrite to replace it")
    write_separating_plan(plan_path, diag.recommendation, data)
    _previous_sim_options(data.config, args)
    args.plan, args.resume = str(plan_path), None
    code = _run(args, "stepped-sine")
    if code != EXIT_OK:
        return code
    sep = rank_on_separating_run(diag.group, read_stepped(str(out)), settings.tie_bic)
    report |= {
        "plan": str(plan_path),
        "separating_run": str(out),
        "ranking": sep.ranking,
        "tied": sep.tied,
        "resolved": sep.resolved,
    }
    print(json.dumps(report) if args.json else f"{diag.summary()}\n{sep.summary()}")
    return EXIT_OK


def add_separate_command(sub) -> None:
    """Add ``separate`` to the ``rig`` parser's subcommands."""
    sp: argparse.ArgumentParser = sub.add_parser(
        "separate",
        help="diagnose a run and, on a tie, run the test that separates it and rank again",
        description="Diagnose RUN against MODEL; when candidates tie, write the separating "
        "measurement as a plan, run it on the backend as 'rig run' does (the simulated rig "
        "takes RUN's truth and seed unless given) and rank the tied candidates on the new file.",
    )
    sp.add_argument("run", help="stepped-sine measurement file (.h5) to diagnose")
    sp.add_argument("--model", required=True, help="calibrated model file")
    sp.add_argument("--linear-run", help="random-excitation test (for linear candidates)")
    sp.add_argument("--workers", type=int, default=2, help="processes for verifications")
    sp.add_argument(
        "--plan-out", help="where the separating plan is written (default: beside --out)"
    )
    _add_rig_options(sp, "separate.h5")
    sp.set_defaults(func=cmd_separate)
