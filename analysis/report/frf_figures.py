"""Multi-harmonic FRF figures: magnitude and phase per order, one curve per level."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from analysis.report.units import mathtext_unit  # noqa: E402

__all__ = ["plot_branches", "plot_multiharmonic_frfs"]


def plot_multiharmonic_frfs(
    frequency_hz: np.ndarray,
    frfs: dict[str, np.ndarray],
    orders: Sequence[str],
    sensor_labels: Sequence[str],
    path: str | Path,
    *,
    title: str = "",
    unit: str = "m/N",
) -> Path:
    """Magnitude (log) and phase of ``H^nu`` per order (columns) and sensor (rows).

    Parameters
    ----------
    frequency_hz : ndarray, shape (n,)
        Fundamental frequency of each step [Hz].
    frfs : dict label -> ndarray, shape (n, n_orders, n_sensors), complex
        One curve per entry (e.g. per force level).
    orders : sequence of str
        Column titles (``"1"``, ``"2"``, ``"3"``).
    sensor_labels : sequence of str
        Row titles.
    path : str or Path
        PNG file to write.
    """
    from analysis.report.calibration_figures import frf_quantity

    n_o, n_s = len(orders), len(sensor_labels)
    fig, axes = plt.subplots(
        2 * n_s, n_o, figsize=(4.2 * n_o, 2.6 * 2 * n_s + 0.5), sharex=True, squeeze=False
    )
    handles = []
    for H in frfs.values():
        for s in range(n_s):
            for o in range(n_o):
                (h,) = axes[2 * s, o].semilogy(frequency_hz, np.abs(H[:, o, s]), ".-", ms=3)
                if s == o == 0:
                    handles.append(h)
                axes[2 * s + 1, o].plot(frequency_hz, np.degrees(np.angle(H[:, o, s])), ".", ms=3)
    for o in range(n_o):
        axes[0, o].set_title(f"order {orders[o]}")
        axes[-1, o].set_xlabel("fundamental frequency [Hz]")
    for s in range(n_s):
        q = frf_quantity(unit)
        axes[2 * s, 0].set_ylabel(f"{sensor_labels[s]}\n|{q}| [{mathtext_unit(unit)}]")
        axes[2 * s + 1, 0].set_ylabel("phase [deg]")
        for o in range(n_o):
            axes[2 * s + 1, o].set_ylim(-185, 185)
            axes[2 * s, o].grid(True, which="both", alpha=0.3)
            axes[2 * s + 1, o].grid(True, alpha=0.3)
    # below the axes: a legend on the first panel would hide the low level's jump
    rows = int(np.ceil(len(handles) / 6)) if handles else 0
    if handles:
        fig.legend(handles, list(frfs), loc="lower center", ncol=6, fontsize=8, frameon=True)
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, (0.28 * rows + 0.12) / fig.get_figheight() if rows else 0, 1, 1))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_branches(
    branches: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]],
    path: str | Path,
    *,
    steps: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
    title: str = "",
    ylabel: str = "tip amplitude, order 1 [mm]",
    xlabel: str = "fundamental frequency [Hz]",
    marks: dict[str, tuple[Sequence[float], Sequence[float]]] | None = None,
) -> Path:
    """Continued branches with stable parts solid and unstable parts dashed.

    Parameters
    ----------
    branches : dict label -> (frequency_hz (n,), amplitude (n,), stable (n,) bool or None)
    steps : dict label -> (frequency_hz, amplitude), optional
        Stepped solutions drawn as markers (what a stepped-sine test follows).
    path : str or Path
        PNG file to write.
    marks : dict label -> (x, y), optional
        Located points (folds, peaks) drawn as black markers.
    """
    fig, ax = plt.subplots(figsize=(8, 5))
    for i, (label, (f, a, stable)) in enumerate(branches.items()):
        color = f"C{i}"
        if stable is None:
            ax.plot(f, a, "-", color=color, label=label)
            continue
        st = np.asarray(stable, dtype=float)
        ax.plot(f, np.where(st > 0, a, np.nan), "-", color=color, label=f"{label} stable")
        ax.plot(f, np.where(st > 0, np.nan, a), "--", color=color, label=f"{label} unstable")
    for i, (label, (f, a)) in enumerate((steps or {}).items()):
        ax.plot(f, a, "o", ms=3, color=f"C{i}", alpha=0.6, label=f"{label} stepped")
    for symbol, (label, (x, y)) in zip("xv^s", (marks or {}).items(), strict=False):
        ax.plot(x, y, symbol, color="k", ms=7, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=2, loc="best", frameon=True, framealpha=0.9)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
