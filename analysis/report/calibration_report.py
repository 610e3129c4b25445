"""One readable report (HTML and Markdown) from a calibration folder's files.

The report only reads what the commands wrote (``calibration.json``, ``crossval.json``,
``validation.json``, ``../linear/linear_calibration.json``, the figures) and, when given, a
reference file (a simulated rig's truth); it never changes a calibrated value. Pages are made
with jinja2 templates (HTML autoescaped); prose a command wrote as Markdown (notes) is rendered
with markdown-it-py with raw HTML disabled. Every number carries its unit (from the result file,
else from the model the calibration used); paths are shown relative to the report's folder.

Reference file layout (``rig reference --out truth.json``)::

    {"source": "simulated rig, truth 'reference'",
     "parameters": {name: value}, "units": {name: unit}, "modal_damping": {mode: zeta}}
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from analysis.report.units import display_unit

__all__ = ["ParameterRow", "load_reference", "parameter_rows", "write_report"]

#: z of a two-sided 95 % interval of a normal distribution.
Z95 = 1.959963984540054

_FIGURES = [
    (
        "calibration_fit.png",
        "Calibration levels: measured (markers) and calibrated model (lines), magnitude per "
        "channel and harmonic order.",
    ),
    (
        "validation.png",
        "Validation at the held-out level: magnitude and phase; measurement with 2-sigma error "
        "bars, prediction with its 2-sigma band from the parameter covariance.",
    ),
]


@dataclass
class ParameterRow:
    """One parameter as a table shows it: values already in the displayed unit.

    ``value``, ``std``, ``std_noise``, ``low``, ``high`` and ``reference`` are multiplied by
    ``factor`` (SI -> displayed unit, e.g. m -> mm); ``error_pct`` and ``z`` are unit-free.
    """

    name: str
    unit: str
    si_unit: str
    factor: float
    value: float
    std: float | None
    std_noise: float | None = None
    low: float | None = None
    high: float | None = None
    interval_source: str = ""
    status: str = ""
    status_note: str = ""
    reference: float | None = None
    reference_note: str = ""
    error_pct: float | None = None
    z: float | None = None
    inside: bool | None = None
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------- reading
def _load(path: Path) -> dict | None:
    if not path.exists():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not readable JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return doc


def _number(x: Any) -> float | None:
    """A finite float, or None (missing, null, NaN, text)."""
    if isinstance(x, bool):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _mapping(doc: dict | None, key: str) -> dict:
    v = (doc or {}).get(key)
    return v if isinstance(v, dict) else {}


def load_reference(path: str | Path) -> dict:
    """Read a reference file; it must have ``parameters`` {name: number}."""
    path = Path(path)
    doc = _load(path)
    if doc is None:
        raise ValueError(f"{path}: no such reference file")
    params = doc.get("parameters")
    if not isinstance(params, dict) or not params:
        raise ValueError(f"{path}: a reference file needs 'parameters' {{name: value}}")
    return {
        "source": str(doc.get("source") or ""),
        "parameters": {str(k): _number(v) for k, v in params.items()},
        "units": {str(k): str(v) for k, v in _mapping(doc, "units").items()},
        "modal_damping": {str(k): _number(v) for k, v in _mapping(doc, "modal_damping").items()},
        "path": path,
    }


def _model_units(doc: dict | None, folder: Path) -> dict[str, str]:
    """Parameter units of the model a calibration used (its ``model_toml``, else a calibrated
    model file beside it); {} when neither can be read."""
    from analysis.model import Model

    texts = []
    if doc and isinstance(doc.get("model_toml"), str):
        texts.append(doc["model_toml"])
    for name in ("calibrated_model.toml",):
        p = folder / name
        if p.exists():
            texts.append(p.read_text())
    for text in texts:
        try:
            model = Model.from_toml_text(text, source=str(folder))
        except Exception:  # noqa: BLE001 - any unreadable model: units left blank
            continue
        return {n: p.unit for n, p in model.parameters.items() if p.unit}
    return {}


# ---------------------------------------------------------------------------------- tables
def parameter_rows(
    doc: dict, model_units: dict[str, str], reference: dict | None = None
) -> list[ParameterRow]:
    """Rows of a parameter table from a calibration result (nonlinear or linear JSON).

    Uses ``parameters`` and ``std`` (required) and the optional ``std_noise``, ``interval_95``,
    ``units``, ``status``, ``status_reason``, ``prior_rel_std``. A held parameter's interval and
    sigma are its prior's (``value * (1 +- 1.96 prior_rel_std)``) unless ``interval_95`` says
    otherwise. With ``reference``: the reference value, the error (relative, %), the error over
    the sigma (z) and whether the reference lies inside the 95 % interval.
    """
    params = doc.get("parameters")
    if not isinstance(params, dict):
        raise ValueError("a calibration result needs 'parameters' {name: value}")
    std = _mapping(doc, "std")
    std_noise = _mapping(doc, "std_noise")
    intervals = _mapping(doc, "interval_95")
    units = _mapping(doc, "units")
    status = _mapping(doc, "status")
    reasons = _mapping(doc, "status_reason")
    prior = _mapping(doc, "prior_rel_std")
    rows = []
    for name, raw in params.items():
        value = _number(raw)
        if value is None:
            continue
        si_unit = str(units.get(name) or model_units.get(name) or "")
        factor, unit = display_unit(si_unit)
        st = str(status.get(name) or "")
        s = _number(std.get(name))
        pr = _number(prior.get(name))
        interval_source = ""
        low = high = None
        iv = intervals.get(name)
        if isinstance(iv, list | tuple) and len(iv) == 2 and None not in map(_number, iv):
            low, high = sorted(_number(x) for x in iv)
            interval_source = "stated"
        if st == "held" and pr is not None:
            s = pr * abs(value)  # the prior is all that is known of a held value
            if low is None:
                low, high = value - Z95 * s, value + Z95 * s
                interval_source = "prior"
        if low is None and s is not None:
            low, high = value - Z95 * s, value + Z95 * s
            interval_source = "value \u00b1 1.96\u03c3"
        note = str(reasons.get(name) or "")
        if st == "held" and pr is not None:
            note = (note + "; " if note else "") + f"prior 1 sigma {100 * pr:.3g} %"
        row = ParameterRow(
            name=str(name),
            unit=unit,
            si_unit=si_unit,
            factor=factor,
            value=value * factor,
            std=None if s is None else s * factor,
            std_noise=(
                None
                if _number(std_noise.get(name)) is None
                else _number(std_noise.get(name)) * factor
            ),
            low=None if low is None else low * factor,
            high=None if high is None else high * factor,
            interval_source=interval_source,
            status=st,
            status_note=note,
        )
        if reference is not None:
            _compare(row, value, s, low, high, reference)
        rows.append(row)
    return rows


def _compare(row: ParameterRow, value, s, low, high, reference: dict) -> None:
    ref = reference["parameters"].get(row.name)
    if ref is None:
        row.reference_note = "not in the reference"
        return
    ref_unit = reference["units"].get(row.name, "")
    if ref_unit and row.si_unit and ref_unit.replace(" ", "") != row.si_unit.replace(" ", ""):
        row.reference_note = f"reference in {ref_unit}, not {row.si_unit}: not compared"
        return
    row.reference = ref * row.factor
    if ref != 0:
        row.error_pct = 100.0 * (value - ref) / abs(ref)
    if s is not None and s > 0:
        row.z = (value - ref) / s
    if low is not None and high is not None:
        row.inside = bool(low <= ref <= high)


def _coverage(tables: list[list[ParameterRow]]) -> dict | None:
    rows = [r for t in tables for r in t if r.inside is not None]
    if not rows:
        return None
    zs = [abs(r.z) for r in rows if r.z is not None]
    return {
        "inside": sum(r.inside for r in rows),
        "n": len(rows),
        "outside": [r.name for r in rows if not r.inside],
        "max_abs_z": max(zs) if zs else None,
    }


# ---------------------------------------------------------------------------------- paths
def _relative(path: str | os.PathLike | None, folder: Path) -> str:
    """``path`` relative to the report's folder (a bare file name when that fails)."""
    if not path:
        return ""
    p = Path(path)
    if not p.is_absolute():
        return p.as_posix()
    try:
        return Path(os.path.relpath(p, folder.resolve())).as_posix()
    except ValueError:  # another drive
        return p.name


# ---------------------------------------------------------------------------------- figures
def _report_figures(folder: Path, cal: dict, cv: dict | None, units: dict) -> list[dict]:
    """Figures drawn from the JSON files (convergence, cross-validation) into
    ``report_files/``, then those the commands wrote; each {src, caption}."""
    import numpy as np

    from analysis.report.calibration_figures import plot_convergence, plot_crossval

    out = folder / "report_files"
    figs = []
    history = _mapping(cal, "lm").get("history") or []
    costs = [_number(h.get("cost")) for h in history if isinstance(h, dict)]
    costs = [c for c in costs if c is not None]
    weighted = _mapping(cal, "settings").get("weighting", "uncertainty") != "identity"
    if costs:
        out.mkdir(exist_ok=True)
        p = plot_convergence(
            costs,
            out / "convergence.png",
            weighted=weighted,
            n_residuals=cal.get("n_residuals"),
        )
        figs.append(
            {
                "src": p,
                "caption": "Levenberg-Marquardt convergence: chi-square of the weighted "
                "residuals (sum of squared residuals over their measurement sigma, "
                "dimensionless) per iteration."
                if weighted
                else "Levenberg-Marquardt convergence: sum of squared residuals per iteration.",
            }
        )
    elif (folder / "convergence.png").exists():
        figs.append(
            {"src": folder / "convergence.png", "caption": "Levenberg-Marquardt convergence."}
        )
    try:
        est = np.array(cv["estimates"], dtype=float) if cv else None
        ok = est is not None and est.ndim == 2 and est.shape[1] == len(cv["names"])
    except (KeyError, TypeError, ValueError):
        ok = False
    if ok:
        out.mkdir(exist_ok=True)
        nan = lambda xs: np.array([np.nan if x is None else x for x in xs], dtype=float)
        p = plot_crossval(
            cv["names"],
            [str(f) for f in cv.get("folds") or range(est.shape[0])],
            est,
            nan(cv["mean"]),
            nan(cv["std"]),
            nan(cv.get("fim_std") or [None] * est.shape[1]),
            out / "crossval.png",
            units=units,
        )
        figs.append(
            {
                "src": p,
                "caption": "Cross-validation: each fold's estimate relative to the mean of the "
                "folds, 1-sigma of the folds (CV) and of the noise alone (FIM\u207b\u00b9).",
            }
        )
    elif (folder / "crossval.png").exists():
        figs.append({"src": folder / "crossval.png", "caption": "Cross-validation."})
    for name, caption in _FIGURES:
        if (folder / name).exists():
            figs.append({"src": folder / name, "caption": caption})
    for f in figs:
        f["src"] = _relative(Path(f["src"]).resolve(), folder)
    return figs


# ---------------------------------------------------------------------------------- report
def _crossval_rows(cv: dict, units: dict) -> list[dict]:
    rows = []
    names = cv.get("names") or []
    for j, n in enumerate(names):
        factor, unit = display_unit(units.get(n, ""))

        def at(key, scale=True, j=j, factor=factor):
            xs = cv.get(key) or []
            v = _number(xs[j]) if j < len(xs) else None
            return None if v is None else (v * factor if scale else v)

        rows.append(
            {
                "name": n,
                "unit": unit,
                "mean": at("mean"),
                "std": at("std"),
                "fim_std": at("fim_std"),
                "ratio": at("std_ratio", scale=False),
            }
        )
    return rows


def _fold_rows(cv: dict) -> list[dict]:
    folds, chi2, p = cv.get("folds"), cv.get("fold_chi2"), cv.get("fold_p")
    share = cv.get("information_share")
    if not (folds and chi2 and p and share):
        return []
    return [
        {"fold": f, "chi2": _number(c), "p": _number(q), "share": [_number(x) for x in s or []]}
        for f, c, q, s in zip(folds, chi2, p, share, strict=False)
    ]


def _notes(x) -> list[str]:
    if isinstance(x, str):
        return [x]
    return [str(n) for n in x] if isinstance(x, list) else []


def _uncertainty(doc: dict) -> dict | None:
    u = doc.get("uncertainty")
    if not isinstance(u, dict) or not u:
        return None
    fields = []
    for k, v in u.items():
        if k == "notes" or v is None or isinstance(v, dict | list):
            continue
        if isinstance(v, float):
            v = f"{v:.4g}"
        fields.append((str(k).replace("_", " "), str(v)))
    return {"fields": fields, "notes": _notes(u.get("notes"))}


def _modal_damping(lin: dict | None, reference: dict | None) -> list[dict]:
    """Identified modal damping ratios per mode (``damping_per_mode``), with the reference's."""
    rows = []
    for mode, v in _mapping(lin, "damping_per_mode").items():
        zeta = _number(v.get("zeta") if isinstance(v, dict) else v)
        if zeta is None:
            continue
        ref = (reference or {}).get("modal_damping", {}).get(str(mode))
        rows.append(
            {
                "mode": mode,
                "zeta": zeta,
                "reference": ref,
                "error_pct": None if not ref else 100 * (zeta - ref) / abs(ref),
            }
        )
    return rows


def build_context(folder: str | Path, reference: str | Path | dict | None = None) -> dict:
    """Everything the report shows, read from ``folder`` (and ``reference``)."""
    folder = Path(folder)
    cal = _load(folder / "calibration.json")
    if cal is None:
        raise ValueError(f"{folder}: no calibration.json (run 'calibrate' first)")
    for key in ("parameters", "std"):
        if not isinstance(cal.get(key), dict):
            raise ValueError(f"{folder / 'calibration.json'}: no '{key}'")
    if reference is not None and not isinstance(reference, dict):
        reference = load_reference(reference)
    lin_path = folder.parent / "linear" / "linear_calibration.json"
    lin = _load(lin_path)
    units = _model_units(cal, folder)
    lin_units = {**units, **_model_units(lin, lin_path.parent)}
    nl_rows = parameter_rows(cal, units, reference)
    lin_rows = parameter_rows(lin, lin_units, reference) if lin and "parameters" in lin else []
    all_units = {**lin_units, **{r.name: r.si_unit for r in nl_rows if r.si_unit}}
    cv = _load(folder / "crossval.json")
    val = _load(folder / "validation.json")
    lm = _mapping(cal, "lm")
    ctx = {
        "folder": folder.resolve().name,
        "measurement_file": _relative(cal.get("measurement_file"), folder),
        "model_source": _relative(cal.get("model_source"), folder)
        if cal.get("model_source") and os.path.isabs(str(cal.get("model_source")))
        else str(cal.get("model_source") or ""),
        "calibration_levels": cal.get("calibration_levels_n") or [],
        "validation_level": _number(cal.get("validation_level_n")),
        "chi2_per_dof": _number(cal.get("chi2_per_dof")),
        "n_residuals": cal.get("n_residuals"),
        "weighting": _mapping(cal, "settings").get("weighting"),
        "lm": {"nit": lm.get("nit"), "message": lm.get("message"), "success": lm.get("success")},
        "nonlinear": nl_rows,
        "has_noise_std": any(r.std_noise is not None for r in nl_rows),
        "uncertainty": _uncertainty(cal),
        "linear": lin_rows,
        "linear_file": _relative(lin_path.resolve(), folder) if lin else "",
        "linear_has_status": any(r.status for r in lin_rows),
        "linear_notes": [
            f"{k}: relative 1 sigma {100 * v:.3g} % (not determined by the random test)"
            for k, v in _mapping(lin, "undetermined").items()
            if _number(v) is not None
        ],
        "modal_damping": _modal_damping(lin, reference),
        "misfit": [str(m) for m in cal.get("misfit") or []],
        "adequate_rms": _number(cal.get("adequate_rms")),
        "reference": None,
        "crossval": None,
        "validation": None,
    }
    if reference is not None:
        ctx["reference"] = {
            "source": reference.get("source", ""),
            "file": _relative(Path(reference["path"]).resolve(), folder)
            if reference.get("path")
            else "",
            "coverage": _coverage([lin_rows, nl_rows]),
        }
    if cv:
        ctx["crossval"] = {
            "rows": _crossval_rows(cv, all_units),
            "folds": _fold_rows(cv),
            "names": cv.get("names") or [],
            "notes": _notes(cv.get("notes")),
            "stuck": _notes(cv.get("stuck")),
            "n_folds": len(cv.get("folds") or []),
        }
    if val:
        ctx["validation"] = {
            "level": _number(val.get("level_n")),
            "passed": bool(val.get("passed")),
            "chi2_per_dof": _number(val.get("chi2_per_dof")),
            "threshold": _number(val.get("threshold")),
            "within_2sigma": _number(val.get("within_2sigma")),
            "n_steps": val.get("n_steps"),
            "channels": val.get("channels") or [],
        }
    ctx["figures"] = _report_figures(folder, cal, cv, all_units)
    ctx["inputs"] = [
        _relative((folder / n).resolve(), folder)
        for n in ("calibration.json", "crossval.json", "validation.json")
        if (folder / n).exists()
    ] + ([ctx["linear_file"]] if lin else [])
    return ctx


def write_report(folder: str | Path, reference: str | Path | None = None) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` into ``folder`` from what it contains.

    Parameters
    ----------
    folder : path
        A folder written by ``calibrate`` (and ``crossval``, ``validate``); the linear
        calibration is read from ``../linear/linear_calibration.json`` when present.
    reference : path, optional
        A reference file (e.g. a simulated rig's ``truth.json``): every parameter table then
        shows the reference value, the error, the error over sigma (z) and whether the
        reference lies inside the stated 95 % interval.
    """
    from analysis.report.templates import render_html, render_markdown

    folder = Path(folder)
    ctx = build_context(folder, reference)
    hp = folder / "report.html"
    hp.write_text(render_html(ctx), encoding="utf-8")
    md = folder / "report.md"
    md.write_text(render_markdown(ctx), encoding="utf-8")
    return {"html": hp, "markdown": md}
