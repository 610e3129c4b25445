"""Figures of a calibration: measured vs model, convergence, cross-validation, validation bands.

Every axis carries its quantity and unit; legends sit outside the axes (below the figure), so no
legend hides data (the jump of a low level, a band's edge).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from analysis.report.units import display_unit, mathtext_unit  # noqa: E402

__all__ = [
    "frf_quantity",
    "plot_convergence",
    "plot_crossval",
    "plot_measured_vs_model",
    "plot_validation",
]

#: The FRF the calibration compares: accelerometer channels per newton of drive force.
ACCELERANCE = "(m/s^2)/N"

_QUANTITY = {
    "m/N": "receptance",
    "(m/s)/N": "mobility",
    "(m/s^2)/N": "accelerance",
}


def frf_quantity(unit: str) -> str:
    """Name of the FRF in ``unit``: receptance (m/N), mobility, accelerance ((m/s^2)/N)."""
    return _QUANTITY.get(unit.replace(" ", ""), "FRF")


def _save(fig, path, *, legend_rows: int = 0) -> Path:
    # room below the axes for a figure legend: about 0.28 in per row of entries
    bottom = (0.28 * legend_rows + 0.12) / fig.get_figheight() if legend_rows else 0.0
    fig.tight_layout(rect=(0, bottom, 1, 1))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _figure_legend(fig, handles, labels, ncol: int) -> int:
    """A legend below every axes (outside the data); returns the number of its rows."""
    if not handles:
        return 0
    ncol = max(1, min(ncol, len(handles)))
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=True)
    return int(np.ceil(len(handles) / ncol))


def plot_measured_vs_model(
    curves: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    channels: Sequence[str],
    orders: Sequence[str],
    path: str | Path,
    *,
    title: str = "",
    unit: str = ACCELERANCE,
) -> Path:
    """|H| per channel (rows) and order (columns): measured markers, model lines, per level.

    Parameters
    ----------
    curves : dict label -> (frequency_hz (n,), measured (n, C, H), model (n, C, H))
    unit : str
        Unit of the FRFs (default accelerance, (m/s^2)/N).
    """
    C, H = len(channels), len(orders)
    fig, axes = plt.subplots(C, H, figsize=(4.2 * H, 2.8 * C + 0.6), sharex=True, squeeze=False)
    handles, labels = [], []
    for i, (label, (f, meas, model)) in enumerate(curves.items()):
        col = f"C{i}"
        for c in range(C):
            for k in range(H):
                ax = axes[c, k]
                (hm,) = ax.semilogy(f, np.abs(meas[:, c, k]), "o", ms=2.5, color=col, alpha=0.7)
                (hl,) = ax.semilogy(f, np.abs(model[:, c, k]), "-", lw=1.2, color=col)
                if c == k == 0:
                    handles += [hm, hl]
                    labels += [f"{label} measured", f"{label} model"]
    for k in range(H):
        axes[0, k].set_title(f"order {orders[k]}")
        axes[-1, k].set_xlabel("fundamental frequency [Hz]")
    q = frf_quantity(unit)
    for c in range(C):
        axes[c, 0].set_ylabel(f"{channels[c]}\n|{q}| [{mathtext_unit(unit)}]")
        for k in range(H):
            axes[c, k].grid(True, which="both", alpha=0.3)
    rows = _figure_legend(fig, handles, labels, ncol=2 * min(len(curves), 4))
    if title:
        fig.suptitle(title)
    return _save(fig, path, legend_rows=rows)


def plot_convergence(
    costs: Sequence[float],
    path: str | Path,
    *,
    title: str = "",
    weighted: bool = True,
    n_residuals: int | None = None,
) -> Path:
    """The Levenberg-Marquardt metric per iteration (log scale).

    Parameters
    ----------
    costs : sequence of float
        The LM cost per iteration, ``1/2 |r|^2`` of the weighted residuals ``r``; the figure
        shows ``chi^2 = |r|^2 = 2 cost``.
    weighted : bool
        The residuals are weighted by ``1/sigma`` (chi-square, dimensionless); ``False``
        (identity weighting) leaves them in FRF units.
    n_residuals : int, optional
        Number of real residuals: the title then gives the final chi-square per residual.
    """
    chi2 = 2.0 * np.asarray(costs, dtype=float)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.semilogy(range(chi2.size), chi2, "o-")
    ax.set_xlabel("Levenberg-Marquardt iteration")
    if weighted:
        ax.set_ylabel("LM metric: $\\chi^2$ of the weighted residuals\n[dimensionless]")
    else:
        ax.set_ylabel("LM metric: sum of squared residuals [(FRF unit)$^2$]")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(True, which="both", alpha=0.3)
    head = title or "Levenberg-Marquardt convergence"
    if n_residuals and chi2.size:
        head += f"\nfinal $\\chi^2$ = {chi2[-1]:.4g} over {n_residuals} residuals"
    ax.set_title(head, fontsize=10)
    return _save(fig, path)


def plot_crossval(
    names: Sequence[str],
    folds: Sequence[str],
    estimates: np.ndarray,
    mean: np.ndarray,
    cv_std: np.ndarray,
    fim_std: np.ndarray,
    path: str | Path,
    *,
    units: Mapping[str, str] | None = None,
) -> Path:
    """Fold estimates per parameter relative to the mean, with CV and FIM^-1 std bands.

    ``units`` (name -> unit) puts each parameter's unit in its panel title.
    """
    n = len(names)
    estimates = np.asarray(estimates, dtype=float)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.4), squeeze=False)
    x = np.arange(len(folds))
    handles, labels = [], []
    for j, name in enumerate(names):
        ax = axes[0, j]
        rel = estimates[:, j] / mean[j] - 1
        hb = ax.bar(x, 100 * rel, color="C0")
        for s, style, lab in ((cv_std[j], "--", "CV std"), (fim_std[j], ":", "FIM$^{-1}$ std")):
            if s is None or not np.isfinite(s):
                continue
            h = ax.axhline(100 * s / abs(mean[j]), ls=style, color="k", lw=1)
            ax.axhline(-100 * s / abs(mean[j]), ls=style, color="k", lw=1)
            if j == 0:
                handles.append(h)
                labels.append(f"$\\pm 1\\sigma$, {lab}")
        if j == 0:
            handles.insert(0, hb)
            labels.insert(0, "fold estimate")
        ax.set_xticks(x, folds, rotation=70, fontsize=7)
        ax.set_ylabel("fold estimate - CV mean [% of mean]")
        factor, unit = display_unit((units or {}).get(name, ""))
        text = f"{name}: CV mean {factor * mean[j]:.4g} {mathtext_unit(unit)}"
        ax.set_title(text.strip(), fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    rows = _figure_legend(fig, handles, labels, ncol=3)
    return _save(fig, path, legend_rows=rows)


def _phases_deg(predicted: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phases [deg] drawn without wrap jumps: the prediction's unwrapped along frequency (its
    mean within +-180 deg), the measurement's within 180 deg of the prediction's."""
    pp = np.unwrap(np.angle(predicted))
    ok = np.isfinite(pp)
    if ok.any():
        pp = pp - 2 * np.pi * np.round(np.mean(pp[ok]) / (2 * np.pi))
    with np.errstate(divide="ignore", invalid="ignore"):
        mp = pp + np.angle(measured / predicted)
    return np.degrees(pp), np.degrees(mp)


def _phase_std_deg(value: np.ndarray, std: np.ndarray) -> np.ndarray:
    """1-sigma of the phase of a complex value with complex-magnitude std ``std`` [deg]."""
    mag = np.abs(value)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.degrees(np.where(mag > 0, std / mag, np.inf))
    return np.minimum(s, 90.0)  # a 2-sigma bar of 180 deg: phase unknown


def plot_validation(
    frequency_hz: np.ndarray,
    measured: np.ndarray,
    measured_std: np.ndarray,
    predicted: np.ndarray,
    predicted_std: np.ndarray,
    channels: Sequence[str],
    orders: Sequence[str],
    path: str | Path,
    *,
    title: str = "",
    unit: str = ACCELERANCE,
) -> Path:
    """Held-out FRFs, magnitude and phase: measurement with 2-sigma error bars, prediction with
    its 2-sigma band (from the parameter covariance).

    Parameters
    ----------
    measured, predicted : ndarray, shape (n, C, H), complex
    measured_std, predicted_std : ndarray, shape (n, C, H)
        Standard errors of the complex values (complex magnitude); the phase's is ``std/|H|``.
    unit : str
        Unit of the FRFs (default accelerance, (m/s^2)/N).
    """
    f = np.asarray(frequency_hz, dtype=float)
    C, H = len(channels), len(orders)
    fig, axes = plt.subplots(
        2 * C, H, figsize=(4.2 * H, 2.3 * 2 * C + 0.8), sharex=True, squeeze=False
    )
    q = frf_quantity(unit)
    handles, labels = [], []
    for c in range(C):
        for k in range(H):
            am, ap = axes[2 * c, k], axes[2 * c + 1, k]
            pz, mz = predicted[:, c, k], measured[:, c, k]
            ps, ms = predicted_std[:, c, k], measured_std[:, c, k]
            m = np.abs(pz)
            band = am.fill_between(
                f, np.maximum(m - 2 * ps, m * 1e-3), m + 2 * ps, color="C1", alpha=0.3, lw=0
            )
            (line,) = am.plot(f, m, "-", color="C1", lw=1.2)
            mm = np.abs(mz)
            lower = np.minimum(2 * ms, 0.999 * mm)  # a log axis has no room below zero
            bars = am.errorbar(
                f, mm, yerr=[lower, 2 * ms], fmt="o", ms=2.5, color="C0", elinewidth=0.8
            )
            am.set_yscale("log")
            pp, mp = _phases_deg(pz, mz)
            sp = _phase_std_deg(pz, ps)
            ap.fill_between(f, pp - 2 * sp, pp + 2 * sp, color="C1", alpha=0.3, lw=0)
            ap.plot(f, pp, "-", color="C1", lw=1.2)
            ap.errorbar(
                f,
                mp,
                yerr=2 * _phase_std_deg(mz, ms),
                fmt="o",
                ms=2.5,
                color="C0",
                elinewidth=0.8,
            )
            ap.yaxis.set_major_locator(matplotlib.ticker.MultipleLocator(90))
            for ax in (am, ap):
                ax.grid(True, which="both", alpha=0.3)
            if c == k == 0:
                handles = [bars, line, band]
                labels = [
                    "measured, $\\pm 2\\sigma$ error bars",
                    "model prediction",
                    "prediction $\\pm 2\\sigma$ (parameter uncertainty)",
                ]
    for k in range(H):
        axes[0, k].set_title(f"order {orders[k]}")
        axes[-1, k].set_xlabel("fundamental frequency [Hz]")
    for c in range(C):
        axes[2 * c, 0].set_ylabel(f"{channels[c]}\n|{q}| [{mathtext_unit(unit)}]")
        axes[2 * c + 1, 0].set_ylabel(f"{channels[c]}\nphase [deg]")
    rows = _figure_legend(fig, handles, labels, ncol=3)
    if title:
        fig.suptitle(title)
    return _save(fig, path, legend_rows=rows)
