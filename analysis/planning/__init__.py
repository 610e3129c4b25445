"""Pretest planning with the Fisher information matrix (the reference paper's sec. 2.1).

Choose the actuator, sensors, force levels and frequency range of a stepped multi-sine test
that make the planned parameters best identifiable: every candidate configuration is ranked by
``det(FIM)``, with ``FIM = sum_n sigma_n^-2 (dz_n/dP)(dz_n/dP)^T`` over the stacked real and
imaginary parts of the multi-harmonic FRFs it would measure. The chosen configuration's
``FIM^-1`` bounds the parameter covariance and the MAC between Jacobian columns shows which
parameters are hard to tell apart.

Modules, in the order data flows: :mod:`~analysis.planning.candidates` (settings),
:mod:`~analysis.planning.sweeps` (one stepped MHB sweep with sensitivities per job),
:mod:`~analysis.executors` (where jobs run), :mod:`~analysis.planning.information`
(noise, blocks, Jacobians, MAC), :mod:`~analysis.planning.ranking` (all configurations at
once), :mod:`~analysis.planning.plan` (the entry point), :mod:`~analysis.planning.result`,
:mod:`~analysis.planning.cli` (``python -m analysis plan``).
"""

from analysis.executors import open_executor
from analysis.planning.candidates import (
    Candidates,
    Configuration,
    FrequencyRange,
    NoiseModel,
    paper_candidates,
    quick_candidates,
)
from analysis.planning.information import correlation_indices, jacobian_mac
from analysis.planning.plan import PAPER_LINEAR, PlanSettings, plan_tests
from analysis.planning.result import Correlations, PlanResult, RankedConfiguration

__all__ = [
    "PAPER_LINEAR",
    "Candidates",
    "Configuration",
    "Correlations",
    "FrequencyRange",
    "NoiseModel",
    "PlanResult",
    "PlanSettings",
    "RankedConfiguration",
    "correlation_indices",
    "jacobian_mac",
    "open_executor",
    "paper_candidates",
    "plan_tests",
    "quick_candidates",
]
