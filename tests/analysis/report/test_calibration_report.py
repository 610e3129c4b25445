"""The calibration report from a small synthetic calibration folder: well-formed HTML, units,
relative paths, and the reference columns (``--reference``) without changing any number."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from analysis.calibration.cli import cmd_report
from analysis.model import load_model
from analysis.report import plot_validation

NL = {"k_c": 4.62e5, "gap": 6.3e-4, "v_c": 24.0}
NL_STD = {"k_c": 1.1e4, "gap": 1.0e-5, "v_c": 1.5}
LIN = {"E_frame": 2.04e11, "E_corner": 1.30e11, "k_mount": 5.0e4, "rho_corner": 5200.0}
LIN_STD = {"E_frame": 1.0e9, "E_corner": 2.0e10, "k_mount": 1.0e2, "rho_corner": 40.0}
TRUTH = {
    "E_frame": 2.05e11,
    "E_corner": 1.28e11,
    "E_beam": 2.01e11,
    "rho_corner": 5175.0,
    "k_mount": 57989.0,
    "k_c": 4.51e5,
    "gap": 6.0e-4,
    "v_c": 25.21,
}
TRUTH_UNITS = {
    "E_frame": "Pa",
    "E_corner": "Pa",
    "E_beam": "Pa",
    "rho_corner": "kg/m^3",
    "k_mount": "N/m",
    "k_c": "N/m^1.5",
    "gap": "m",
    "v_c": "N s^2/m^2",
}


@pytest.fixture
def study(tmp_path: Path) -> Path:
    """A workflow-like folder: linear/, nonlinear/ (calibration, crossval, validation) and a
    truth.json beside them; the nonlinear result has no 'units' (they come from its model)."""
    lin_dir, nl_dir = tmp_path / "linear", tmp_path / "nonlinear"
    lin_dir.mkdir()
    nl_dir.mkdir()
    (tmp_path / "paper.h5").write_bytes(b"")
    cal = {
        "parameters": NL,
        "std": NL_STD,
        "std_noise": {"k_c": 6.0e3, "gap": 5.0e-6, "v_c": 0.8},
        "interval_95": {"k_c": [4.40e5, 4.84e5]},
        "uncertainty": {
            "estimator": "FIM^-1 scaled by the **cross-validation** spread",
            "inflation": 1.8,
            "notes": ["`gap` and `k_c` are correlated (rho = 0.9)", "*two* folds stuck"],
        },
        "names": list(NL),
        "chi2_per_dof": 1.23,
        "n_residuals": 1500,
        "calibration_levels_n": [2.0, 4.0, 6.0],
        "validation_level_n": 8.0,
        "settings": {"weighting": "uncertainty"},
        "lm": {
            "nit": 3,
            "message": "converged (relative cost decrease below ftol)",
            "success": True,
            "history": [{"iteration": i, "cost": c} for i, c in enumerate([9e3, 2e3, 950, 930])],
        },
        "measurement_file": str((tmp_path / "paper.h5").resolve()),
        "model_source": str((lin_dir / "calibrated_model.toml").resolve()),
        "model_toml": load_model().to_toml(),
    }
    (nl_dir / "calibration.json").write_text(json.dumps(cal))
    folds = [f"{lv} N, part {i}" for lv in (2, 4, 6) for i in (1, 2)]
    rng = np.random.default_rng(1)
    est = np.array(list(NL.values())) * (1 + 0.01 * rng.standard_normal((len(folds), 3)))
    cv = {
        "names": list(NL),
        "folds": folds,
        "estimates": est.tolist(),
        "mean": est.mean(0).tolist(),
        "std": est.std(0).tolist(),
        "fim_std": [6.0e3, 5.0e-6, 0.8],
        "std_ratio": [1.2, 0.9, None],
        "stuck": [],
        "fold_chi2": [1.1, 0.9, 1.3, 1.0, 1.2, None],
        "fold_p": [0.2, 0.6, 0.01, 0.5, 0.1, None],
        "information_share": [[0.1, 0.2, 0.3]] * len(folds),
        "notes": ["the `v_c` spread is **within** the noise"],
    }
    (nl_dir / "crossval.json").write_text(json.dumps(cv))
    val = {
        "level_n": 8.0,
        "channels": ["point 7"],
        "chi2_per_dof": 1.4,
        "within_2sigma": 0.93,
        "threshold": 2.0,
        "passed": True,
        "n_steps": 2,
    }
    (nl_dir / "validation.json").write_text(json.dumps(val))
    H = np.array([1 + 1j, 2 - 1j]).reshape(2, 1, 1)
    plot_validation(
        np.array([25.0, 26.0]),
        H,
        0.1 * abs(H),
        H,
        0.05 * abs(H),
        ["point 7"],
        ["1"],
        nl_dir / "validation.png",
    )
    lin = {
        "parameters": LIN,
        "std": LIN_STD,
        "status": {
            "E_frame": "fitted",
            "E_corner": "held",
            "k_mount": "at_bound",
            "rho_corner": "fitted",
        },
        "status_reason": {
            "E_corner": "no identified mode is sensitive to it",
            "k_mount": "at the upper bound 5e4 N/m",
        },
        "prior_rel_std": {"E_corner": 0.1},
        "units": {"E_frame": "Pa", "E_corner": "Pa", "k_mount": "N/m", "rho_corner": "kg/m^3"},
        "damping_per_mode": {"1": 0.041, "2": 0.035},
    }
    (lin_dir / "linear_calibration.json").write_text(json.dumps(lin))
    doc = {
        "source": "simulated rig, truth 'reference'",
        "parameters": TRUTH,
        "units": TRUTH_UNITS,
        "modal_damping": {"1": 0.04, "2": 0.04},
    }
    (tmp_path / "truth.json").write_text(json.dumps(doc))
    return tmp_path


class _Page(HTMLParser):
    """Tables (header and body rows as cell texts), text outside code, images, well-formedness."""

    VOID = {"meta", "img", "br", "hr", "link", "input", "col", "source", "wbr"}

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.tables: list[dict] = []
        self.text: list[str] = []
        self.images: list[str] = []
        self._cell: list[str] | None = None
        self._row: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs).get("src", ""))
        if tag in self.VOID:
            return
        if tag == "table":
            self.tables.append({"thead": [], "tbody": [], "caption": "", "loose_rows": 0})
        if tag == "tr":
            if not self.tables or not {"thead", "tbody"} & set(self.stack[-1:]):
                self.errors.append("a <tr> outside thead/tbody")
            self._row = []
        if tag in ("td", "th"):
            self._cell = []
        self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in self.VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag in ("td", "th") and self._row is not None:
            self._row.append(" ".join("".join(self._cell).split()))
            self._cell = None
        if tag == "tr":
            section = "thead" if "thead" in self.stack else "tbody"
            self.tables[-1][section].append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if "caption" in self.stack and self.tables:
            self.tables[-1]["caption"] += data
        if "code" not in self.stack and "style" not in self.stack:
            self.text.append(data)


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text())
    page.close()
    assert not page.errors, page.errors
    assert page.stack == [], f"unclosed: {page.stack}"
    return page


def _table(page: _Page, caption_word: str) -> list[dict]:
    (t,) = [t for t in page.tables if caption_word in t["caption"]]
    assert len(t["thead"]) == 1 and t["tbody"], t
    head = t["thead"][0]
    for row in t["tbody"]:
        assert len(row) == len(head), (head, row)
    return [dict(zip(head, row, strict=True)) for row in t["tbody"]]


def _report(folder: Path, reference: Path | None) -> _Page:
    class Args:
        json = True

    args = Args()
    args.folder, args.reference = (
        str(folder / "nonlinear"),
        None if reference is None else str(reference),
    )
    out = cmd_report(args)
    return _parse(Path(out["html"]))


def _number(text: str) -> float:
    """A displayed number back to float ('4.620 × 10^5' is shown as '4.620 × 105')."""
    text = text.replace("\u2212", "-").replace("\u202f", " ")
    m = re.fullmatch(r"(-?[0-9.]+)(?: × 10(-?\d+))?", text.strip())
    assert m, text
    return float(m.group(1)) * (10 ** int(m.group(2)) if m.group(2) else 1)


def test_report_html_is_well_formed_with_units_and_relative_paths(study: Path):
    page = _report(study, None)
    html_text = (study / "nonlinear" / "report.html").read_text()
    assert len(page.tables) >= 4
    for t in page.tables:
        assert t["thead"] and t["tbody"], t["caption"]
    text = " ".join(page.text)
    assert "**" not in text and "`" not in text, "literal markdown in the page"
    assert "<strong>cross-validation</strong>" in html_text  # rendered, not shown
    for src in page.images:
        assert src and not Path(src).is_absolute()
        assert (study / "nonlinear" / src).is_file(), src
    assert len(page.images) == 3  # convergence, cross-validation (drawn), validation
    assert str(study) not in html_text and "/tmp/" not in html_text
    assert "../paper.h5" in html_text
    nl = _table(page, "Contact parameters")
    units = {r["parameter"]: r["unit"] for r in nl}
    assert units == {"k_c": "N/m1.5", "gap": "mm", "v_c": "N s2/m2"}  # from the model
    assert "reference" not in " ".join(nl[0])
    gap = {r["parameter"]: r for r in nl}["gap"]
    assert _number(gap["calibrated"]) == pytest.approx(0.63)  # shown in mm
    lin = _table(page, "Linear parameters")
    by = {r["parameter"]: r for r in lin}
    assert by["E_frame"]["unit"] == "GPa" and by["k_mount"]["unit"] == "N/m"
    assert by["E_corner"]["status"].startswith("held")
    assert "no identified mode" in by["E_corner"]["status"]
    assert "(prior)" in by["E_corner"]["1σ"]
    lo, hi = (
        _number(x) for x in by["E_corner"]["95 % interval"].split("(")[0].strip(" []").split(",")
    )
    assert (lo, hi) == pytest.approx((130 * (1 - 1.96 * 0.1), 130 * (1 + 1.96 * 0.1)), rel=1e-3)
    assert by["k_mount"]["status"].startswith("at bound")
    cv = _table(page, "cross-validation")
    assert {r["parameter"]: r["unit"] for r in cv}["gap"] == "mm"
    md = (study / "nonlinear" / "report.md").read_text()
    assert "| gap | mm |" in md and "/tmp/" not in md


def test_reference_columns_z_values_and_unchanged_numbers(study: Path):
    plain = _report(study, None)
    plain_nl = _table(plain, "Contact parameters")
    plain_lin = _table(plain, "Linear parameters")
    page = _report(study, study / "truth.json")
    nl = _table(page, "Contact parameters")
    lin = _table(page, "Linear parameters")
    extra = ["reference", "error [%]", "z = error/σ", "reference inside 95 %"]
    for table in (nl, lin):
        assert list(table[0])[-4:] == extra
    for table in (plain_nl, plain_lin):
        assert not set(extra) & set(table[0])
    for before, after in ((plain_nl, nl), (plain_lin, lin)):  # the numbers are the same
        for b, a in zip(before, after, strict=True):
            for col in b:
                assert a[col] == b[col], (col, a, b)
    by = {r["parameter"]: r for r in nl}
    for name in NL:
        z = (NL[name] - TRUTH[name]) / NL_STD[name]
        assert float(by[name]["z = error/σ"].replace("\u2212", "-")) == pytest.approx(z, abs=0.006)
        err = 100 * (NL[name] - TRUTH[name]) / TRUTH[name]
        assert float(by[name]["error [%]"].replace("\u2212", "-")) == pytest.approx(err, rel=1e-2)
    # k_c's stated interval [4.40e5, 4.84e5] holds 4.51e5; gap 0.63 +- 0.0196 mm misses 0.60
    assert by["k_c"]["reference inside 95 %"] == "yes"
    assert by["gap"]["reference inside 95 %"] == "no"
    assert _number(by["gap"]["reference"]) == pytest.approx(0.6)
    lby = {r["parameter"]: r for r in lin}
    # held: sigma is the prior's (10 % of 130 GPa)
    z = (LIN["E_corner"] - TRUTH["E_corner"]) / (0.1 * LIN["E_corner"])
    assert float(lby["E_corner"]["z = error/σ"].replace("\u2212", "-")) == pytest.approx(
        z, abs=0.006
    )
    text = " ".join(page.text)
    assert "simulated rig, truth 'reference'" in text
    assert "<code>../truth.json</code>" in (study / "nonlinear" / "report.html").read_text()
    assert "5 of 7 reference values inside the stated 95 % intervals (outside: k_mount, gap)" in (
        " ".join(text.split())
    )


def test_reference_needs_parameters(study: Path, tmp_path: Path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"source": "x"}))
    with pytest.raises(ValueError, match="parameters"):
        _report(study, bad)
