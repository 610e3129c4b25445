"""Compare a model with a measurement and localise the misfit.

Residuals ``r = (H_model - H_meas) / sigma`` (sigma: the FRF's complex standard error from the
file's phasor uncertainties, the force's carried through the model) are grouped into blocks by
sensor, order, level and frequency band. Each block gets a chi-square with two degrees of
freedom per complex value (each part has half the complex variance) and a verdict: "consistent
with the noise" when its p-value is at least ``alpha / n_blocks`` (a family-wise level
``alpha`` over all blocks, Bonferroni), "fails here" otherwise, with the numbers. Neighbouring
frequency steps are not independent in a real test (a model error is smooth in frequency), so
a failing block is evidence of a model error while a passing one bounds it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from analysis.calibration.uncertainty import ADEQUATE_RMS, adequate
from analysis.measurement_file import SteppedSineData, require_steps
from analysis.model import Model
from analysis.predict import SteppedSinePredictor, check_standard_errors
from analysis.predict_branches import BranchMatchedPredictor

__all__ = ["Block", "Comparison", "compare", "uncalibrated_note"]


@dataclass(frozen=True)
class Block:
    """One group of FRF values and its verdict."""

    sensor: str
    order: str
    level_n: float
    band_hz: tuple[float, float]
    n_values: int
    chi2_per_dof: float
    p_value: float
    consistent: bool

    @property
    def verdict(self) -> str:
        word = "consistent with the noise" if self.consistent else "fails here"
        return (
            f"{self.sensor}, order {self.order}, {self.level_n:g} N, "
            f"{self.band_hz[0]:g}-{self.band_hz[1]:g} Hz: {word} "
            f"(chi2/dof {self.chi2_per_dof:.2f} over {self.n_values} values, "
            f"p = {self.p_value:.2g})"
        )


@dataclass
class Comparison:
    """Normalised residuals of a model against a measurement, with block verdicts.

    Attributes
    ----------
    residual : ndarray, shape (n_steps, n_channels, n_orders), complex
        ``(H_model - H_meas) / sigma``; NaN where the model did not converge.
    frequency_hz, level_n : ndarray, shape (n_steps,)
    blocks : list of Block
    """

    residual: np.ndarray
    frequency_hz: np.ndarray
    level_n: np.ndarray
    channels: list[str]
    orders: list[str]
    bands_hz: list[tuple[float, float]]
    blocks: list[Block]
    measured: np.ndarray
    predicted: np.ndarray
    alpha: float
    left_out: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    notes: list[str] = field(default_factory=list)

    @property
    def chi2_per_dof(self) -> float:
        """Whole-file chi-square per degree of freedom."""
        z = np.abs(self.residual[np.isfinite(self.residual)]) ** 2
        return float(z.mean()) if z.size else np.nan

    @property
    def rms_over_noise(self) -> float:
        """Root of the chi-square per degree of freedom (1 = at the noise)."""
        return float(np.sqrt(self.chi2_per_dof))

    @property
    def adequate(self) -> bool:
        """Within :data:`~analysis.calibration.uncertainty.ADEQUATE_RMS` of the noise over the
        whole file: the threshold every analysis judges a model by (calibration,
        cross-validation, validation, diagnosis)."""
        return adequate(self.rms_over_noise)

    @property
    def blocks_consistent(self) -> bool:
        """Every block passes its own noise test (a stricter, local question: where a small
        model error shows, it fails there even when the model is adequate overall)."""
        return all(b.consistent for b in self.blocks)

    def failing(self) -> list[Block]:
        return sorted((b for b in self.blocks if not b.consistent), key=lambda b: -b.chi2_per_dof)

    def map_sensor_order_level(self) -> tuple[np.ndarray, list[float]]:
        """chi2/dof per (sensor, order, level): shape (n_channels, n_orders, n_levels)."""
        levels = sorted(set(self.level_n.tolist()))
        out = np.full((len(self.channels), len(self.orders), len(levels)), np.nan)
        for li, lv in enumerate(levels):
            r = self.residual[self.level_n == lv]
            z = np.abs(r) ** 2
            with np.errstate(invalid="ignore"):
                out[:, :, li] = np.nanmean(z, axis=0)
        return out, levels

    def summary(self, n: int = 8) -> str:
        lines = [
            f"chi2/dof {self.chi2_per_dof:.3g} (rms residual / noise "
            f"{self.rms_over_noise:.3g}) over {np.isfinite(self.residual).sum()} FRF values"
            + (
                f" ({self.left_out.size} step(s) not converged under force control left out)"
                if self.left_out.size
                else ""
            )
        ]
        fails = self.failing()
        if not fails:
            lines.append("every block is consistent with the noise: the model is adequate here")
            return "\n".join(lines)
        if self.adequate:
            lines.append(
                f"adequate overall (within {ADEQUATE_RMS:g} x the noise, the threshold every "
                f"analysis uses), but {len(fails)} of {len(self.blocks)} blocks fail their own "
                "noise test: a small model error shows there; the worst:"
            )
        else:
            lines.append(
                f"the model misfits (above {ADEQUATE_RMS:g} x the noise): {len(fails)} of "
                f"{len(self.blocks)} blocks fail; the worst:"
            )
        lines += ["  " + b.verdict for b in fails[:n]]
        lines += [f"note: {t}" for t in self.notes]
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "chi2_per_dof": self.chi2_per_dof,
            "rms_over_noise": self.rms_over_noise,
            "adequate": self.adequate,
            "adequate_rms": ADEQUATE_RMS,
            "blocks_consistent": self.blocks_consistent,
            "alpha": self.alpha,
            "left_out_steps": self.left_out.tolist(),
            "notes": list(self.notes),
            "blocks": [{**b.__dict__, "verdict": b.verdict} for b in self.blocks],
        }


def uncalibrated_note(model: Model) -> str | None:
    """A note when every parameter the model calibrates is still at its nominal value.

    Such a model (the shipped reference rig, or a new model file) has not been calibrated, so a
    misfit of tens of times the noise says that, not that the model misses an effect. None when
    the model has been calibrated (some calibrated parameter left its nominal value) or
    calibrates nothing.
    """
    params = [p for p in model.parameters.values() if p.calibrate]
    if not params or any(not np.isclose(p.value, p.nominal, rtol=1e-9, atol=0.0) for p in params):
        return None
    names = ", ".join(p.name for p in params)
    return (
        f"the model's calibrated parameters ({names}) are all at their nominal values: it has "
        "not been calibrated yet, and the misfit says so. Calibrate it first: "
        "'python -m analysis calibrate-linear RANDOM.h5 --model MODEL --out LIN' (the linear "
        "part, from a random test), then 'python -m analysis calibrate RUN.h5 --model "
        "LIN/calibrated_model.toml --out CAL', and compare CAL/calibrated_model.toml"
    )


def default_bands(frequency_hz: np.ndarray, n_bands: int = 3) -> list[tuple[float, float]]:
    """Bands with equal numbers of steps (resonance regions are sampled densely)."""
    f = np.sort(np.unique(frequency_hz))
    if f.size == 0:
        raise ValueError("no frequencies to divide into bands (no steps)")
    edges = np.quantile(f, np.linspace(0, 1, n_bands + 1))
    return [(float(edges[i]), float(edges[i + 1])) for i in range(n_bands)]


def compare(
    model: Model,
    data: SteppedSineData,
    *,
    channels: Sequence[str] | None = None,
    bands_hz: Sequence[tuple[float, float]] | None = None,
    alpha: float = 0.01,
    predictor: SteppedSinePredictor | None = None,
    include_unconverged: bool = False,
    sigma: str = "model",
) -> Comparison:
    """Normalised residuals and block verdicts of ``model`` against ``data``.

    Parameters
    ----------
    model : Model
    data : SteppedSineData
    channels : sequence of str, optional
        Response channels (default: every motion channel but the drive force).
    bands_hz : sequence of (lo, hi), optional
        Frequency bands of the blocks (default: three with equal numbers of steps).
    alpha : float
        Family-wise significance of the "fails here" verdicts (Bonferroni over the blocks).
    predictor : SteppedSinePredictor, optional
        Default: a :class:`~analysis.predict_branches.BranchMatchedPredictor`, whose
        standard errors carry the force's error through the model.
    sigma : {"model", "file"}
        ``"model"`` (with a :class:`~analysis.predict_branches.BranchMatchedPredictor`): the
        response's error and the force's carried through the model's tangent
        (:meth:`~analysis.predict_branches.BranchMatchedPredictor.response_sigma`), the
        weights a calibration fits with. The model is driven by the measured force, so near
        the fold of a resonance a force error moves its response far more than in
        proportion; at the last steps on the upper branch before a jump that decides the
        score (the exact truth of a 192-period friction run scores 2.29 x noise with
        ``"file"``, 1.43 with ``"model"``). ``"file"``: the file's first-order FRF errors,
        ``|H| sqrt((s_R/|R|)^2 + (s_F/|F|)^2)``, which hold for a linear structure.
    include_unconverged : bool
        Also score the steps the file flags as not converged under force control (by default
        they are left out: their residuals are NaN and :attr:`Comparison.left_out` lists them).
    """
    require_steps(data)
    pred = predictor or BranchMatchedPredictor(model, data, channels=channels)
    H, s = pred.measured()
    scored = np.ones(data.n_steps, bool) if include_unconverged else data.control_converged
    check_standard_errors(
        data,
        pred.channel_names,
        H,
        s,
        rows=scored,
        remedy="the file's standard errors are needed to score a model in units of the noise",
    )
    positive = s[np.isfinite(s) & (s > 0)]
    floor = positive.min() if positive.size else 1.0  # only NaN errors (unscored) left to fill
    if isinstance(pred, BranchMatchedPredictor) and sigma == "model":
        # the force's error propagated through the model (see response_sigma)
        p, s = pred.predict_with_sigma()
    else:
        p = pred.predict()
    sig = np.maximum(np.nan_to_num(s, nan=floor), floor)
    r = (p.frf - H) / sig
    left_out = np.zeros(data.n_steps, bool)
    if not include_unconverged:
        # a step whose force control did not converge is not the planned excitation, and at
        # the fold of a resonance its response is still drifting while it is measured
        left_out = ~np.asarray(data.control_converged, bool)
        r[left_out] = np.nan
    lv = data.levels_n[data.level_index]
    bands = list(bands_hz) if bands_hz is not None else default_bands(data.frequency_hz)
    orders = [str(o) for o in getattr(pred, "compared_orders", data.orders)]
    blocks = []
    for c, ch in enumerate(pred.channel_names):
        for k, o in enumerate(orders):
            for level in sorted(set(lv.tolist())):
                for lo, hi in bands:
                    m = (lv == level) & (data.frequency_hz >= lo) & (data.frequency_hz <= hi)
                    z = r[m, c, k]
                    z = z[np.isfinite(z)]
                    if z.size == 0:
                        continue
                    chi2 = float(2 * np.sum(np.abs(z) ** 2))
                    dof = 2 * z.size
                    pv = float(stats.chi2.sf(chi2, dof))
                    blocks.append(
                        Block(ch, o, float(level), (lo, hi), int(z.size), chi2 / dof, pv, True)
                    )
    per_block = alpha / max(len(blocks), 1)
    blocks = [Block(**{**b.__dict__, "consistent": b.p_value >= per_block}) for b in blocks]
    return Comparison(
        r,
        data.frequency_hz,
        lv,
        pred.channel_names,
        orders,
        bands,
        blocks,
        H,
        p.frf,
        alpha,
        np.flatnonzero(left_out),
        [t for t in [uncalibrated_note(model)] if t],
    )
