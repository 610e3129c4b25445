"""The analysis command line, run as a user runs it."""

import json
import subprocess
import sys

import pytest


def _run(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "analysis", *args], capture_output=True, text=True, timeout=timeout
    )


def test_modes_lists_the_beam_modes_in_their_bands():
    r = _run("modes", "--json", "--n", "8")
    assert r.returncode == 0, r.stderr
    modes = json.loads(r.stdout.strip().splitlines()[-1])["modes"]
    beam = [m for m in modes if m["beam_energy_share"] > 0.8]
    assert 21 <= beam[0]["frequency_hz"] <= 40
    assert 141 <= beam[1]["frequency_hz"] <= 160


@pytest.mark.slow
def test_sweep_writes_a_figure_and_converges(tmp_path):
    r = _run("sweep", "--paper", "--levels", "2,8", "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["converged"] == out["points"] == 112
    assert (tmp_path / "mhb_frfs.png").stat().st_size > 10_000


def test_bad_parameter_override_is_a_clear_error():
    r = _run("modes", "--set", "E_beam=abc")
    assert r.returncode != 0
    assert "E_beam=abc" in r.stderr


def test_unknown_parameter_names_it():
    r = _run("modes", "--set", "E_bam=2e11")
    assert r.returncode == 2
    assert "E_bam" in r.stderr


@pytest.mark.slow
def test_continuation_finds_folds_and_unstable_points(tmp_path):
    r = _run("continuation", "--paper", "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert len(out["folds_hz"]) == 2 and out["unstable_points"] > 0
    assert (tmp_path / "branch.png").exists() and (tmp_path / "curve.csv").exists()


def test_top_level_help_lists_each_command_once():
    """``python -m analysis --help`` names every command on one line of its own, once."""
    from analysis.cli import build_parser

    text = build_parser().format_help()
    names = list(build_parser()._subparsers._group_actions[0].choices)
    assert {"compare", "calibrate", "plan", "augment"} <= set(names)
    for name in names:
        lines = [ln for ln in text.splitlines() if ln.split()[:1] == [name]]
        assert len(lines) == 1, (name, lines)
    assert "{" not in text
