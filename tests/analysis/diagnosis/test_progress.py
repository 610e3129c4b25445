"""The diagnosis commands show every event the diagnosis, the screen, the refit and augment
send (:mod:`analysis.events`), as text on stderr, and nothing with ``--json``."""

from __future__ import annotations

from analysis.diagnosis.cli import _progress
from analysis.events import Iteration, StageDone, UnitDone

#: One event of each kind (and shape) sent by diagnose, the screen, the refit and augment.
EVENTS = [
    StageDone("compared", rms_over_noise=43.2, seconds=1.5),
    UnitDone("screen", 1, 30, "cubic_spring at point 5"),
    UnitDone("screen", 8, 30, "cubic_spring at point 5"),
    UnitDone("refine", 3, 3, "cubic_spring at point 5"),
    StageDone("screened", count=30, seconds=12.0),
    StageDone("linear screen", count=4, note="best mass at point 7"),
    StageDone("recalibrated", rms_over_noise=2.0),
    StageDone("verified", count=3, rms_over_noise=1.1),
    StageDone("chosen", note="quadratic_damper at point 5"),
    # augment with a --candidate: the screen's estimate
    StageDone("screened", values={"c2_5": 0.5}),
    StageDone("linear recalibration", cost=0.1, values={"E_beam": 2.0e11}),
    UnitDone("starts", 1, 4, cost=3.5),
    Iteration("Levenberg-Marquardt", 1, 2.5, (1.0,)),
    Iteration("Levenberg-Marquardt", 2, 1.5, (1.1,), last=True),
    StageDone("balance checked", rms_over_noise=0.05, note="truncation at 9 harmonics"),
]


def test_every_event_kind_is_shown(capsys) -> None:
    show = _progress(False).event
    for e in EVENTS:
        show(e)
    err = capsys.readouterr().err
    assert "diagnosis: compared: residual 43.2 x noise, 1.5 s" in err
    assert "screen 1/30" in err and "refine 3/3" in err
    assert "screened: c2_5=0.5" in err
    assert "verified: 3, residual 1.1 x noise" in err
    assert "chosen: quadratic_damper at point 5" in err
    assert "starts 1/4" in err
    assert "Levenberg-Marquardt iterations 2/2" in err and "metric 1.5" in err
    assert "linear recalibration: metric 0.1, E_beam=2e+11" in err


def test_quiet_shows_nothing(capsys) -> None:
    show = _progress(True).event
    for e in EVENTS:
        show(e)
    assert capsys.readouterr().err == ""
