"""``python -m analysis continuation`` on any model file: outputs, units and input errors."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from analysis.cli import main

DUFFING = str(Path(__file__).resolve().parents[2] / "examples" / "duffing.toml")
ONE_HARMONIC = ["--force-orders", "1", "--amplitudes", "0.1", "--H", "1", "--N", "16"]
#: folds of the single-harmonic Duffing relation at k3 = 0.5, c = 0.05, F = 0.1 [rad/s]
#: (tests/analysis/mhb/test_fold_location.py solves for them)
FOLDS_RAD_S = (1.3504933721457575, 1.1336499974952545)


def _run(capsys, *argv) -> dict:
    assert main(["continuation", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_any_model_file_to_csv_and_figure(tmp_path, capsys):
    out = _run(
        capsys,
        DUFFING,
        "--drive",
        "1",
        *ONE_HARMONIC,
        "--range",
        "0.5:2",
        "--unit",
        "rad/s",
        "--out",
        str(tmp_path / "curve.csv"),
        "--figure",
        str(tmp_path / "curve.png"),
    )
    assert out["message"] == "reached the end frequency"
    folds = 2 * np.pi * np.array(out["folds_hz"])
    assert np.abs(folds / FOLDS_RAD_S - 1).max() < 1e-9
    with (tmp_path / "curve.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == out["points"]
    assert {"frequency_hz", "omega_rad_s", "stable", "amplitude [m] point1 order 1"} <= set(rows[0])
    with (tmp_path / "curve.located.csv").open() as fh:
        located = list(csv.DictReader(fh))
    assert [r["kind"] for r in located] == ["fold", "fold", "peak"]
    assert (tmp_path / "curve.png").stat().st_size > 10_000


def test_hz_range_and_hdf5_output(tmp_path, capsys):
    lo, hi = 0.5 / (2 * np.pi), 2.0 / (2 * np.pi)
    out = _run(
        capsys,
        DUFFING,
        "--drive",
        "mass/x",
        "--outputs",
        "dof:0",
        *ONE_HARMONIC,
        "--range",
        f"{lo!r}:{hi!r}",
        "--unit",
        "hz",
        "--out",
        str(tmp_path / "curve.h5"),
    )
    with h5py.File(tmp_path / "curve.h5") as f:
        w = f["curve/omega_rad_s"][()]
        kinds = [k.decode() for k in f["located/kind"][()]]
        fold_w = f["located/omega_rad_s"][()][:2]
    assert len(w) == out["points"] and abs(w[0] - 0.5) < 1e-12
    assert kinds == ["fold", "fold", "peak"]
    assert np.abs(fold_w / FOLDS_RAD_S - 1).max() < 1e-9


BAD = {
    "unknown point": (["--drive", "9"], "--drive '9': unknown measurement point 9"),
    "unknown node": (["--drive", "wheel/x"], "--drive 'wheel/x': no free DOF wheel/x"),
    "bad dof": (["--drive", "1", "--outputs", "dof:5"], "--outputs 'dof:5': DOF indices run 0..0"),
    "amplitudes": (
        ["--drive", "1", "--amplitudes", "1,2"],
        "--amplitudes '1,2': one amplitude per force order (1: 1)",
    ),
    "orders": (["--drive", "1", "--force-orders", "1,x"], "--force-orders '1,x': expected numbers"),
    "range": (
        ["--drive", "1", "--amplitudes", "1", "--range", "10-40"],
        "--range '10-40': expected START:END",
    ),
    "samples": (
        ["--drive", "1", "--amplitudes", "1", "--H", "5", "--N", "16", "--range", "1:2"],
        "--H 5 --N 16: need H >= 1 and N >= 4 H + 1",
    ),
    "no drive": ([], "--drive: required with a model file"),
    "no force": (["--drive", "1"], "--amplitudes: required with a model file"),
    "no range": (["--drive", "1", "--amplitudes", "1"], "--range: required with a model file"),
    "angle": (
        ["--drive", "1", "--amplitudes", "1", "--max-angle", "2", "--range", "1:2"],
        "--max-angle 2.0: expected 0 < angle < pi/2",
    ),
}


@pytest.mark.parametrize(("argv", "expected"), BAD.values(), ids=BAD.keys())
def test_bad_input_names_the_argument(argv, expected):
    with pytest.raises(SystemExit) as info:
        main(["continuation", DUFFING, *argv])
    assert expected in str(info.value)
