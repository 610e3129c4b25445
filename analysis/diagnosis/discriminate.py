"""The measurement that separates tied candidates (neighbouring locations, look-alike laws).

Each tied model (recalibrated in the full model) is swept as a pretest plan would sweep it
(:class:`analysis.planning.sweeps.SweepJob`: drive at the file's actuator, each candidate level,
each of the paper's frequency ranges, outputs at every measurement point) and the
*discriminating power* of a (sensor, level, range) is the RMS over its steps and orders of
``|Y_a - Y_b| / sigma`` for the pair of candidates it separates worst, ``sigma`` the planning
noise model's standard error of each phasor (:func:`analysis.planning.information.phasor_sigma`).
The best configuration is the one a test should add.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from analysis.measurement_file import SteppedSineData
from analysis.model import Model
from analysis.planning.candidates import PAPER_RANGES, FrequencyRange, NoiseModel
from analysis.planning.information import phasor_sigma
from analysis.planning.sweeps import SweepJob, run_sweep

__all__ = ["discriminate"]


def discriminate(
    group: Sequence,
    data: SteppedSineData,
    *,
    levels_n: Sequence[float] | None = None,
    ranges: Sequence[FrequencyRange] = PAPER_RANGES,
    noise: NoiseModel | None = None,
    n_best: int = 5,
) -> dict:
    """Discriminating power of every (sensor, level, range) for a group of tied candidates.

    Parameters
    ----------
    group : sequence of RankedCandidate
        The tied candidates (their recalibrated models).
    data : SteppedSineData
        The file (actuator, levels and side-harmonic ratios).
    levels_n : sequence of float, optional
        Candidate levels (default: the file's).
    ranges : sequence of FrequencyRange
        Candidate frequency ranges (default: the paper's seven 20 Hz ranges).
    noise : NoiseModel, optional
        Default: the planning default (2 % and 0.01 m/s^2).

    Returns
    -------
    dict
        ``best`` (sensor, level_n, range, power), ``table`` (the ``n_best`` best) and ``text``.
    """
    if len(group) < 2:
        raise ValueError("discrimination needs at least two tied candidates")
    noise = noise or NoiseModel()
    levels = list(levels_n) if levels_n is not None else sorted(float(x) for x in data.levels_n)
    ratio = data.force_targets[0] / data.force_targets[0][0]
    models = [Model.from_toml_text(g.verified.model_toml, "<tied candidate>") for g in group]
    sensors = tuple(sorted(models[0].points))
    act = data.actuator.point
    outputs = {}
    for m_i, model in enumerate(models):
        text = model.to_toml()
        # a sweep job differentiates with respect to at least one parameter (unused here)
        any_param = (model.parameter_names(group="nonlinear") or model.parameter_names())[:1]
        for li, lv in enumerate(levels):
            for ri, rg in enumerate(ranges):
                job = SweepJob(
                    text,
                    act,
                    tuple(complex(lv * r) for r in ratio),
                    tuple(rg.frequencies_hz().tolist()),
                    sensors,
                    tuple(any_param),
                    orders=tuple(data.orders),
                )
                outputs[m_i, li, ri] = run_sweep(job)
    rows: list[dict[str, Any]] = []
    for li, lv in enumerate(levels):
        for ri, rg in enumerate(ranges):
            worst = None
            for a, b in itertools.combinations(range(len(models)), 2):
                sa, sb = outputs[a, li, ri], outputs[b, li, ri]
                f = np.intersect1d(sa.frequency_hz, sb.frequency_hz)
                if f.size == 0:
                    continue
                ia, ib = np.isin(sa.frequency_hz, f), np.isin(sb.frequency_hz, f)
                sig = phasor_sigma(sa, sensors, noise)[ia]
                d = np.abs(sa.outputs[ia] - sb.outputs[ib]) / sig  # (n, K, S)
                with np.errstate(invalid="ignore"):
                    power = np.sqrt(
                        np.nanmean(np.where(np.isfinite(d), d, np.nan) ** 2, axis=(0, 1))
                    )
                worst = power if worst is None else np.minimum(worst, power)
            if worst is None:
                continue
            for si, s in enumerate(sensors):
                rows.append(
                    {
                        "sensor": int(s),
                        "level_n": float(lv),
                        "range": rg.label,
                        "start_hz": float(rg.start_hz),
                        "stop_hz": float(rg.stop_hz),
                        "step_hz": float(rg.step_hz),
                        "power": float(worst[si]),
                    }
                )
    rows.sort(key=lambda r: -r["power"] if np.isfinite(r["power"]) else np.inf)
    if not rows:
        raise RuntimeError("no configuration converged for every tied candidate")
    best = rows[0]
    measured = {ch.point for ch in data.channels}
    text = (
        f"add a sensor at point {best['sensor']}"
        if best["sensor"] not in measured
        else f"use point {best['sensor']}"
    ) + (
        f" at {best['level_n']:g} N in {best['range']} Hz: the tied candidates' predictions "
        f"differ there by {best['power']:.3g} standard errors (RMS, worst pair)"
    )
    return {
        "best": best,
        "table": rows[:n_best],
        "text": text,
        "candidates": [g.candidate.label for g in group],
    }
