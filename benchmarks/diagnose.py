"""Diagnosis on the simulated rig: is the hidden effect found, and does adding it work?

For every shipped truth the paper's two tests are simulated: the stepped multi-sine run
(drive at point 3, accelerometers at 3, 6 and 7, 2/4/6/8 N, orders 1-3 with 2 % side harmonics,
21-40 Hz in 1 Hz steps and 0.1 Hz in 24-28 Hz, swept up) and the linear random test (all 13
points). The nominal model is calibrated the paper's way (linear parameters with damping
equalization on the random test, then k_c, gap and v_c from Latin hypercube starts and
Levenberg-Marquardt on 2/4/6 N), then diagnosed, and the best candidate is added and
everything recalibrated (:func:`analysis.diagnosis.augment`).

How the runs are simulated (the rig's run engine, ``python -m rig run``, does not yet finish
the paper's runs on the simulated backend): the stepped sine is the truth's forced periodic
response by multi-harmonic balance at 20 harmonics and 1024 samples (sensor masses included),
driven by the target force with 0.3 % control errors, with the truth's noise floors on every
phasor (48 averaged periods: standard error ``asd sqrt(2 / T)``); steps where the truth's own
balance does not converge are not recorded. The random test is the H1 of the truth's
underlying linear structure (every element linearised at rest: a friction element sticks as
its regularised damper, a stop or a cubic spring adds nothing) with modal damping and the
sensors' masses, with 2 % complex noise (the random plan's drive at the truth's noise floors
gives no usable coherence off resonance).

Figures (the last JSON line): ``cases`` (per hidden effect: ``truth``, ``true_effect_rank``
(1 = first, or in the first tied group), ``residual_drop`` (residual before over after, root
of chi-square per degree of freedom on the whole file) and ``final_over_noise``),
``negative_control_claims`` (claims made for ``reference`` and ``hysteretic_joint``, whose
effect is outside the library) and ``total_s``.
"""

from __future__ import annotations

import json
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import sim_backend.hysteresis  # noqa: F401  (registers the simulator's Jenkins element)
from analysis.calibration.lhs import paper_distributions
from analysis.calibration.linear import calibrate_linear
from analysis.calibration.nonlinear import level_rows
from analysis.diagnosis import DiagnosisSettings, augment, diagnose
from analysis.linear.modal import modal_analysis
from analysis.measurement_file import (
    Actuator,
    ChannelInfo,
    RandomFRF,
    StepRecord,
    create_stepped_sine,
    read_measurement,
    write_random,
)
from analysis.mhb.solver import NewtonSettings
from analysis.mhb.sweep import solve_steps
from analysis.model import load_model
from analysis.system import attachments, build_problem_dofs
from sim_backend.sizing import paper_frequencies
from sim_backend.truth import load_truth

log = logging.getLogger(__name__)

#: The hidden effect of each truth as a candidate: (kind, location, side).
TRUE_EFFECTS = {
    "hardening_mounts": ("cubic_spring", "mounts", None),
    "clamp_friction": ("coulomb_friction", "joint clamp rz", None),
    "two_sided_stop": ("hertz_contact", "point 7", 1),
    "damper_p5": ("quadratic_damper", "point 5", None),
    "mass_loading": ("mass", "point 6", None),
}
NEGATIVE_CONTROLS = ("reference", "hysteretic_joint")
POSTS = (8, 9, 12, 13)  # points measuring x (the posts' bending direction)


# -- simulated runs ---------------------------------------------------------------------------
def simulate_stepped_sine(
    truth_name: str,
    path: Path,
    *,
    levels_n=(2.0, 4.0, 6.0, 8.0),
    frequencies_hz=None,
    points=(3, 6, 7),
    control_error: float = 0.003,
    record_periods: int = 48,
    n_harmonics: int = 20,
    n_time: int = 1024,
    seed: int = 0,
) -> Path:
    """The paper's stepped sine on a truth (see the module notes); returns ``path``."""
    truth = load_truth(truth_name)
    f = paper_frequencies() if frequencies_hz is None else np.asarray(frequencies_hz, float)
    s = truth.sensors
    masses = {p: (s.impedance_head_mass_kg if p == 3 else s.accelerometer_mass_kg) for p in points}
    model = truth.model.add_masses(masses)
    asm = model.assemble()
    pb = build_problem_dofs(model, [asm.point_dof(3)], [asm.point_dof(p) for p in points],
                            n_harmonics=n_harmonics, n_time=n_time)  # fmt: skip
    chans = [ChannelInfo("force3", 3, "y", "force", "N", 22.5, "mV/N", "drive-force", 0.0, "IH")]
    chans += [
        ChannelInfo(f"acc{p}", p, "y", "acceleration", "m/s^2", 100.0, "mV/g",
                    "drive-acceleration" if p == 3 else "response", masses[p], f"A{p}")
        for p in points
    ]  # fmt: skip
    rng = np.random.default_rng(seed)
    targets = np.array([[lv, 0.02 * lv, 0.02 * lv] for lv in levels_n], complex)
    writer = create_stepped_sine(
        path, channels=chans, actuator=Actuator(3, "y"), levels_n=list(levels_n),
        orders_num=[1, 2, 3], orders_den=[1, 1, 1], force_targets=targets,
        config={"simulated": truth_name, "plan": "paper"}, setup={"backend": "truth MHB"},
        overwrite=True,
    )  # fmt: skip
    k = np.arange(1, 4)
    newton = NewtonSettings(rtol=1e-9, max_iterations=80, stall_window=20)
    plan = 0
    with writer:
        for li, lv in enumerate(levels_n):
            e = rng.standard_normal((f.size, 3)) + 1j * rng.standard_normal((f.size, 3))
            F = targets[li][None, :] * (1 + control_error * e)
            res = solve_steps(pb, 2 * np.pi * f, F[:, :, None], settings=newton)
            for j, p in enumerate(res.points):
                if not p.converged:
                    plan += 1
                    continue
                om = 2 * np.pi * f[j]
                acc = (-((k * om) ** 2))[:, None] * p.outputs()
                resp = np.concatenate([F[j][None, :], acc.T])
                std = np.empty((len(points) + 1, 3))
                root = np.sqrt(2 * f[j] / record_periods)
                std[0] = truth.noise.force_n_per_rthz * root
                std[1:] = truth.noise.acceleration_ms2_per_rthz * root
                noise = rng.standard_normal(std.shape) + 1j * rng.standard_normal(std.shape)
                meas = resp + std / np.sqrt(2) * noise
                writer.append_step(StepRecord(
                    plan_index=plan, level_index=li, sweep_direction=1,
                    frequency_target_hz=float(f[j]), frequency_hz=float(f[j]), force=meas[0],
                    force_std=std[0], response=meas, response_std=std, drive=0.1 * F[j],
                    n_blocks=record_periods, control_iterations=2, control_converged=True,
                    control_error=float(np.max(np.abs(F[j] - targets[li])) / lv),
                ))  # fmt: skip
                plan += 1
        writer.finish("success", "simulated from the truth")
    return Path(path)


def simulate_linear_test(
    truth_name: str,
    path: Path,
    *,
    band_hz=(5.0, 200.0),
    df_hz: float = 0.125,
    noise: float = 0.02,
    seed: int = 0,
) -> Path:
    """The linear random test on a truth (see the module notes); returns ``path``."""
    truth = load_truth(truth_name)
    s = truth.sensors
    masses = {p: s.accelerometer_mass_kg for p in range(1, 14)}
    masses[3] = s.impedance_head_mass_kg
    model = truth.model.add_masses(masses)
    asm = model.assemble()
    K, Cel = np.array(asm.K), np.zeros_like(asm.K)
    for att in attachments(model):  # each element linearised at rest
        ev = att.element.evaluate(np.zeros(1), np.zeros(1))
        inc = [(att.dof_a, 1.0)] + ([(att.dof_b, -1.0)] if att.dof_b is not None else [])
        for i, si in inc:
            for j, sj in inc:
                K[i, j] -= si * sj * float(ev.df_du[0])
                Cel[i, j] -= si * sj * float(ev.df_dv[0])
    d = model.damping
    modes = modal_analysis(asm.M, asm.K, dict(d.per_mode), default_zeta=d.default_zeta)
    Mphi = asm.M @ modes.phi
    Ctot = Cel + Mphi @ np.diag(2 * modes.zeta * modes.omega) @ Mphi.T
    freq = np.arange(round(band_hz[0] / df_hz), round(band_hz[1] / df_hz) + 1) * df_hz
    drive = asm.point_dof(3, "y")
    chans = [ChannelInfo("force3", 3, "y", "force", "N", 22.4, "mV/N", "drive-force", 0.0, "IH")]
    rows = []
    for p in range(1, 14):
        direction = "x" if p in POSTS else "y"
        chans.append(ChannelInfo(f"acc{p}", p, direction, "acceleration", "m/s^2", 100.0,
                                 "mV/g", "drive-acceleration" if p == 3 else "response",
                                 masses[p], f"A{p}"))  # fmt: skip
        rows.append(asm.point_dof(p, direction))
    e = np.zeros(asm.n_dofs)
    e[drive] = 1.0
    h1 = np.ones((freq.size, 14), complex)
    for i, fi in enumerate(freq):
        w = 2 * np.pi * fi
        x = np.linalg.solve(K - w * w * asm.M + 1j * w * Ctot, e)
        h1[i, 1:] = -w * w * x[rows]
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((freq.size, 13)) + 1j * rng.standard_normal((freq.size, 13))
    h1[:, 1:] *= 1 + noise / np.sqrt(2) * z
    frf = RandomFRF(frequency_hz=freq, h1=h1, coherence=np.full(h1.shape, 1 / (1 + noise**2)),
                    force_psd=np.full(freq.size, 0.09 / (band_hz[1] - band_hz[0])),
                    n_averages=8, window="boxcar", overlap=0.0, fs_hz=2560.0,
                    rms_force_n=0.3)  # fmt: skip
    return write_random(path, channels=chans, actuator=Actuator(3, "y"), frf=frf,
                        config={"simulated": truth_name, "plan": "linear"},
                        setup={"backend": "truth linearised"}, overwrite=True)  # fmt: skip


# -- the paper's calibration ------------------------------------------------------------------
def calibrate_paper_way(stepped: Path, linear: Path, *, n_starts: int = 30, seed: int = 0):
    """Nominal model -> linear calibration on the random test -> k_c, gap, v_c from Latin
    hypercube starts and LM on 2/4/6 N (on the measured branch)."""
    from analysis.diagnosis import refit

    lin = calibrate_linear(load_model(), linear).model
    data = read_measurement(stepped)
    levels = sorted(float(x) for x in data.levels_n)
    rows = level_rows(data, levels[:-1] if len(levels) >= 3 else levels)
    fit = refit(lin, data, ("k_c", "gap", "v_c"), rows=rows,
                distributions=paper_distributions(lin.parameters["gap"].nominal),
                n_random_starts=n_starts, seed=seed)  # fmt: skip
    return fit.model, data


def _rank(diag, truth: str) -> int:
    kind, location, side = TRUE_EFFECTS[truth]
    r = diag.rank_of(kind, location, side)
    if r is not None:
        return r
    for i, f in enumerate(diag.screen):
        c = f.candidate
        if (
            c.law.kind == kind
            and c.location.name == location
            and (side is None or c.law.options.get("side") == side)
        ):
            return len(diag.ranking) + i + 1
    return len(diag.ranking) + len(diag.screen) + 1


def run_case(truth: str, folder: Path, *, quick: bool = False, seed: int = 0) -> dict:
    """Simulate, calibrate, diagnose and (for a hidden effect) augment one truth."""
    t0 = time.perf_counter()
    f = None if not quick else np.unique(np.round(np.concatenate(
        [np.arange(21.0, 40.5, 1.0), np.arange(24.0, 28.05, 0.2)]), 6))  # fmt: skip
    stepped = simulate_stepped_sine(truth, folder / f"{truth}.h5", frequencies_hz=f, seed=seed)
    linear = simulate_linear_test(truth, folder / f"{truth}_linear.h5", seed=seed)
    model, data = calibrate_paper_way(stepped, linear, n_starts=12 if quick else 30, seed=seed)
    model.save(folder / f"{truth}_calibrated.toml")
    t1 = time.perf_counter()
    diag = diagnose(model, data, linear_run=linear, settings=DiagnosisSettings())
    t2 = time.perf_counter()
    out = {
        "truth": truth,
        "verdict": diag.verdict,
        "group": [r.candidate.label for r in diag.group],
        "rms_before": diag.comparison.rms_over_noise,
        "calibration_s": round(t1 - t0, 1),
        "diagnosis_s": round(t2 - t1, 1),
    }
    print(f"--- {truth}: {diag.verdict}, {time.perf_counter() - t0:.0f} s so far")
    print(diag.summary())
    if truth in TRUE_EFFECTS:
        out["true_effect_rank"] = _rank(diag, truth)
        pick = diag.group[0] if diag.group else (diag.ranking[0] if diag.ranking else None)
        if pick is not None:
            res = augment(model, data, pick.candidate, values=dict(pick.screen.values),
                          known=dict(pick.screen.known), linear_run=linear,
                          n_starts=4 if quick else 8, out=folder / f"{truth}_augmented.toml",
                          seed=seed)  # fmt: skip
            print(res.summary())
            out.update(residual_drop=res.residual_drop,
                       final_over_noise=res.after.rms_over_noise,
                       augment_s=round(res.seconds, 1))  # fmt: skip
        else:
            out.update(residual_drop=1.0, final_over_noise=diag.comparison.rms_over_noise)
    out["total_s"] = round(time.perf_counter() - t0, 1)
    return out


def run(quick: bool = False) -> dict:
    """All truths (``quick``: the damper and the reference on a coarser grid)."""
    t0 = time.perf_counter()
    truths = ["damper_p5"] if quick else list(TRUE_EFFECTS)
    controls = ["reference"] if quick else list(NEGATIVE_CONTROLS)
    cases, claims, details = [], 0, []
    with tempfile.TemporaryDirectory(prefix="diagnose-bench-") as tmp:
        folder = Path(tmp)
        for truth in truths:
            r = run_case(truth, folder, quick=quick)
            details.append(r)
            cases.append({k: r[k] for k in ("truth", "true_effect_rank", "residual_drop",
                                             "final_over_noise")})  # fmt: skip
        for truth in controls:
            r = run_case(truth, folder, quick=quick)
            details.append(r)
            claims += int(r["verdict"] == "explained")
    print(json.dumps({"details": details}, default=str))
    return {
        "cases": cases,
        "negative_control_claims": claims,
        "total_s": round(time.perf_counter() - t0, 1),
    }


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    print(json.dumps(run(quick="--quick" in sys.argv[1:])))
