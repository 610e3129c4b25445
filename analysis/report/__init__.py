"""Figures and reports a person reads. The only place in ``analysis`` that imports matplotlib."""

from analysis.report.frf_figures import plot_branches, plot_multiharmonic_frfs

__all__ = ["plot_branches", "plot_multiharmonic_frfs"]
