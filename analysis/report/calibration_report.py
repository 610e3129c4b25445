"""One readable report (HTML and Markdown) from a calibration folder's files."""

from __future__ import annotations

import html
import json
from pathlib import Path

__all__ = ["write_report"]

#: The reference paper's published values, for the side-by-side tables.
PAPER = {
    "table2": {
        "E_frame": 205e9,
        "E_corner": 128e9,
        "E_beam": 201e9,
        "rho_corner": 5175.0,
        "k_mount": 57989.0,
    },
    "table5": {"k_c": 4.51e5, "gap": 0.61e-3, "v_c": 25.21},
}
_FIGURES = [
    ("calibration_fit.png", "Calibration levels: measured vs calibrated model"),
    ("convergence.png", "Levenberg-Marquardt convergence"),
    ("crossval.png", "Cross-validation: fold estimates with CV and FIM^-1 standard deviations"),
    ("validation.png", "Validation at the held-out level with 2-sigma bands"),
]


def _load(folder: Path, name: str) -> dict | None:
    p = folder / name
    return json.loads(p.read_text()) if p.exists() else None


def write_report(folder: Path) -> dict[str, Path]:
    """Write ``report.md`` and ``report.html`` into ``folder`` from what it contains."""
    folder = Path(folder)
    cal = _load(folder, "calibration.json")
    if cal is None:
        raise ValueError(f"{folder}: no calibration.json (run 'calibrate' first)")
    cv = _load(folder, "crossval.json")
    val = _load(folder, "validation.json")
    lines = ["# Calibration report", ""]
    lines += [
        f"Measurement file: `{cal.get('measurement_file', '')}`",
        f"Calibration levels: {cal['calibration_levels_n']} N; held out: "
        f"{cal['validation_level_n']} N",
        "",
    ]
    lines += ["| parameter | calibrated | 1 sigma | paper (Table 5) |", "|---|---|---|---|"]
    for n, v in cal["parameters"].items():
        ref = PAPER["table5"].get(n)
        lines.append(
            f"| {n} | {v:.5g} | {cal['std'][n]:.3g} | {'' if ref is None else f'{ref:.4g}'} |"
        )
    lines += [
        "",
        f"chi2 per degree of freedom: {cal['chi2_per_dof']:.3f}; LM: "
        f"{cal['lm']['nit']} iterations, {cal['lm']['message']}",
        "",
    ]
    if cv:
        lines += [
            "## Cross-validation",
            "",
            "| parameter | CV mean | CV std | FIM^-1 std | ratio |",
            "|---|---|---|---|---|",
        ]
        for j, n in enumerate(cv["names"]):
            lines.append(
                f"| {n} | {cv['mean'][j]:.5g} | {cv['std'][j]:.3g} | "
                f"{cv['fim_std'][j]:.3g} | {cv['std_ratio'][j]:.2f} |"
            )
        lines.append("")
        lines += [f"- {note}" for note in cv.get("notes") or []]
        if cv.get("fold_chi2") is not None:
            names = " | ".join(f"share of {n}" for n in cv["names"])
            lines += [
                "",
                f"| fold left out | chi2/value at the optimum | p (noise only) | {names} |",
                "|---|---|---|" + "---|" * len(cv["names"]),
            ]
            for f, c, p, share in zip(cv["folds"], cv["fold_chi2"], cv["fold_p"],
                                      cv["information_share"], strict=True):  # fmt: skip
                shares = " | ".join(f"{100 * x:.0f} %" for x in share)
                c_text = "" if c is None else f"{c:.2f}"
                p_text = "" if p is None else f"{p:.2g}"
                lines.append(f"| {f} | {c_text} | {p_text} | {shares} |")
            lines.append("")
    if val:
        verdict = "PASS" if val["passed"] else "FAIL"
        lines += [
            "## Validation",
            "",
            f"{val['level_n']:g} N: **{verdict}**, chi2/dof "
            f"{val['chi2_per_dof']:.2f} (threshold {val['threshold']:g}), "
            f"{100 * val['within_2sigma']:.0f} % within 2 sigma",
            "",
        ]
    figs = [(f, t) for f, t in _FIGURES if (folder / f).exists()]
    for f, t in figs:
        lines += [f"## {t}", "", f"![{t}]({f})", ""]
    md = folder / "report.md"
    md.write_text("\n".join(lines))
    body = []
    for line in lines:
        if line.startswith("# "):
            body.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line.startswith("## "):
            body.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.startswith("!["):
            src = line[line.index("(") + 1 : -1]
            body.append(f'<img src="{html.escape(src)}" style="max-width:100%">')
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set("".join(cells)) <= set("-"):
                continue
            body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
        elif line:
            body.append(f"<p>{html.escape(line)}</p>")
    page = "\n".join(body).replace("</p>\n<tr>", "</p>\n<table border=1 cellpadding=4><tr>")
    page = page.replace("</tr>\n<h2>", "</tr></table>\n<h2>").replace(
        "</tr>\n<p>", "</tr></table>\n<p>"
    )
    hp = folder / "report.html"
    hp.write_text(
        f"<!doctype html><meta charset=utf-8><title>Calibration report</title>"
        f"<body style='font-family:sans-serif;max-width:1200px'>{page}</body>"
    )
    return {"markdown": md, "html": hp}
