"""Figures of a diagnosis: residual maps, measured vs model, error history, before and after,
the missing force read out where nothing explains the misfit.

Residual maps show the root of the chi-square per degree of freedom (1 = at the noise) on a
log colour scale, so a failing block stands out at a glance: one map by sensor x order x level
(a panel per order) and one by frequency x level (every step).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from analysis.report.calibration_figures import plot_measured_vs_model  # noqa: E402

__all__ = [
    "plot_before_after",
    "plot_diagnosis",
    "plot_error_history",
    "plot_evidence",
    "plot_force_readout",
    "plot_frequency_level_map",
    "plot_measured_vs_model_levels",
    "plot_ranking",
    "plot_sensor_order_level_map",
]

_NORM: dict[str, Any] = {"vmin": 0.5, "vmax": 300.0}


def _save(fig, path) -> Path:
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _sensor_order_level(ax_row, cmp, title: str = ""):
    grid, levels = cmp.map_sensor_order_level()
    rms = np.sqrt(grid)
    im = None
    for k, ax in enumerate(ax_row):
        im = ax.imshow(rms[:, k, :], norm=LogNorm(**_NORM), cmap="magma_r", aspect="auto")
        ax.set_xticks(range(len(levels)), [f"{lv:g}" for lv in levels])
        ax.set_yticks(range(len(cmp.channels)), cmp.channels)
        ax.set_xlabel("level [N]")
        ax.set_title(f"{title}order {cmp.orders[k]}", fontsize=9)
        for i in range(rms.shape[0]):
            for j in range(rms.shape[2]):
                v = rms[i, k, j]
                if np.isfinite(v):
                    ax.text(
                        j,
                        i,
                        f"{v:.3g}",
                        ha="center",
                        va="center",
                        fontsize=7,
                        color="white" if v > 20 else "black",
                    )
    return im


def plot_sensor_order_level_map(cmp, path: str | Path, *, title: str = "") -> Path:
    """Residual / noise per sensor (rows), level (columns), one panel per order."""
    K = len(cmp.orders)
    fig, axes = plt.subplots(1, K, figsize=(3.2 * K + 1, 0.5 * len(cmp.channels) + 2))
    axes = np.atleast_1d(axes)
    im = _sensor_order_level(axes, cmp)
    fig.colorbar(im, ax=list(axes), label="rms residual / noise", shrink=0.8)
    if title:
        fig.suptitle(title)
    fig.savefig(Path(path), dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def _frequency_level(ax, cmp):
    levels = sorted(set(cmp.level_n.tolist()))
    freqs = np.unique(np.round(cmp.frequency_hz, 6))
    img = np.full((len(levels), freqs.size), np.nan)
    z = np.sqrt(np.nanmean(np.abs(cmp.residual) ** 2, axis=(1, 2)))
    for i, f in enumerate(np.round(cmp.frequency_hz, 6)):
        img[levels.index(cmp.level_n[i]), np.searchsorted(freqs, f)] = z[i]
    edges = np.concatenate([[freqs[0] - 0.05], (freqs[1:] + freqs[:-1]) / 2, [freqs[-1] + 0.05]])
    im = ax.pcolormesh(
        edges, np.arange(len(levels) + 1) - 0.5, img, norm=LogNorm(**_NORM), cmap="magma_r"
    )
    ax.set_yticks(range(len(levels)), [f"{lv:g} N" for lv in levels])
    ax.set_xlabel("frequency [Hz]")
    return im


def plot_frequency_level_map(cmp, path: str | Path, *, title: str = "") -> Path:
    """Residual / noise of every step (all sensors and orders), frequency x level."""
    fig, ax = plt.subplots(figsize=(9, 2.8))
    im = _frequency_level(ax, cmp)
    fig.colorbar(im, ax=ax, label="rms residual / noise")
    ax.set_title(title or "residual by frequency and level")
    return _save(fig, path)


def plot_measured_vs_model_levels(cmp, path: str | Path, *, title: str = "") -> Path:
    """|H| per sensor and order, measured (markers) and model (lines), one colour per level."""
    curves = {}
    for lv in sorted(set(cmp.level_n.tolist())):
        m = cmp.level_n == lv
        order = np.argsort(cmp.frequency_hz[m])
        curves[f"{lv:g} N"] = (
            cmp.frequency_hz[m][order],
            cmp.measured[m][order],
            cmp.predicted[m][order],
        )
    return plot_measured_vs_model(curves, cmp.channels, cmp.orders, path, title=title)


def plot_error_history(history: Sequence[dict], path: str | Path, *, title: str = "") -> Path:
    """Chi-square per degree of freedom by iteration (log scale)."""
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    its = [h for h in history if np.isfinite(h.get("chi2_per_dof", np.nan))]
    ax.semilogy(range(len(its)), [h["chi2_per_dof"] for h in its], "o-")
    ax.axhline(1.0, color="0.5", ls="--", lw=1, label="noise")
    ax.set_xlabel("iteration")
    ax.set_ylabel("chi2 / dof (fitted levels)")
    ax.legend()
    ax.set_title(title or "error history")
    return _save(fig, path)


def plot_before_after(before, after, path: str | Path, *, title: str = "") -> Path:
    """Residual maps of the model before and after the change (sensor x order x level, and
    frequency x level), on one colour scale."""
    K = len(before.orders)
    fig = plt.figure(figsize=(3.2 * K + 1.5, 11.0))
    gs = fig.add_gridspec(4, K, hspace=0.75, wspace=0.35)
    for r, (cmp, name) in enumerate(((before, "before"), (after, "after"))):
        axes = [fig.add_subplot(gs[r, k]) for k in range(K)]
        im = _sensor_order_level(axes, cmp, f"{name}: ")
        axes[0].set_ylabel(f"{name}: {cmp.rms_over_noise:.3g} x noise", fontsize=9)
        ax = fig.add_subplot(gs[2 + r, :])
        _frequency_level(ax, cmp)
        ax.set_title(
            f"{name} ({cmp.rms_over_noise:.3g} x noise), by frequency and level", fontsize=9
        )
    fig.colorbar(im, ax=fig.axes, label="rms residual / noise", shrink=0.6)
    if title:
        fig.suptitle(title)
    fig.savefig(Path(path), dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def plot_evidence(evidence, path: str | Path, *, title: str = "") -> Path:
    """The signature tests in figures: resonance frequency and normalised peak height by
    level (measured and model) and the growth exponent of each order, with each finding's
    sentence below."""
    found = {f.name: f for f in evidence.findings}
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    res = found.get("resonance_shift")
    if res is not None and res.values:
        lv = res.values["levels_n"]
        _by_level(axes[0], lv, res.values["measured_hz"], res.values["model_hz"], "resonance [Hz]")
    axes[0].set_title("resonance by level", fontsize=9)
    peak = found.get("peak_height")
    if peak is not None and peak.values and res is not None:
        lv = res.values["levels_n"]
        _by_level(
            axes[1], lv, peak.values["measured"], peak.values["model"], "peak |H1| / lowest level's"
        )
    axes[1].set_title("normalised peak height", fontsize=9)
    growth = [f for f in evidence.findings if f.name.startswith("growth")]
    if growth:
        labels = [f.values.get("order", "?") for f in growth]
        x = np.arange(len(growth))
        axes[2].bar(
            x - 0.2, [f.values.get("measured", np.nan) for f in growth], 0.4, label="measured"
        )
        axes[2].bar(x + 0.2, [f.values.get("model", np.nan) for f in growth], 0.4, label="model")
        axes[2].set_xticks(x, [f"order {o}" for o in labels])
        axes[2].set_ylabel("d log|Y| / d log F")
        axes[2].legend()
    axes[2].set_title("growth exponent by order", fontsize=9)
    text = "\n".join(
        ("[x] " if f.significant else "[ ] ") + _wrap(f.text) for f in evidence.findings
    )
    fig.text(0.01, -0.02, text, va="top", ha="left", fontsize=7.5, family="monospace")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(Path(path), dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def _wrap(text: str, width: int = 150) -> str:
    import textwrap

    return "\n    ".join(textwrap.wrap(text, width))


def plot_ranking(diagnosis, path: str | Path, *, title: str = "") -> Path:
    """The verified candidates: residual over noise after everything was recalibrated (bars,
    log scale) and delta BIC against the recalibrated model; the tied group highlighted."""
    ranking = diagnosis.ranking
    fig, (ax1, ax2) = plt.subplots(
        1, 2, figsize=(12, 0.45 * max(len(ranking), 2) + 1.8), sharey=True
    )
    labels = [r.candidate.label for r in ranking]
    y = np.arange(len(ranking))
    colours = ["C2" if r.group == 1 and diagnosis.verdict == "explained" else "C0" for r in ranking]
    ax1.barh(y, [r.rms_over_noise for r in ranking], color=colours)
    ax1.axvline(
        diagnosis.settings.explained_rms, color="0.3", ls="--", lw=1, label="explained below"
    )
    if diagnosis.refit is not None:
        ax1.axvline(
            diagnosis.refit_rms,
            color="C3",
            ls=":",
            lw=1.5,
            label="model, own parameters recalibrated",
        )
    ax1.set_xscale("log")
    ax1.set_yticks(y, labels, fontsize=8)
    ax1.invert_yaxis()
    ax1.set_xlabel("residual / noise after recalibration")
    ax1.legend(fontsize=7)
    ax2.barh(y, [r.delta_bic for r in ranking], color=colours)
    ax2.axvline(0, color="0.3", lw=1)
    ax2.set_xlabel("delta BIC against the recalibrated model (negative: better)")
    fig.suptitle(title or f"verdict: {diagnosis.verdict}", fontsize=10)
    return _save(fig, path)


def plot_diagnosis(diagnosis, folder: str | Path) -> list[Path]:
    """The figures of a diagnosis in ``folder``: the two residual maps, measured vs model, the
    evidence, (when candidates were verified) the ranking and (when nothing explains the
    misfit) what the data show about the missing law."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cmp = diagnosis.comparison
    out = [
        plot_sensor_order_level_map(
            cmp,
            folder / "residual_sensor_order_level.png",
            title=f"model vs file: {cmp.rms_over_noise:.3g} x noise",
        ),
        plot_frequency_level_map(cmp, folder / "residual_frequency_level.png"),
        plot_measured_vs_model_levels(cmp, folder / "measured_vs_model.png"),
        plot_evidence(diagnosis.evidence, folder / "evidence.png"),
    ]
    if diagnosis.ranking:
        out.append(plot_ranking(diagnosis, folder / "ranking.png"))
    if diagnosis.readout is not None:
        out.append(plot_force_readout(diagnosis.readout, folder / "missing_force.png"))
    return out


def _by_level(ax, levels, measured, model, ylabel: str) -> None:
    """Measured and model values of one evidence quantity against the level."""
    ax.plot(levels, measured, "o-", label="measured")
    ax.plot(levels, model, "s--", label="model")
    ax.set_xlabel("level [N]")
    ax.set_ylabel(ylabel)
    ax.legend()


def _readout_panel(ax, ro, y, sigma, bins, fit, label: str, unit: str) -> None:
    """One describing function against the amplitude: the steps read (by level), their binned
    means and, where its slope is resolved, the fit over the amplitudes it was made on (at
    the fit's reference frequency)."""
    seen = ro.seen
    A = ro.amplitude
    for lv in sorted(set(ro.level_n[seen].tolist())):
        at = seen & (ro.level_n == lv)
        ax.errorbar(
            A[at], y[at], yerr=sigma[at], fmt="o", ms=3, lw=0.6, alpha=0.6, label=f"{lv:g} N"
        )
    if bins is not None:
        ax.errorbar(
            bins.A, bins.y, yerr=bins.sigma, fmt="s", color="k", ms=5, lw=1.2, label="binned"
        )
        lo, hi = np.min(bins.y - 3 * bins.sigma), np.max(bins.y + 3 * bins.sigma)
        pts = y[seen]
        lo = min(lo, np.percentile(pts, 5))
        hi = max(hi, np.percentile(pts, 95))
        pad = 0.1 * (hi - lo) + 1e-300
        ax.set_ylim(lo - pad, hi + pad)
    if fit is not None and fit.resolved:
        grid = np.geomspace(fit.span[0], fit.span[1], 100)
        ax.plot(grid, fit.at(grid), "k--", lw=1.2, label=f"fit, slope {fit.p:.2f}")
    ax.set_xscale("log")
    ax.set_xlabel(f"amplitude A [{ro.units['x']}]")
    ax.set_ylabel(f"{label} [{unit}]")
    ax.legend(fontsize=7)


def plot_force_readout(readout, path: str | Path, *, title: str = "") -> Path:
    """What the data show about a missing law (:class:`~analysis.diagnosis.readout.ForceReadout`):
    the equivalent stiffness and damping of its first harmonic against the amplitude, and one
    period of the restoring force against the displacement and the velocity, rebuilt from the
    measured orders (mean left out)."""
    ro = readout
    u = ro.units
    r = ro.reading
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    what = "moment" if ro.rotation else "force"
    _readout_panel(
        axes[0, 0],
        ro,
        ro.k_eq,
        ro.sigma_k,
        None if r is None else r.k_bins,
        None if r is None else r.stiffness,
        "equivalent stiffness k_eq",
        u["k"],
    )
    damping = None
    if r is not None:
        damping = r.damping if r.damping.changes else r.damping_whole
    _readout_panel(
        axes[0, 1],
        ro,
        ro.c_eq,
        ro.sigma_c,
        None if r is None else r.c_bins,
        damping,
        "equivalent damping c_eq",
        u["c"],
    )
    for lp in ro.loops:
        label = f"{lp['level_n']:g} N, {lp['frequency_hz']:.2f} Hz"
        axes[1, 0].plot(lp["x"], lp["f"], lw=1, label=label)
        axes[1, 1].plot(lp["v"], lp["f"], lw=1, label=label)
    orders = ", ".join(ro.orders)
    axes[1, 0].set_xlabel(f"displacement x [{u['x']}]")
    axes[1, 1].set_xlabel(f"velocity v [{u['v']}]")
    for ax in axes[1]:
        ax.set_ylabel(f"restoring {what} f [{u['f']}]")
        ax.set_title(f"one period from orders {orders} (mean not measured)", fontsize=8)
        if ro.loops:
            ax.legend(fontsize=7)
    kind = "not read" if r is None else r.description
    fig.suptitle(title or f"missing {what} at {ro.read_at}: {kind}", fontsize=10)
    return _save(fig, path)
