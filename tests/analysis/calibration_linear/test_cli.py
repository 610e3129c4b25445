"""The calibrate-linear command on a synthetic run."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from analysis.calibration.linear.cli import MODEL_FILE, RESULT_FILE, add_parser
from analysis.model import load_model
from tests.analysis.calibration_linear.synthetic import TRUE_VALUES


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="analysis")
    add_parser(p.add_subparsers(dest="command", required=True))
    return p


def test_calibrate_linear_command(clean_run: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    args = _parser().parse_args(["calibrate-linear", str(clean_run), "--out", str(out)])
    doc = args.func(args)
    printed = capsys.readouterr().out
    assert "k_mount" in printed and "validation rms log10 deviation" in printed
    assert json.loads((out / RESULT_FILE).read_text())["parameters"] == doc["parameters"]
    model = load_model(out / MODEL_FILE)
    for name, value in TRUE_VALUES.items():
        assert model.parameters[name].value == pytest.approx(value, rel=5e-3)
    assert sorted(model.damping.per_mode) == list(range(1, 8))


def test_calibrate_linear_options(clean_run: Path, tmp_path: Path, capsys) -> None:
    argv = [
        "calibrate-linear",
        str(clean_run),
        "--out",
        str(tmp_path),
        "--json",
        "--points",
        "1,2,3,4,5,6,7,9,10",
        "--parameters",
        "E_beam,k_mount",
        "--band",
        "5,200",
        "--zeta0",
        "0.01",
    ]
    args = _parser().parse_args(argv)
    doc = args.func(args)
    assert capsys.readouterr().out == ""  # the caller prints the JSON
    assert doc["names"] == ["E_beam", "k_mount"]
    assert doc["calibration_points"] == [1, 2, 3, 4, 5, 6, 7, 9, 10]
    assert doc["zeta0"] == 0.01
    assert len(doc["identified_modes"]["modes"]) == 5  # 5-200 Hz
    assert json.dumps(doc)


def test_bad_option_values(clean_run: Path, tmp_path: Path) -> None:
    args = _parser().parse_args(
        ["calibrate-linear", str(clean_run), "--out", str(tmp_path), "--band", "5"]
    )
    with pytest.raises(ValueError, match="--band"):
        args.func(args)
