"""The benchmark entry point prints figures and, last, one JSON line with the tracked keys."""

import json
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_mhb_benchmark_quick_run_reports_its_keys():
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "mhb", "--quick"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout.strip().splitlines()[-1])
    for key in ("sweep_s", "ms_per_point", "converged_fraction", "ti_ratio", "max_rel_diff"):
        assert key in figures
    assert figures["converged_fraction"] == 1.0
    assert figures["max_rel_diff"] <= 0.01


def test_continuation_benchmark_quick_run_reports_its_keys():
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "continuation", "--quick"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout.strip().splitlines()[-1])
    assert figures["duffing_folds"] == 2
    assert figures["located_max_rel_err"] < 1e-9


@pytest.mark.slow
def test_speed_benchmark_quick_run_reports_its_keys():
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "speed", "--quick"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout.strip().splitlines()[-1])
    for key in (
        "machine_ref_s",
        "hill_over_solve",
        "solve_s_per_point",
        "paper_sweep_s",
        "sim_paper_run_s",
        "calibrate_total_s",
        "diagnosis_s_max",
    ):
        assert key in figures
    assert set(figures["hill_over_solve"]) == {"5"}
    assert figures["stability_agrees"] is True
    assert figures["leading_multiplier_rel_err_max"] < 0.02
