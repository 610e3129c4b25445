"""Starting gains of stepped-sine steps predicted from the steps already measured."""

import numpy as np
import pytest

from rig.config.plans import PlannedStep
from rig.procedures.gain_prediction import GainHistory

ORDERS = (1, 2, 3)


def _step(index: int, level: int, f: float, first: bool = False) -> PlannedStep:
    return PlannedStep(index, level, 2.0 * (level + 1), f, 1, first)


def _add(history: GainHistory, step: PlannedStep, gain1: float) -> None:
    drive = np.array([0.1, 0.002, 0.001], dtype=complex)
    force = np.array([gain1 * 0.1, 0.01, 0.005], dtype=complex)
    history.add(step, drive, force)


def _history(lower_at_27_2: float) -> GainHistory:
    """2 N swept over 27.0-27.2 Hz, then 4 N over 27.0-27.1 Hz (gains in N/V)."""
    h = GainHistory(0, ORDERS)
    _add(h, _step(0, 0, 27.0, first=True), 14.0)
    _add(h, _step(1, 0, 27.1), 14.0)
    _add(h, _step(2, 0, 27.2), lower_at_27_2)
    _add(h, _step(3, 1, 27.0, first=True), 20.0)
    _add(h, _step(4, 1, 27.1), 21.0)
    return h


def test_the_lower_level_scales_the_prediction_where_it_stayed_on_its_branch():
    h = _history(lower_at_27_2=15.0)
    gain = h.predict(_step(5, 1, 27.2), _step(4, 1, 27.1))
    # G(27.2, 4 N) = G(27.2, 2 N) G(27.1, 4 N) / G(27.1, 2 N)
    assert gain[0, 0] == pytest.approx(15.0 * 21.0 / 14.0)


def test_a_lower_level_that_jumped_off_its_fold_does_not_move_this_sweep():
    # at 27.2 Hz the 2 N response fell off its resonance's fold (the force per volt jumped
    # from 14 to 66 N/V); the 4 N sweep is still on its branch: its own trend counts
    h = _history(lower_at_27_2=66.0)
    gain = h.predict(_step(5, 1, 27.2), _step(4, 1, 27.1))
    along = 21.0 * (21.0 / 20.0)  # log-extrapolated one step along the 4 N sweep
    assert gain[0, 0] == pytest.approx(along, rel=1e-9)
    drive = h.predict_drive(_step(5, 1, 27.2), _step(4, 1, 27.1), np.array([4.0, 0.08, 0.08]))
    assert abs(drive[0]) == pytest.approx(4.0 / along, rel=1e-9)
