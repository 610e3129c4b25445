"""The branch-matched prediction, used by every diagnosis step (it lives beside
:mod:`analysis.predict`, since calibration uses it too)."""

from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["BranchMatchedPredictor"]
