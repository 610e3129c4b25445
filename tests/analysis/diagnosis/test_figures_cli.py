"""Figures and the command line."""

from __future__ import annotations

import argparse
import json

import pytest

from analysis.diagnosis import BranchMatchedPredictor, compare
from analysis.diagnosis.cli import _settings, add_parsers
from analysis.report.diagnosis_figures import (
    plot_before_after,
    plot_error_history,
    plot_frequency_level_map,
    plot_measured_vs_model_levels,
    plot_sensor_order_level_map,
)


@pytest.mark.slow
def test_figures_are_written(runs, reference_model, tmp_path) -> None:
    data = runs("two_sided_stop")
    cmp = compare(reference_model, data, predictor=BranchMatchedPredictor(reference_model, data))
    paths = [
        plot_sensor_order_level_map(cmp, tmp_path / "a.png"),
        plot_frequency_level_map(cmp, tmp_path / "b.png"),
        plot_measured_vs_model_levels(cmp, tmp_path / "c.png"),
        plot_before_after(cmp, cmp, tmp_path / "d.png"),
        plot_error_history([{"chi2_per_dof": 50.0}, {"chi2_per_dof": 1.1}], tmp_path / "e.png"),
    ]
    assert all(p.stat().st_size > 5000 for p in paths)


def _run(argv, capsys):
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    out = args.func(args)
    return out, capsys.readouterr()


@pytest.mark.slow
def test_compare_and_diagnose_commands(runs, reference_model, tmp_path, capsys) -> None:
    data = runs("reference")
    model_path = reference_model.save(tmp_path / "model.toml")
    out, text = _run(
        ["compare", str(data.path), "--model", str(model_path), "--figures", str(tmp_path / "fig")],
        capsys,
    )
    assert "chi2/dof" in text.out and out["rms_over_noise"] < 1.3
    assert (tmp_path / "fig" / "residual_sensor_order_level.png").exists()
    out, text = _run(
        [
            "diagnose",
            str(data.path),
            "--model",
            str(model_path),
            "--json",
            "--rescreen-ratio",
            "0.4",
        ],
        capsys,
    )
    assert out["verdict"] == "adequate"
    json.dumps(out)


def test_the_rescreen_ratio_reaches_the_settings_and_a_bad_one_is_refused() -> None:
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="cmd"))
    args = parser.parse_args(["diagnose", "run.h5", "--model", "m.toml", "--rescreen-ratio", "0"])
    assert _settings(args).rescreen_ratio == 0.0
    args = parser.parse_args(["augment", "run.h5", "--model", "m.toml", "--out", "a.toml"])
    assert _settings(args).rescreen_ratio == 0.5
    args.rescreen_ratio = 1.0
    with pytest.raises(ValueError, match="rescreen_ratio: must be < 1"):
        _settings(args)
