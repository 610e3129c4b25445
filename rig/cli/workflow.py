"""The paper's whole workflow on a backend, as a lab would run it: ``python -m rig workflow``.

Each stage is the command a user would type, run in a child process and writing its own files
into one folder, so the folder documents the study and any stage can be repeated by hand:

0. ``rig reference``             (simulated rig) its truth, as ``truth.json``
1. ``rig linear``                 random test, all 13 points, low level (gap open)
2. ``rig run paper``              stepped multi-sine under force control, 2/4/6/8 N
3. ``analysis calibrate-linear``  damping-equalized linear calibration, modal damping; weak
                                  parameters held at their prior (:func:`analyse_runs` on)
4. ``analysis plan``              FIM pretest planning of the nonlinear test
5. ``analysis calibrate``         Latin hypercube + Levenberg-Marquardt on 2/4/6 N, refined
                                  jointly with the linear test's posterior, 9-fold
                                  cross-validation, the stated intervals
6. ``analysis validate``          prediction of 8 N with uncertainty bands
7. ``analysis report``            figures and tables (against ``truth.json`` on the simulated
                                  rig); ``summary.md`` gives the verdict and compares with the
                                  paper
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

from analysis.paper import PAPER_LINEAR, PAPER_NONLINEAR, TABLE4_BEST
from analysis.progress import ProgressReporter, format_duration, parse_line

__all__ = ["analyse_runs", "run_workflow", "verdict"]

#: The simulated rig's truth, beside the results (never in a measurement file).
TRUTH_FILE = "truth.json"


class StageError(RuntimeError):
    """A workflow stage failed; the message names it and quotes its error output."""


def _stage(name: str, argv: list[str], log: list[dict], quiet: bool) -> dict:
    """Run one command of the workflow with ``--json``: its last JSON line is the result, its
    progress lines (:mod:`analysis.progress`) are shown as they come, the rest of its error
    output is kept for the message if it fails."""
    t0 = time.perf_counter()
    if not quiet:
        print(f"== {name}: {' '.join(argv[2:])}", file=sys.stderr, flush=True)
    shown = ProgressReporter("none" if quiet else "text", sys.stderr, prefix="   ")
    other: list[str] = []
    with subprocess.Popen(
        [sys.executable, *argv, "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        bufsize=1,
    ) as proc:
        stdout: list[str] = []
        reader = threading.Thread(target=lambda: stdout.append(proc.stdout.read()), daemon=True)
        reader.start()
        for line in proc.stderr:
            progress = parse_line(line)
            if progress is None:
                other.append(line)
            else:
                shown.show(progress)
        reader.join()
        returncode = proc.wait()
    shown.close()
    dt = time.perf_counter() - t0
    if returncode != 0:
        tail = "".join(other).strip()[-2000:]
        raise StageError(f"stage '{name}' failed (exit {returncode}):\n{tail}")
    lines = [ln for ln in "".join(stdout).strip().splitlines() if ln.startswith("{")]
    out = json.loads(lines[-1]) if lines else {}
    log.append({"stage": name, "seconds": round(dt, 2), "argv": argv})
    if not quiet:
        print(f"   done in {format_duration(dt)}", file=sys.stderr, flush=True)
    return out


def _m(module: str, *args) -> list[str]:
    """The arguments of ``python -m module args...`` (paths and numbers as text)."""
    return ["-m", module, *(str(a) for a in args)]


def run_workflow(
    out: str | Path,
    *,
    backend: str = "sim",
    truth: str = "reference",
    seed: int = 1,
    starts: int = 100,
    quiet: bool = False,
    plan: str = "paper",
    linear_plan: str = "linear",
    lock_dir: str | Path | None = None,
) -> dict:
    """Run the whole paper workflow into folder ``out`` and return its summary.

    ``plan`` and ``linear_plan`` name the stepped-sine and random plans (built-in names or
    plan files); ``lock_dir`` is the device-lock folder of the rig commands. On the simulated
    rig the truth's values are written to ``truth.json`` beside the results (``rig
    reference``): the report and the summary show each calibrated value against them.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log: list[dict] = []
    sim = ["--truth", truth, "--seed", str(seed)] if backend == "sim" else []
    rig_args = [*sim, *(["--lock-dir", str(lock_dir)] if lock_dir is not None else [])]
    lin_run = out / "linear.h5"
    paper_run = out / "paper.h5"
    reference = None
    if backend == "sim":
        reference = out / TRUTH_FILE
        argv = _m("rig", "reference", "--out", reference, "--overwrite", *sim)
        _stage("reference values", argv, log, quiet)
    rig_args = ["--backend", backend, "--overwrite", *rig_args]
    _stage("random test", _m("rig", "linear", linear_plan, "--out", lin_run, *rig_args), log, quiet)
    lin, planning = _linear_stages(out, lin_run, log, quiet)
    argv = _m("rig", "run", plan, "--out", paper_run, *rig_args)
    run = _stage("stepped-sine run", argv, log, quiet)
    title = f"the {truth!r} simulated rig, seed {seed}" if backend == "sim" else "the rig"
    return _nonlinear_stages(
        out, paper_run, lin, planning, run, starts, reference, title, log, quiet
    )


def analyse_runs(
    out: str | Path,
    linear_run: str | Path,
    stepped_run: str | Path,
    *,
    starts: int = 100,
    quiet: bool = False,
    reference: str | Path | None = None,
    title: str = "the rig",
) -> dict:
    """The analysis part of the workflow on a random test and a stepped-sine run already made,
    exactly as :func:`run_workflow` runs it (each stage the ``analysis`` command a user would
    type, writing into ``out``); returns the summary and writes ``workflow.json`` and
    ``summary.md``. ``reference``: a reference file (``truth.json``) the report and the
    summary compare with; no calibration reads it.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log: list[dict] = []
    lin, planning = _linear_stages(out, Path(linear_run), log, quiet)
    return _nonlinear_stages(
        out, Path(stepped_run), lin, planning, {}, starts, reference, title, log, quiet
    )


def _linear_stages(out: Path, linear_run: Path, log: list, quiet: bool) -> tuple[dict, dict]:
    argv = _m("analysis", "calibrate-linear", linear_run, "--out", out / "linear")
    lin = _stage("linear calibration", argv, log, quiet)
    argv = _m("analysis", "plan", "--model", out / "linear" / "calibrated_model.toml", "--top", 5)
    planning = _stage("pretest planning", argv, log, quiet)
    (out / "planning.json").write_text(json.dumps(planning, indent=1))
    return lin, planning


def _nonlinear_stages(
    out, stepped_run, lin, planning, run, starts, reference, title, log, quiet
) -> dict:
    cal_dir = out / "nonlinear"
    linear = out / "linear"
    model = ["--model", linear / "calibrated_model.toml"]
    model += ["--linear-result", linear / "linear_calibration.json"]
    argv = _m("analysis", "calibrate", stepped_run, *model, "--out", cal_dir, "--starts", starts)
    cal = _stage("nonlinear calibration", argv, log, quiet)
    result = str(cal_dir / "calibration.json")
    val = _stage("validation", ["-m", "analysis", "validate", "--result", result], log, quiet)
    ref = [] if reference is None else ["--reference", str(reference)]
    _stage("report", ["-m", "analysis", "report", str(cal_dir), *ref], log, quiet)
    summary = {
        "linear": lin,
        "planning": planning,
        "run": run,
        "calibration": cal,
        "crossval": cal.get("crossval", {}),
        "validation": val,
        "verdict": verdict(cal, val),
        "comparison": _reference_table(out, reference),
        "reference_damping": _reference_damping(reference),
        "stages": log,
    }
    (out / "workflow.json").write_text(json.dumps(summary, indent=1, default=str))
    md = _summary_markdown(summary, title, reference, out)
    (out / "summary.md").write_text(md)
    if not quiet:
        print(md)
    return summary


def verdict(calibration: dict, validation: dict) -> dict:
    """One verdict from the calibration (its fit and its cross-validation folds) and the
    validation, judged by the one threshold every analysis uses: ``misfit`` with the reasons
    (the stated intervals are then not to be trusted), or adequate."""
    from analysis.calibration.uncertainty import ADEQUATE_RMS

    reasons = list(calibration.get("misfit", []))
    chi2 = validation.get("chi2_per_dof")
    if validation and not validation.get("passed", True):
        reasons.append(
            f"the validation at {validation.get('level_n', 0):g} N misfits by "
            f"{chi2**0.5:.3g} x the noise (adequate up to {ADEQUATE_RMS:g})"
        )
    return {"misfit": bool(reasons), "reasons": reasons, "adequate_rms": ADEQUATE_RMS}


def _reference_table(out: Path, reference: str | Path | None) -> dict:
    """Calibrated value, 95 % interval, reference, error and z of every parameter, linear and
    nonlinear, as the report computes them ({} without a reference)."""
    from analysis.report.calibration_report import load_reference, parameter_rows

    if reference is None or not Path(reference).exists():
        return {}
    ref = load_reference(reference)
    table = {}
    for stage, path in (
        ("linear", out / "linear" / "linear_calibration.json"),
        ("nonlinear", out / "nonlinear" / "calibration.json"),
    ):
        doc = json.loads(path.read_text())
        for row in parameter_rows(doc, {}, ref):
            f = row.factor or 1.0
            table[row.name] = {
                "stage": stage,
                "status": row.status or "fitted",
                "value": row.value / f,
                "std": None if row.std is None else row.std / f,
                "interval_95": [
                    None if row.low is None else row.low / f,
                    None if row.high is None else row.high / f,
                ],
                "reference": None if row.reference is None else row.reference / f,
                "error_rel": None if row.error_pct is None else row.error_pct / 100,
                "z": row.z,
                "inside_95": row.inside,
                "unit": row.si_unit,
            }
    return table


def _fmt(x, digits: int = 4) -> str:
    return "" if x is None else f"{x:.{digits}g}"


def _reference_damping(reference: str | Path | None) -> dict:
    from analysis.report.calibration_report import load_reference

    if reference is None or not Path(reference).exists():
        return {}
    return load_reference(reference)["modal_damping"]


def _summary_markdown(s: dict, title: str, reference: str | Path | None, out: Path) -> str:
    def rel(text: str) -> str:  # paths as seen from the summary's folder
        return str(text).replace(f"{Path(out).resolve()}/", "").replace(f"{out}/", "")

    table = _ParameterTable(s.get("comparison") or {})
    lines = [f"# The paper's workflow on {title}", "", "## Verdict", ""]
    lines += _verdict_lines(s)
    lines += _linear_lines(s["linear"], table)
    if table.with_truth:
        inside = [
            r["inside_95"] for r in table.comparison.values() if r.get("inside_95") is not None
        ]
        lines += [
            "",
            f"{sum(inside)} of {len(inside)} truth values lie inside their stated 95 % "
            f"interval ({rel(str(reference))}: the simulated rig's truth, never read by the "
            "calibration).",
        ]
    lines += _planning_lines(s["planning"])
    if s["run"]:
        run = json.dumps(s["run"], indent=1)[:1500]
        lines += ["", "## Stepped-sine run", "", "```", run, "```"]
    lines += _nonlinear_lines(s, table, rel)
    lines += _crossval_lines(s.get("crossval") or {})
    lines += _validation_lines(s["validation"])
    total = sum(st["seconds"] for st in s["stages"])
    lines.append(
        f"Total {total:.0f} s: "
        + ", ".join(f"{st['stage']} {st['seconds']:.0f} s" for st in s["stages"])
    )
    return "\n".join(lines)


def _verdict_lines(s: dict) -> list[str]:
    v = s["verdict"]
    if v["misfit"]:
        return [
            "**The model misfits its data: the stated intervals are not to be trusted.** "
            "The model lacks something the structure does; `python -m analysis diagnose` "
            "looks for what:",
            "",
            *(f"- {why}" for why in v["reasons"]),
        ]
    cal, val = s["calibration"], s["validation"]
    return [
        f"The model fits its data within {v['adequate_rms']:g} x the noise (RMS residual over "
        f"the noise: calibration {cal['chi2_per_dof'] ** 0.5:.3g}, validation at "
        f"{val['level_n']:g} N {val['chi2_per_dof'] ** 0.5:.3g}; no cross-validation fold "
        "misfits): the "
        "stated intervals carry the noise, the misfit and the uncertainty of the values "
        "the calibration holds (linear parameters, modal damping)."
    ]


class _ParameterTable:
    """The parameter tables of the summary: value, interval, and with a truth file the truth,
    the error and the error over sigma; the paper's value last."""

    def __init__(self, comparison: dict) -> None:
        self.comparison = comparison
        self.with_truth = bool(comparison)

    def lines(self, params: dict, std: dict, status: dict, paper: dict) -> list[str]:
        head = "| parameter | status | calibrated | 95 % interval |"
        rule = "|---|---|---|---|"
        if self.with_truth:
            head += " truth | error | error / sigma |"
            rule += "---|---|---|"
        out = [head + " paper |", rule + "---|"]
        for k, value in params.items():
            cells = self._cells(k, value, std.get(k), status.get(k, "fitted"))
            cells.append(_fmt(paper.get(k)))
            out.append("| " + " | ".join(cells) + " |")
        return out

    def _cells(self, k: str, value: float, sd: float | None, status: str) -> list[str]:
        row = self.comparison.get(k, {})
        lo, hi = row.get("interval_95", [None, None]) if row else (None, None)
        if lo is None and sd is not None:
            lo, hi = value - 1.96 * sd, value + 1.96 * sd
        cells = [k, status, _fmt(value), f"{_fmt(lo)} .. {_fmt(hi)}"]
        if self.with_truth:
            err, z = row.get("error_rel"), row.get("z")
            cells += [
                _fmt(row.get("reference")),
                "" if err is None else f"{100 * err:+.2f} %",
                "" if z is None else f"{z:+.2f}",
            ]
        return cells


def _linear_lines(lin: dict, table: _ParameterTable) -> list[str]:
    lines = ["", "## Linear calibration (Table 2)", ""]
    lines += table.lines(
        lin.get("parameters", {}), lin.get("std", {}), lin.get("status", {}), PAPER_LINEAR
    )
    held = lin.get("held", {})
    if held:
        lines += ["", "Not determined by the random test, held at the prior:", ""]
        lines += [f"- **{k}**: {why}" for k, why in held.items()]
    loose = {k: r for k, r in lin.get("undetermined", {}).items() if k not in held}
    if loose:
        rels = ", ".join(f"{k} ({100 * r:.3g} %)" for k, r in loose.items())
        lines += ["", "Fitted, but uncertain (relative 1 sigma above 5 %): " + rels]
    return lines


def _planning_lines(planning: dict) -> list[str]:
    lines = [
        "",
        "## Pretest planning (Table 4)",
        "",
        f"paper's best: {TABLE4_BEST}",
        "",
        "| rank | actuator | levels [N] | range [Hz] | sensors | det(FIM) |",
        "|---|---|---|---|---|---|",
    ]
    for t in planning.get("top", [])[:5]:
        lines.append(
            f"| {t.get('rank')} | {t.get('actuator')} | {t.get('levels_n')} | "
            f"{t.get('range_hz')} | {t.get('sensors')} | {t.get('det', 0):.3g} |"
        )
    return lines


def _nonlinear_lines(s: dict, table: _ParameterTable, rel) -> list[str]:
    cal = s["calibration"]
    lines = ["", "## Nonlinear calibration (Table 5)", ""]
    lines += table.lines(cal["parameters"], cal["std"], {}, PAPER_NONLINEAR)
    refined = cal.get("held_refined") or {}
    if refined:
        truth = {k: row.get("reference") for k, row in table.comparison.items()}
        truth |= {f"zeta_{k}": v for k, v in (s.get("reference_damping") or {}).items()}
        extra_head, extra_rule = (" truth |", "---|") if table.with_truth else ("", "")
        lines += [
            "",
            "Refined jointly with the values it holds (the linear test's posterior as "
            "the prior; the calibrated model file carries these):",
            "",
            "| value | linear test | after the stepped sine | 1 sigma |" + extra_head,
            "|---|---|---|---|" + extra_rule,
        ]
        for k, r in refined.items():
            row = f"| {k} | {_fmt(r.get('start'))} | {_fmt(r['value'])} | {_fmt(r['std'], 3)} |"
            if table.with_truth:
                row += f" {_fmt(truth.get(k))} |"
            lines.append(row)
    noise = ", ".join(f"{k} {_fmt(x, 3)}" for k, x in cal.get("std_noise", {}).items())
    held_from = rel(cal.get("held") or "nowhere (held as exact)")
    lines += [
        "",
        f"chi2/dof {cal['chi2_per_dof']:.3f}; the held values' uncertainty from "
        f"{held_from}; noise-only 1 sigma: {noise}",
    ]
    return lines


def _crossval_lines(cv: dict) -> list[str]:
    if not cv:
        return []
    lines = ["", "## Cross-validation", ""]
    lines += ["| parameter | folds' std / noise-only (FIM^-1) std |", "|---|---|"]
    for n, r in zip(cv["names"], cv["std_ratio"], strict=True):
        lines.append(f"| {n} | {r:.2f} |")
    if cv.get("stuck"):
        lines += [
            "",
            f"{len(cv['stuck'])} fold(s) could not leave the calibrated optimum; "
            "their scatter understates the uncertainty.",
        ]
    if cv.get("notes"):
        lines += ["", *(f"- {note}" for note in cv["notes"])]
    return lines


def _validation_lines(val: dict) -> list[str]:
    return [
        "",
        "## Validation",
        "",
        f"{val['level_n']:g} N: {'PASS' if val['passed'] else 'FAIL'}, chi2/dof "
        f"{val['chi2_per_dof']:.2f} (threshold {val['threshold']:g}), "
        f"{100 * val['within_2sigma']:.0f} % within 2 sigma",
        "",
        "Figures and tables: `nonlinear/report.html`.",
        "",
    ]
