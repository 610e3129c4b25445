"""The paper's whole workflow on a backend, as a lab would run it: ``python -m rig workflow``.

Each stage is the command a user would type, run in a child process and writing its own files
into one folder, so the folder documents the study and any stage can be repeated by hand:

1. ``rig linear``                 random test, all 13 points, low level (gap open)
2. ``analysis calibrate-linear`` damping-equalized linear calibration, modal damping
3. ``analysis plan``             FIM pretest planning of the nonlinear test
4. ``rig run paper``             stepped multi-sine under force control, 2/4/6/8 N
5. ``analysis calibrate``        Latin hypercube + Levenberg-Marquardt on 2/4/6 N
6. ``analysis crossval``         9-fold cross-validation
7. ``analysis validate``         prediction of 8 N with uncertainty bands
8. ``analysis report``           figures and tables; ``summary.md`` compares with the paper
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["run_workflow"]

PAPER_TABLE2 = {
    "E_frame": 205e9,
    "E_corner": 128e9,
    "E_beam": 201e9,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
}
PAPER_TABLE5 = {"k_c": 4.51e5, "gap": 0.61e-3, "v_c": 25.21}
PAPER_TABLE4_TOP = "actuator 3, levels [2, 4, 6] N, range [21-40] Hz, sensors [4, 6, 7]"


class StageError(RuntimeError):
    """A workflow stage failed; the message names it and quotes its error output."""


def _stage(name: str, argv: list[str], log: list[dict], quiet: bool) -> dict:
    t0 = time.perf_counter()
    if not quiet:
        print(f"== {name}: {' '.join(argv[2:])}", file=sys.stderr, flush=True)
    r = subprocess.run([sys.executable, *argv, "--json"], capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        tail = r.stderr.strip()[-2000:]
        raise StageError(f"stage '{name}' failed (exit {r.returncode}):\n{tail}")
    lines = [ln for ln in r.stdout.strip().splitlines() if ln.startswith("{")]
    out = json.loads(lines[-1]) if lines else {}
    log.append({"stage": name, "seconds": round(dt, 2), "argv": argv})
    if not quiet:
        print(f"   done in {dt:.1f} s", file=sys.stderr, flush=True)
    return out


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
    plan files); ``lock_dir`` is the device-lock folder of the rig commands.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log: list[dict] = []
    sim = ["--truth", truth, "--seed", str(seed)] if backend == "sim" else []
    if lock_dir is not None:
        sim += ["--lock-dir", str(lock_dir)]
    lin_run = out / "linear.h5"
    paper_run = out / "paper.h5"
    _stage(
        "random test",
        [
            "-m",
            "rig",
            "linear",
            str(linear_plan),
            "--backend",
            backend,
            "--out",
            str(lin_run),
            "--overwrite",
            "--quiet",
            *sim,
        ],
        log,
        quiet,
    )
    lin = _stage(
        "linear calibration",
        ["-m", "analysis", "calibrate-linear", str(lin_run), "--out", str(out / "linear")],
        log,
        quiet,
    )
    lin_model = out / "linear" / "calibrated_model.toml"
    planning = _stage(
        "pretest planning",
        ["-m", "analysis", "plan", "--model", str(lin_model), "--top", "5"],
        log,
        quiet,
    )
    (out / "planning.json").write_text(json.dumps(planning, indent=1))
    run = _stage(
        "stepped-sine run",
        [
            "-m",
            "rig",
            "run",
            str(plan),
            "--backend",
            backend,
            "--out",
            str(paper_run),
            "--overwrite",
            "--quiet",
            *sim,
        ],
        log,
        quiet,
    )
    cal_dir = out / "nonlinear"
    cal = _stage(
        "nonlinear calibration",
        [
            "-m",
            "analysis",
            "calibrate",
            str(paper_run),
            "--model",
            str(lin_model),
            "--out",
            str(cal_dir),
            "--starts",
            str(starts),
        ],
        log,
        quiet,
    )
    result = str(cal_dir / "calibration.json")
    cv = _stage("cross-validation", ["-m", "analysis", "crossval", "--result", result], log, quiet)
    val = _stage("validation", ["-m", "analysis", "validate", "--result", result], log, quiet)
    _stage("report", ["-m", "analysis", "report", str(cal_dir)], log, quiet)
    summary = {
        "linear": lin,
        "planning": planning,
        "run": run,
        "calibration": cal,
        "crossval": cv,
        "validation": val,
        "stages": log,
    }
    (out / "workflow.json").write_text(json.dumps(summary, indent=1, default=str))
    md = _summary_markdown(summary, truth)
    (out / "summary.md").write_text(md)
    if not quiet:
        print(md)
    return summary


def _summary_markdown(s: dict, truth: str) -> str:
    lin = s["linear"].get("parameters", {})
    lin_std = s["linear"].get("std", {})
    undetermined = s["linear"].get("undetermined", {})
    cal = s["calibration"]["parameters"]
    std = s["calibration"]["std"]
    lines = [
        f"# The paper's workflow on the {truth!r} rig",
        "",
        "## Linear calibration (Table 2)",
        "",
        "| parameter | calibrated | 1 sigma | paper (Table 2) |",
        "|---|---|---|---|",
    ]
    for k, ref in PAPER_TABLE2.items():
        v, sd = lin.get(k), lin_std.get(k)
        lines.append(f"| {k} | {'' if v is None else f'{v:.4g}'} | "
                     f"{'' if sd is None else f'{sd:.2g}'} | {ref:.4g} |")  # fmt: skip
    if undetermined:
        lines += [
            "",
            "Not determined by the random test (relative 1 sigma above 5 %): "
            + ", ".join(f"{k} ({100 * r:.3g} %)" for k, r in undetermined.items())
            + "; `linear/linear_calibration.json` lists the model modes they act on that the "
            "test did not identify (`unidentified_modes`).",
        ]
    top = s["planning"].get("top", [])
    lines += [
        "",
        "## Pretest planning (Table 4)",
        "",
        f"paper's best: {PAPER_TABLE4_TOP}",
        "",
        "| rank | actuator | levels [N] | range [Hz] | sensors | det(FIM) |",
        "|---|---|---|---|---|---|",
    ]
    for t in top[:5]:
        lines.append(
            f"| {t.get('rank')} | {t.get('actuator')} | {t.get('levels_n')} | "
            f"{t.get('range_hz')} | {t.get('sensors')} | {t.get('det', 0):.3g} |"
        )
    run = s["run"]
    lines += [
        "",
        "## Stepped-sine run",
        "",
        "```",
        json.dumps(run, indent=1)[:1500],
        "```",
        "",
        "## Nonlinear calibration (Table 5)",
        "",
        "| parameter | calibrated | 1 sigma | paper (Table 5) |",
        "|---|---|---|---|",
    ]
    for k, ref in PAPER_TABLE5.items():
        lines.append(f"| {k} | {cal[k]:.4g} | {std[k]:.2g} | {ref:.4g} |")
    cv = s["crossval"]
    lines += ["", "## Cross-validation", "", "| parameter | CV std / FIM^-1 std |", "|---|---|"]
    for n, r in zip(cv["names"], cv["std_ratio"], strict=True):
        lines.append(f"| {n} | {r:.2f} |")
    if cv.get("stuck"):
        lines += ["", f"Warning: {len(cv['stuck'])} fold(s) could not leave the calibrated "
                  "optimum; the standard deviations understate the uncertainty."]  # fmt: skip
    if cv.get("notes"):
        lines += ["", *(f"- {note}" for note in cv["notes"])]
    v = s["validation"]
    lines += [
        "",
        "## Validation",
        "",
        f"{v['level_n']:g} N: {'PASS' if v['passed'] else 'FAIL'}, chi2/dof "
        f"{v['chi2_per_dof']:.2f}, {100 * v['within_2sigma']:.0f} % within 2 sigma",
        "",
        "Figures and tables: `nonlinear/report.html`.",
        "",
    ]
    total = sum(st["seconds"] for st in s["stages"])
    lines.append(
        f"Total {total:.0f} s: "
        + ", ".join(f"{st['stage']} {st['seconds']:.0f} s" for st in s["stages"])
    )
    return "\n".join(lines)
