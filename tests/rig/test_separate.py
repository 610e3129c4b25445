"""``rig separate``: on a tie, the separating plan is run on the simulated rig as ``rig run``
runs a plan, and the tied candidates are ranked again on the new file."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import analysis.diagnosis
import analysis.diagnosis.cli
from rig.cli.main import main
from tests.analysis.diagnosis.conftest import truth_as_model


def _tied(label: str, model) -> SimpleNamespace:
    return SimpleNamespace(
        candidate=SimpleNamespace(label=label), verified=SimpleNamespace(model_toml=model.to_toml())
    )


@pytest.mark.slow
def test_a_tie_is_run_on_the_simulated_rig_and_ranked_again(tmp_path, monkeypatch, capsys):
    reference = truth_as_model("reference")  # the simulated rig's own values
    stiffer = reference.with_values({"E_beam": 1.08 * reference.parameters["E_beam"].value})
    group = [_tied("stiffer beam", stiffer), _tied("the reference", reference)]
    first = SimpleNamespace(
        orders=np.array([1, 2, 3]),
        force_targets=np.array([[2.0, 0.04, 0.04]]),
        channels=[SimpleNamespace(point=p) for p in (3, 6, 7)],
        config={"run": {"backend": "sim", "backend_options": {"truth": "reference", "seed": 4}}},
    )
    recommendation = {
        "best": {"sensor": 2, "level_n": 2.0, "start_hz": 22.0, "stop_hz": 23.0, "step_hz": 1.0},
        "candidates": [g.candidate.label for g in group],
    }
    diagnosis = SimpleNamespace(
        verdict="explained", group=group, recommendation=recommendation, summary=lambda: ""
    )
    read = analysis.diagnosis.cli.read_stepped
    monkeypatch.setattr(
        analysis.diagnosis.cli, "read_stepped", lambda p: first if p == "first.h5" else read(p)
    )
    monkeypatch.setattr(analysis.diagnosis, "diagnose", lambda *a, **k: diagnosis)
    model = reference.save(tmp_path / "m.toml")
    out = tmp_path / "separate.h5"
    code = main(
        ["separate", "first.h5", "--model", str(model), "--out", str(out), "--quiet", "--json"]
        + ["--lock-dir", str(tmp_path / "locks")]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # the plan was written beside the run and run on the first run's simulated rig
    assert (tmp_path / "separate.plan.toml").exists() and out.exists()
    assert report["resolved"] and report["tied"] == ["the reference"]
    assert report["ranking"][1]["delta_chi2"] > 10.0
