"""The measurement that separates tied candidates (neighbouring locations, look-alike laws).

Each tied model (recalibrated in the full model) is swept as a pretest plan would sweep it
(:class:`analysis.planning.sweeps.SweepJob`: drive at the file's actuator, each candidate level,
each of the paper's frequency ranges, outputs at every measurement point) and the
*discriminating power* of a (sensor, level, range) is the RMS over its steps and orders of
``|Y_a - Y_b| / sigma`` for the pair of candidates it separates worst, ``sigma`` the standard
error of each phasor (:func:`analysis.planning.information.phasor_sigma`) with each sensor's
floor read from the file (:func:`file_noise`): a sensor whose point hardly moves in a band is
worth nothing there if its noise is larger than the difference, whatever a default floor says.
Besides the paper's ranges, a band around each mode of the structure below their top that none
of them covers (:func:`mode_ranges`): tied places differ most where they move, and a place the
paper's band hardly moves (a mount, in the frame's suspension modes below it) moves most in its
own modes. The best configuration is the one a test should add, among those the rig's drive
can run: where
the file's lab setup gives the shaker's armature mass and force constant and the amplifier's
current limit (:class:`analysis.planning.drive_current.ShakerDrive`), a (level, range) whose
predicted coil current exceeds the usable share of the limit for any tied candidate is left out
(it would trip the amplifier at the drive point's resonance).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from analysis.measurement_file import SteppedSineData
from analysis.model import Model
from analysis.planning.candidates import PAPER_RANGES, FrequencyRange, NoiseModel
from analysis.planning.drive_current import ShakerDrive
from analysis.planning.information import phasor_sigma
from analysis.planning.sweeps import SweepJob, run_sweep

__all__ = ["discriminate", "file_noise", "mode_ranges"]


def discriminate(
    group: Sequence,
    data: SteppedSineData,
    *,
    levels_n: Sequence[float] | None = None,
    ranges: Sequence[FrequencyRange] | None = None,
    noise: NoiseModel | None = None,
    n_best: int = 5,
    drive: ShakerDrive | None = None,
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
        Candidate frequency ranges (default: the paper's seven 20 Hz ranges and
        :func:`mode_ranges` of the first candidate's model).
    noise : NoiseModel, optional
        Default: :func:`file_noise` of ``data``.
    drive : ShakerDrive, optional
        The shaker and amplifier (default: from the file's lab setup; none there, the current
        is not checked).

    Returns
    -------
    dict
        ``best`` (sensor, level_n, range, power, current_a: the predicted peak coil current,
        None when unknown), ``table`` (the ``n_best`` best), ``text`` and ``excluded`` (the
        levels and ranges left out for the current, with it).

    Raises
    ------
    RuntimeError
        When no configuration converged for every candidate, or every one needs more current
        than the amplifier gives.
    """
    if len(group) < 2:
        raise ValueError("discrimination needs at least two tied candidates")
    noise = noise or file_noise(data)
    levels = list(levels_n) if levels_n is not None else sorted(float(x) for x in data.levels_n)
    ratio = data.force_targets[0] / data.force_targets[0][0]
    masses = _sensor_masses(data)
    models = []
    for g in group:
        model = Model.from_toml_text(g.verified.model_toml, "<tied candidate>")
        # the rig runs the test with the file's sensors on, and their masses move the modes
        # (2.5 Hz at the beam's second bending mode), as the comparison's prediction has them
        models.append(model.add_masses(masses) if masses else model)
    if ranges is None:
        ranges = (*PAPER_RANGES, *mode_ranges(models[0], PAPER_RANGES))
    sensors = tuple(sorted(models[0].points))
    act = data.actuator.point
    drive = drive if drive is not None else ShakerDrive.from_setup(getattr(data, "setup", None))
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
    excluded: list[dict[str, Any]] = []
    for li, lv in enumerate(levels):
        for ri, rg in enumerate(ranges):
            sweeps = [outputs[m, li, ri] for m in range(len(models))]
            current = _peak_current(drive, sweeps, sensors.index(act))
            if drive is not None and current is not None and current > drive.usable_current_a:
                excluded.append({"level_n": float(lv), "range": rg.label, "current_a": current})
                continue
            worst = _worst_pair_power(sweeps, sensors, noise)
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
                        "current_a": current,
                    }
                )
    rows.sort(key=lambda r: -r["power"] if np.isfinite(r["power"]) else np.inf)
    if not rows and excluded and drive is not None:
        least = min(excluded, key=lambda e: e["current_a"])
        raise RuntimeError(
            f"every level and range needs more coil current than the amplifier gives: the least, "
            f"{least['level_n']:g} N in {least['range']} Hz, needs {least['current_a']:.3g} A "
            f"against {drive.usable_current_a:.3g} A usable (of its {drive.current_limit_a:g} A "
            "limit); give lower levels"
        )
    if not rows:
        raise RuntimeError("no configuration converged for every tied candidate")
    best = rows[0]
    # the loop check drives at a low level: read where the sensors move from the lowest
    # level's sweeps (near the linear structure's response; at the plan's level a stiffening
    # law can jump near a mode, and its unconverged steps say nothing there)
    li = int(np.argmin(levels))
    ri = next(i for i, r in enumerate(ranges) if r.label == best["range"])
    best["loop_check_hz"] = _loop_check_hz(
        [outputs[m, li, ri] for m in range(len(models))],
        sensors,
        sorted({int(ch.point) for ch in data.channels} | {best["sensor"]}),
    )
    return {
        "best": best,
        "table": rows[:n_best],
        "text": _text(best, data, drive, excluded),
        "candidates": [g.candidate.label for g in group],
        "excluded": excluded,
    }


def file_noise(data: SteppedSineData) -> NoiseModel:
    """The noise of the file's accelerometers as a planning noise model.

    Each acceleration channel's floor is the median over its steps and orders of the file's
    standard error (``response_std``, of the complex phasor) over sqrt(2), the standard error
    of each real part, as :class:`~analysis.planning.candidates.NoiseModel` takes it; two
    sensors at one point, the quieter. A point the file does not measure (a sensor the
    discrimination may propose) gets the median of the file's accelerometers: the same kind
    of sensor on the same rig. The relative part stays the planning default's 2 %, the
    paper's bound on what is proportional to the response (calibration, drift), which a
    file's scatter does not show. A file without accelerometers gives the planning default.

    The median is over the file's frequencies; a white floor's phasor error grows as the
    square root of the frequency at a fixed number of recorded periods, so in a band below the
    file's the floor is overstated, never understated.
    """
    per_point: dict[int, float] = {}
    for c, ch in enumerate(data.channels):
        if ch.quantity != "acceleration":
            continue
        std = np.asarray(data.response_std[:, c, :], float)
        std = std[np.isfinite(std) & (std > 0)]
        if std.size == 0:
            continue
        floor = float(np.median(std)) / math.sqrt(2.0)
        point = int(ch.point)
        per_point[point] = min(floor, per_point.get(point, math.inf))
    if not per_point:
        return NoiseModel()
    return NoiseModel(floor=float(np.median(list(per_point.values()))), sensor_floors=per_point)


#: Half-width of the band around a mode, as a share of its frequency, and its steps per band.
MODE_BAND = 0.15
MODE_BAND_STEPS = 30


def mode_ranges(model: Model, covered: Sequence[FrequencyRange]) -> list[FrequencyRange]:
    """A band of +-:data:`MODE_BAND` around each mode of ``model``'s linear structure below
    the top of ``covered`` that no range of ``covered`` holds, stepped in
    :data:`MODE_BAND_STEPS` (to 0.05 Hz), overlapping bands merged."""
    top = max(r.stop_hz for r in covered)
    freqs, _ = model.assemble().normal_modes()
    bands: list[list[float]] = []
    for f in sorted(float(x) for x in freqs if 0 < x < top):
        if any(r.start_hz <= f <= r.stop_hz for r in covered):
            continue
        lo, hi = (1 - MODE_BAND) * f, min((1 + MODE_BAND) * f, top)
        if bands and lo <= bands[-1][1]:
            bands[-1][1] = max(bands[-1][1], hi)
        else:
            bands.append([lo, hi])
    out = []
    for lo, hi in bands:
        step = max(round((hi - lo) / MODE_BAND_STEPS / 0.05) * 0.05, 0.05)
        lo = round(lo / 0.05) * 0.05
        n = max(int(round((hi - lo) / step)), 1)
        out.append(FrequencyRange(round(lo, 2), round(lo + n * step, 2), round(step, 2)))
    return out


def _loop_check_hz(sweeps: Sequence, sensors: tuple[int, ...], used: Sequence[int]) -> float:
    """The step of the plan's range (``sweeps``: one per tied candidate) where the plan's
    sensors (``used``) respond most to the fundamental, the weakest of them for the weakest
    candidate. The rig's loop check drives at one frequency at a low level and takes a sensor
    that hardly moves for a disconnected one: below a structure's modes an accelerometer sees
    little, so the check runs where all of them move, not at the plan's first step; inside
    the plan's range, so that the force per volt it measures holds for the first steps."""
    cols = [sensors.index(p) for p in used if p in sensors]
    if not cols or not sweeps:
        return math.nan
    # a step counts only where every candidate converged
    common = sweeps[0].frequency_hz
    for sw in sweeps[1:]:
        common = np.intersect1d(common, sw.frequency_hz)
    weakest = np.full(common.size, np.inf)
    for sw in sweeps:
        k1 = int(np.argmin(np.abs(np.asarray(sw.order_values, float) - 1.0)))
        rows = np.isin(sw.frequency_hz, common)
        omega = 2 * np.pi * sw.frequency_hz[rows]
        acc = np.abs(sw.outputs[rows, k1][:, cols]) * omega[:, None] ** 2
        weakest = np.minimum(weakest, acc.min(axis=1))
    ok = np.isfinite(weakest)
    if not ok.any():
        return math.nan
    return float(common[ok][np.argmax(weakest[ok])])


def _worst_pair_power(sweeps: Sequence, sensors: tuple[int, ...], noise: NoiseModel):
    """Per sensor, the discriminating power of the pair of candidates it separates worst
    (None when no pair has a common converged step)."""
    worst = None
    for sa, sb in itertools.combinations(sweeps, 2):
        f = np.intersect1d(sa.frequency_hz, sb.frequency_hz)
        if f.size == 0:
            continue
        ia, ib = np.isin(sa.frequency_hz, f), np.isin(sb.frequency_hz, f)
        sig = phasor_sigma(sa, sensors, noise)[ia]
        d = np.abs(sa.outputs[ia] - sb.outputs[ib]) / sig  # (n, K, S)
        with np.errstate(invalid="ignore"):
            power = np.sqrt(np.nanmean(np.where(np.isfinite(d), d, np.nan) ** 2, axis=(0, 1)))
        worst = power if worst is None else np.minimum(worst, power)
    return worst


def _text(best: dict, data: SteppedSineData, drive: ShakerDrive | None, excluded: list) -> str:
    measured = {ch.point for ch in data.channels}
    text = (
        f"add a sensor at point {best['sensor']}"
        if best["sensor"] not in measured
        else f"use point {best['sensor']}"
    ) + (
        f" at {best['level_n']:g} N in {best['range']} Hz: the tied candidates' predictions "
        f"differ there by {best['power']:.3g} standard errors (RMS, worst pair)"
    )
    if drive is not None:
        text += (
            f"; the shaker needs up to {best['current_a']:.2g} A of the amplifier's "
            f"{drive.current_limit_a:g} A"
        )
        if excluded:
            text += f" ({len(excluded)} level(s) and range(s) needing more left out)"
    return text


def _sensor_masses(data: SteppedSineData) -> dict[int, float]:
    """The mass each of the file's sensors adds at its point [kg] (as the comparison's)."""
    masses: dict[int, float] = {}
    for ch in data.channels:
        m = float(getattr(ch, "mass_kg", 0.0))
        if m > 0:
            masses[int(ch.point)] = masses.get(int(ch.point), 0.0) + m
    return masses


def _peak_current(drive: ShakerDrive | None, sweeps: Sequence, column: int) -> float | None:
    """The largest peak coil current any candidate's sweep needs [A] (None without a drive);
    ``column`` is the drive point's among the sweeps' outputs."""
    if drive is None:
        return None
    peak = 0.0
    for sw in sweeps:
        if sw.frequency_hz.size == 0:
            continue
        omega = 2 * np.pi * sw.frequency_hz[:, None] * sw.order_values[None, :]
        x = sw.outputs[:, :, column]
        peak = max(peak, float(drive.peak_current_a(sw.force, x, omega).max()))
    return peak
