"""Figures of a calibration: measured vs model, convergence, cross-validation, validation bands."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_convergence", "plot_crossval", "plot_measured_vs_model", "plot_validation"]


def _save(fig, path) -> Path:
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_measured_vs_model(
    curves: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    channels: Sequence[str],
    orders: Sequence[str],
    path: str | Path,
    *,
    title: str = "",
    unit: str = "(m/s^2)/N",
) -> Path:
    """|H| per channel (rows) and order (columns): measured markers, model lines, per level.

    Parameters
    ----------
    curves : dict label -> (frequency_hz (n,), measured (n, C, H), model (n, C, H))
    """
    C, H = len(channels), len(orders)
    fig, axes = plt.subplots(C, H, figsize=(4.2 * H, 2.8 * C), sharex=True, squeeze=False)
    for i, (label, (f, meas, model)) in enumerate(curves.items()):
        col = f"C{i}"
        for c in range(C):
            for k in range(H):
                ax = axes[c, k]
                ax.semilogy(
                    f,
                    np.abs(meas[:, c, k]),
                    "o",
                    ms=2.5,
                    color=col,
                    alpha=0.7,
                    label=f"{label} measured" if c == k == 0 else None,
                )
                ax.semilogy(
                    f,
                    np.abs(model[:, c, k]),
                    "-",
                    lw=1.2,
                    color=col,
                    label=f"{label} model" if c == k == 0 else None,
                )
    for k in range(H):
        axes[0, k].set_title(f"order {orders[k]}")
        axes[-1, k].set_xlabel("fundamental frequency [Hz]")
    for c in range(C):
        axes[c, 0].set_ylabel(f"{channels[c]}\n|H| [{unit}]")
        for k in range(H):
            axes[c, k].grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_convergence(costs: Sequence[float], path: str | Path, *, title: str = "") -> Path:
    """Metric per Levenberg-Marquardt iteration (log scale)."""
    fig, ax = plt.subplots(figsize=(6, 3.8))
    ax.semilogy(range(len(costs)), costs, "o-")
    ax.set_xlabel("iteration")
    ax.set_ylabel("metric delta / 2")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title(title or "Levenberg-Marquardt convergence")
    return _save(fig, path)


def plot_crossval(
    names: Sequence[str],
    folds: Sequence[str],
    estimates: np.ndarray,
    mean: np.ndarray,
    cv_std: np.ndarray,
    fim_std: np.ndarray,
    path: str | Path,
) -> Path:
    """Fold estimates per parameter relative to the mean, with CV and FIM^-1 std bands."""
    n = len(names)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 4.0), squeeze=False)
    x = np.arange(len(folds))
    for j, name in enumerate(names):
        ax = axes[0, j]
        rel = estimates[:, j] / mean[j] - 1
        ax.bar(x, 100 * rel, color="C0")
        for s, style, lab in ((cv_std[j], "--", "CV std"), (fim_std[j], ":", "FIM$^{-1}$ std")):
            ax.axhline(100 * s / abs(mean[j]), ls=style, color="k", lw=1, label=lab)
            ax.axhline(-100 * s / abs(mean[j]), ls=style, color="k", lw=1)
        ax.set_xticks(x, folds, rotation=70, fontsize=7)
        ax.set_ylabel(f"{name}: fold estimate - mean [%]")
        ax.set_title(f"{name} = {mean[j]:.4g}")
        ax.legend(fontsize=7)
        ax.grid(True, axis="y", alpha=0.3)
    return _save(fig, path)


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
) -> Path:
    """Held-out FRFs: measurement with 2-sigma bars, prediction with its 2-sigma band."""
    C, H = len(channels), len(orders)
    fig, axes = plt.subplots(C, H, figsize=(4.2 * H, 2.8 * C), sharex=True, squeeze=False)
    for c in range(C):
        for k in range(H):
            ax = axes[c, k]
            m, s = np.abs(predicted[:, c, k]), predicted_std[:, c, k]
            ax.fill_between(
                frequency_hz,
                np.maximum(m - 2 * s, m * 1e-3),
                m + 2 * s,
                color="C1",
                alpha=0.3,
                label="model $\\pm 2\\sigma$" if c == k == 0 else None,
            )
            ax.plot(frequency_hz, m, "-", color="C1", lw=1.2)
            ax.errorbar(
                frequency_hz,
                np.abs(measured[:, c, k]),
                yerr=2 * measured_std[:, c, k],
                fmt="o",
                ms=2.5,
                color="C0",
                elinewidth=0.8,
                label="measured $\\pm 2\\sigma$" if c == k == 0 else None,
            )
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
    for k in range(H):
        axes[0, k].set_title(f"order {orders[k]}")
        axes[-1, k].set_xlabel("fundamental frequency [Hz]")
    for c in range(C):
        axes[c, 0].set_ylabel(f"{channels[c]}\n|H|")
    axes[0, 0].legend(fontsize=7)
    if title:
        fig.suptitle(title)
    return _save(fig, path)
