"""Figures and reports a person reads. The only place in ``analysis`` that imports matplotlib."""

from analysis.report.calibration_figures import (
    plot_convergence,
    plot_crossval,
    plot_measured_vs_model,
    plot_validation,
)
from analysis.report.frf_figures import plot_branches, plot_multiharmonic_frfs

__all__ = [
    "plot_branches",
    "plot_convergence",
    "plot_crossval",
    "plot_measured_vs_model",
    "plot_multiharmonic_frfs",
    "plot_validation",
]
