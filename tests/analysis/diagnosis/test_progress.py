"""The diagnosis commands' progress printer takes every event kind the diagnosis emits."""

from __future__ import annotations

from analysis.diagnosis.cli import _progress

#: One event of each kind (and shape) sent by diagnose, the screen, the refit and augment.
EVENTS = [
    ("compare", {"rms_over_noise": 43.2, "seconds": 1.5}),
    ("screen", {"index": 0, "n": 30, "label": "cubic_spring at point 5"}),
    ("screen", {"index": 7, "n": 30, "label": "cubic_spring at point 5"}),
    ("refine", {"index": 2, "n": 3, "label": "cubic_spring at point 5"}),
    ("screened", {"n": 30, "seconds": 12.0}),
    ("linear screen", {"n": 4, "best": "mass at point 7", "base_cost": 3.0}),
    ("recalibrated", {"rms_over_noise": 2.0}),
    ("rescreen", {"rms_over_noise": 2.0}),
    ("continue", {"n": 1, "rms_over_noise": 1.2}),
    ("verified", {"n": 3, "best_rms": 1.1}),
    ("neighbours", {"n": 2}),
    ("other laws", {"n": 2}),
    ("restart", {"n": 1}),
    ("chosen", {"candidate": "quadratic_damper at point 5"}),
    # augment with a --candidate: the screen's estimate, no counter
    ("screen", {"values": {"c2_5": 0.5}, "known": {"k_c": 4.5e5}}),
    ("linear", {"cost": 0.1, "parameters": {"E_beam": 2.0e11}}),
    ("start", {"index": 0, "n": 4, "cost": 3.5}),
    ("lm", {"iteration": 1, "cost": 2.5, "lam": 1e-3, "x": [1.0], "step_norm": 0.1}),
    ("balance", {"n_harmonics": 9, "truncation_over_noise": 0.05}),
]


def test_every_event_kind_is_printed_without_error(capsys) -> None:
    show = _progress(False)
    for stage, info in EVENTS:
        show(stage, info)
    err = capsys.readouterr().err
    assert "screen 1/30" in err and "screen 8/30" not in err
    assert "screen: values {c2_5=0.5}, known {k_c=4.5e+05}" in err
    assert "LM iteration 1: metric 2.5" in err
    assert "chosen: candidate quadratic_damper at point 5" in err
    assert "start 1/4" in err


def test_quiet_prints_nothing(capsys) -> None:
    show = _progress(True)
    for stage, info in EVENTS:
        show(stage, info)
    assert capsys.readouterr().err == ""
