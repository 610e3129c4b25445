"""Diagnosis on the simulated rig: is the hidden effect found, and does adding it work?

For every shipped truth the rig's own engine runs the stepped multi-sine test on the simulated
backend (:func:`stepped_run`: the paper's plan, drive at point 3, accelerometers at 3, 6 and
7, 2/4/6/8 N, orders 1-3 with 2 % side harmonics, 21-40 Hz in 1 Hz steps and 0.1 Hz in
24-28 Hz, swept up), with one change: the force controller also holds the force's orders 4-8
at zero and the file records them. The contact's impacts make the shaker push back at those
orders (up to 12 % of the fundamental at 8 N on the simulated rig); a model driven by the
force's orders 1-3 alone cannot follow that at the file's noise, whatever its physics. Each
step averages the plan's 48 periods, or ``$CLEARANCE_RIG_RECORD_BLOCKS`` (192 halves the
noise of every phasor: a misfit is judged against the noise; the weakest hidden effect, the
mounts' hardening, is measured with quieter accelerometers by its truth for that reason).
The linear random test is :func:`linear_run`. Runs are made once and kept in a
cache folder (``$CLEARANCE_RIG_CACHE``, default ``~/.cache/clearance-rig/diagnose``), keyed by
the truth file, the plan, the seed and the code that makes them (the simulated rig's and the
rig's engine's sources); making them is timed apart (``data_s``) and not part of
``total_s``.

Then the nominal model is calibrated the paper's way (linear parameters with damping
equalization on the random test, then k_c, gap and v_c from Latin hypercube starts and
Levenberg-Marquardt on 2/4/6 N, on the measured branch), diagnosed
(:func:`analysis.diagnosis.diagnose`), and the best candidate is added and everything
recalibrated (:func:`analysis.diagnosis.augment`).

Figures (the last JSON line): ``cases`` (per hidden effect: ``truth``, ``true_effect_rank``
(1 = first, or in the first tied group), ``residual_drop`` (residual before over after, root
of chi-square per degree of freedom on the whole file with its uncertainties) and
``final_over_noise``), ``negative_control_claims`` (claims made for ``reference`` and
``hysteretic_joint``, whose effect is outside the library), ``candidates`` (per truth, the
candidates screened: nonlinear and linear), ``ties_resolved`` (per truth whose diagnosis tied:
the separating plan, written by the analysis and read by the rig, run on the simulated rig,
and the true effect first alone on the new file; the effect added is then the new file's
best), ``max_diagnosis_s`` and ``total_s`` (calibrations, diagnoses and augmentations); per
truth the details (``details``) with the times of each part.
The machine's speed drifts (the same calibration took up to 45 % longer twenty minutes
later): just before each diagnosis the paper sweep of :mod:`benchmarks.mhb` is timed
(``paper_sweep_s``, its range over the cases at the top level), and each diagnosis is also
given in those sweeps (``diagnosis_in_sweeps``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import os
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

from analysis.calibration.lhs import paper_distributions
from analysis.calibration.linear import calibrate_linear
from analysis.calibration.nonlinear import fitted_rows
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
from analysis.paper import paper_frequencies_hz
from analysis.system import attachments, build_problem_dofs
from benchmarks.mhb import paper_sweep_s
from sim_backend.truth import TRUTH_DIR, load_truth

log = logging.getLogger(__name__)

#: The hidden effect of each truth as a candidate: (kind, location, side).
TRUE_EFFECTS = {
    "hardening_mounts": ("cubic_spring", "springs k_mount", None),
    "clamp_friction": ("coulomb_friction", "joint clamp rz", None),
    "two_sided_stop": ("hertz_contact", "point 7", 1),
    "damper_p5": ("quadratic_damper", "point 5", None),
    "mass_loading": ("mass", "point 6", None),
    # One spring of the mounts' group (in a direction no sensor measures), a beam point no
    # sensor is at, a stop between the tip and the frame (between two nodes), a damper whose
    # neighbours come within about 1 x noise (RMS) of it in the paper's band (its truth file).
    # The tie a second test separates is hardening_mounts': in the paper's band the four
    # mounts and the right mount's vertical spring alone fit within 1 BIC.
    "one_mount_hardens": ("cubic_spring", "spring mount_right_y", None),
    "stop_above_p5": ("hertz_contact", "point 5", 1),
    "tip_to_frame_stop": ("hertz_contact", "point 7 to right_top y", 1),
    "damper_p4": ("quadratic_damper", "point 4", None),
}
NEGATIVE_CONTROLS = ("reference", "hysteretic_joint")
#: Highest order of the force the controller holds (at zero beyond the excited ones).
HELD_ORDERS = 8
POSTS = (8, 9, 12, 13)  # points measuring x (the posts' bending direction)


def _accelerometer(point: int, direction: str, mass_kg: float) -> ChannelInfo:
    """The channel table's row of the 100 mV/g accelerometer at ``point`` (the drive point's
    is the impedance head's acceleration half)."""
    role = "drive-acceleration" if point == 3 else "response"
    return ChannelInfo(
        f"acc{point}",
        point,
        direction,
        "acceleration",
        "m/s^2",
        100.0,
        "mV/g",
        role,
        mass_kg,
        f"A{point}",
    )


# -- runs on the simulated rig ---------------------------------------------------------------
def cache_dir() -> Path:
    """Where the simulated runs are kept."""
    default = Path.home() / ".cache" / "clearance-rig" / "diagnose"
    return Path(os.environ.get("CLEARANCE_RIG_CACHE", default))


def record_blocks() -> int | None:
    """Periods averaged per recorded step: ``$CLEARANCE_RIG_RECORD_BLOCKS``, or None (the
    plan's)."""
    text = os.environ.get("CLEARANCE_RIG_RECORD_BLOCKS", "").strip()
    if not text:
        return None
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"CLEARANCE_RIG_RECORD_BLOCKS must be a whole number >= 1, not {text!r}")
    return int(text)


def benchmark_plan(quick: bool = False, blocks: int | None = None):
    """The paper's plan with the force's orders up to :data:`HELD_ORDERS` held at zero and
    ``blocks`` periods recorded per step (None: the plan's 48; ``quick``: 2, 5 and 8 N, 0.2 Hz
    steps in 24-28 Hz)."""
    from rig.config.plans import load_plan

    plan = load_plan("paper")
    ex = plan.excitation
    k = len(ex.orders)
    orders = (*ex.orders, *(Fraction(i) for i in range(k + 1, HELD_ORDERS + 1)))
    pad = HELD_ORDERS - k
    excitation = dataclasses.replace(
        ex,
        orders=orders,
        relative_amplitudes=(*ex.relative_amplitudes, *(0.0,) * pad),
        phases_deg=(*ex.phases_deg, *(0.0,) * pad),
        levels_n=(2.0, 5.0, 8.0) if quick else ex.levels_n,
    )
    changes = {"excitation": excitation, "name": "paper-held" + ("-quick" if quick else "")}
    if blocks is not None:
        changes["acquisition"] = dataclasses.replace(plan.acquisition, record_blocks=blocks)
    if quick:
        fr = plan.frequencies
        ranges = tuple(
            dataclasses.replace(r, step_hz=0.2) if r.step_hz < 1 else r for r in fr.ranges
        )
        changes["frequencies"] = dataclasses.replace(fr, ranges=ranges)
    return dataclasses.replace(plan, **changes)


def _key(*parts: str) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode())
    return h.hexdigest()[:12]


#: The code that makes the simulated runs: the simulated rig, the rig's engine and the parts
#: of the analysis the simulated rig balances and builds its structure with.
RUN_CODE = (
    "sim_backend",
    "rig",
    "analysis/mhb",
    "analysis/elements",
    "analysis/linear",
    "analysis/fe",
    "analysis/system.py",
    "analysis/model.py",
    "analysis/model_file.py",
)


#: Command-line front ends and stages that run commands but make no data themselves.
#: (file names in rig/cli/, folders of rig/)
FRONT_ENDS = ("gui", "service", "main.py", "service.py", "workflow.py", "separate.py", "export")


@functools.cache
def _code_version(skip: tuple[str, ...] = ("gui", "service")) -> str:
    """A digest of the code that makes the simulated runs (:data:`RUN_CODE`, without the
    parts named in ``skip``: folders or file names): a run cached by other code is made
    again, not reused."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for part in RUN_CODE:
        path = root / part
        for f in sorted(path.rglob("*.py")) if path.is_dir() else [path]:
            if not set(skip) & set(f.relative_to(root).parts):
                h.update(f.relative_to(root).as_posix().encode())
                h.update(f.read_bytes())
    return h.hexdigest()


def stepped_run(truth: str, folder: Path, *, quick: bool = False, seed: int = 0):
    """The stepped-sine run of ``truth`` on the simulated rig (made once, then cached).

    Returns
    -------
    path : Path
    seconds : float
        Wall time spent making it (0 when taken from the cache).
    """
    return simulated_run(truth, benchmark_plan(quick, record_blocks()), folder, seed=seed)


def simulated_run(truth: str, plan, folder: Path, *, seed: int = 0, stem: str | None = None):
    """``plan`` run by the rig's engine on the simulated rig of ``truth`` (made once, then
    cached under ``stem``, default the truth's name). Returns ``(path, seconds)``."""
    from rig.config.setup import load_setup
    from rig.run.session import TestRun, open_rig

    text = (TRUTH_DIR / f"{truth}.toml").read_text()
    key = _key(text, json.dumps(plan.to_dict(), default=str), str(seed), _code_version(FRONT_ENDS))
    path = folder / f"{stem or truth}-{key}.h5"
    if path.exists():
        try:
            if read_measurement(path).complete:
                return path, 0.0
        except (OSError, ValueError):
            pass
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    setup = load_setup(plan.setup)
    quiet = {n: logging.getLogger(n).level for n in ("sim_backend", "analysis.mhb", "rig")}
    for n in quiet:
        logging.getLogger(n).setLevel(logging.CRITICAL)
    try:
        with open_rig(
            "sim", setup, backend_options={"truth": truth, "seed": seed}, lock_dir=folder / "locks"
        ) as rig:
            run = TestRun(rig.backend, plan, setup, path, amplifier=rig.amplifier, overwrite=True)
            summary = run.execute()
    finally:
        for n, level in quiet.items():
            logging.getLogger(n).setLevel(level)
    if summary.status != "success":
        raise RuntimeError(f"the simulated run of {truth} ended early: {summary.message}")
    return path, time.perf_counter() - t0


def linear_run(truth: str, folder: Path, *, seed: int = 0):
    """The linear random test of ``truth`` (made once, then cached): see
    :func:`simulate_linear_test`. Returns ``(path, seconds)``."""
    text = (TRUTH_DIR / f"{truth}.toml").read_text()
    path = folder / f"{truth}-linear-{_key(text, 'synthetic-2', str(seed))}.h5"
    if path.exists():
        return path, 0.0
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    simulate_linear_test(truth, path, seed=seed)
    return path, time.perf_counter() - t0


def simulate_linear_test(
    truth_name: str,
    path: Path,
    *,
    band_hz=(5.0, 200.0),
    df_hz: float = 0.125,
    noise: float = 0.02,
    seed: int = 0,
) -> Path:
    """The linear random test on a truth, synthesised: the H1 of the truth's underlying
    linear structure (every element linearised at rest: a stop or a cubic spring adds
    nothing; dry friction holds at this level, so a friction element's DOFs move together,
    which the library's memoryless law cannot express) with modal damping and the sensors'
    masses, with 2 % complex noise; returns ``path``."""
    truth = load_truth(truth_name)
    s = truth.sensors
    masses = {p: s.accelerometer_mass_kg for p in range(1, 14)}
    masses[3] = s.impedance_head_mass_kg
    model = truth.model.add_masses(masses)
    asm = model.assemble()
    K, Cel = np.array(asm.K), np.zeros_like(asm.K)
    stuck = 1e3 * float(np.abs(np.diag(asm.K)).max())
    for att in attachments(model):  # each element linearised at rest
        ev = att.element.evaluate(np.zeros(1), np.zeros(1))
        inc = [(att.dof_a, 1.0)] + ([(att.dof_b, -1.0)] if att.dof_b is not None else [])
        friction = "v_reg" in att.element.options
        for i, si in inc:
            for j, sj in inc:
                if friction:
                    K[i, j] += si * sj * stuck
                    continue
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
        chans.append(_accelerometer(p, direction, masses[p]))
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
    frf = RandomFRF(
        frequency_hz=freq,
        h1=h1,
        coherence=np.full(h1.shape, 1 / (1 + noise**2)),
        force_psd=np.full(freq.size, 0.09 / (band_hz[1] - band_hz[0])),
        n_averages=8,
        window="boxcar",
        overlap=0.0,
        fs_hz=2560.0,
        rms_force_n=0.3,
    )
    return write_random(
        path,
        channels=chans,
        actuator=Actuator(3, "y"),
        frf=frf,
        config={"simulated": truth_name, "plan": "linear"},
        setup={"backend": "truth linearised"},
        overwrite=True,
    )


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
    """A stepped sine synthesised from a truth without the rig (for fast tests): the truth's
    forced periodic response by multi-harmonic balance driven by the target force (orders
    1-3) with ``control_error`` relative errors, sensor masses included, and the truth's noise
    floors on every phasor (``record_periods`` averaged periods: standard error
    ``asd sqrt(2 / T)``); steps where the truth's balance does not converge are not recorded.
    Returns ``path``."""
    truth = load_truth(truth_name)
    f = paper_frequencies_hz() if frequencies_hz is None else np.asarray(frequencies_hz, float)
    s = truth.sensors
    masses = {p: (s.impedance_head_mass_kg if p == 3 else s.accelerometer_mass_kg) for p in points}
    model = truth.model.add_masses(masses)
    asm = model.assemble()
    pb = build_problem_dofs(
        model,
        [asm.point_dof(3)],
        [asm.point_dof(p) for p in points],
        n_harmonics=n_harmonics,
        n_time=n_time,
    )
    chans = [ChannelInfo("force3", 3, "y", "force", "N", 22.5, "mV/N", "drive-force", 0.0, "IH")]
    chans += [_accelerometer(p, "y", masses[p]) for p in points]
    rng = np.random.default_rng(seed)
    targets = np.array([[lv, 0.02 * lv, 0.02 * lv] for lv in levels_n], complex)
    writer = create_stepped_sine(
        path,
        channels=chans,
        actuator=Actuator(3, "y"),
        levels_n=list(levels_n),
        orders_num=[1, 2, 3],
        orders_den=[1, 1, 1],
        force_targets=targets,
        config={"simulated": str(truth_name), "plan": "paper"},
        setup={"backend": "truth MHB"},
        overwrite=True,
    )
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
                writer.append_step(
                    StepRecord(
                        plan_index=plan,
                        level_index=li,
                        sweep_direction=1,
                        frequency_target_hz=float(f[j]),
                        frequency_hz=float(f[j]),
                        force=meas[0],
                        force_std=std[0],
                        response=meas,
                        response_std=std,
                        drive=0.1 * F[j],
                        n_blocks=record_periods,
                        control_iterations=2,
                        control_converged=True,
                        control_error=float(np.max(np.abs(F[j] - targets[li])) / lv),
                    )
                )
                plan += 1
        writer.finish("success", "simulated from the truth")
    return Path(path)


# -- the paper's calibration ------------------------------------------------------------------
def calibrate_paper_way(stepped: Path, linear: Path, *, n_starts: int = 30, seed: int = 0):
    """Nominal model -> linear calibration on the random test -> k_c, gap, v_c from Latin
    hypercube starts and LM on every level but the highest (on the measured branch, the
    steps the rig converged at)."""
    from analysis.diagnosis.refit import Starts, refit

    lin = calibrate_linear(load_model(), linear).model
    data = read_measurement(stepped)
    levels = sorted(float(x) for x in data.levels_n)
    rows = fitted_rows(data, levels[:-1] if len(levels) >= 3 else levels)
    fit = refit(
        lin,
        data,
        ("k_c", "gap", "v_c"),
        rows=rows,
        starts=Starts(
            distributions=paper_distributions(lin.parameters["gap"].nominal),
            n_random=n_starts,
            seed=seed,
        ),
    )
    return fit.model, data


def _is_true(c, truth: str) -> bool:
    """``c`` is the hidden effect of ``truth``."""
    kind, location, side = TRUE_EFFECTS[truth]
    # a place that moves as the truth's (candidates.SAME_MOTION) is the same element
    return (
        c.law.kind == kind
        and location in (c.location.name, *c.location.moves_as)
        and (side is None or c.law.options.get("side") == side)
    )


def _rank(diag, truth: str) -> int:
    """Rank of the true effect among the verified candidates (then the screened ones)."""
    kind, location, side = TRUE_EFFECTS[truth]
    r = diag.rank_of(kind, location, side)
    if r is not None:
        return r
    for i, f in enumerate(diag.screen):
        if _is_true(f.candidate, truth):
            return len(diag.ranking) + i + 1
    return len(diag.ranking) + len(diag.screen) + 1


def separate(truth: str, diag, data, folder: Path, seed: int = 0):
    """Settle a tie as the rig's ``separate`` command does: the separating plan written by the
    analysis, read by the rig, run on the simulated rig of ``truth``, the tied candidates
    ranked on the new file. Returns ``(the best of them, its Separation, seconds of data)``."""
    from analysis.diagnosis.separate import rank_on_separating_run, write_separating_plan
    from rig.config.plans import load_plan

    plan_path = write_separating_plan(
        folder / f"{truth}-separate.plan.toml", diag.recommendation, data
    )
    path, seconds = simulated_run(
        truth, load_plan(plan_path), folder, seed=seed, stem=f"{truth}-separate"
    )
    sep = rank_on_separating_run(diag.group, read_measurement(path), diag.settings.tie_bic)
    print(sep.summary())
    best = next(g for g in diag.group if g.candidate.label == sep.ranking[0]["label"])
    return best, sep, seconds


def run_case(truth: str, folder: Path, *, quick: bool = False, seed: int = 0) -> dict:
    """Make (or take) the runs, calibrate, diagnose and (for a hidden effect) augment."""
    stepped, s_data = stepped_run(truth, folder, quick=quick, seed=seed)
    linear, l_data = linear_run(truth, folder, seed=seed)
    t0 = time.perf_counter()
    model, data = calibrate_paper_way(stepped, linear, n_starts=12 if quick else 30, seed=seed)
    model.save(folder / f"{truth}_calibrated.toml")
    sweep_s = paper_sweep_s()  # the machine's speed just before the diagnosis
    t1 = time.perf_counter()
    diag = diagnose(model, data, linear_run=linear, settings=DiagnosisSettings())
    t2 = time.perf_counter()
    out = {
        "truth": truth,
        "verdict": diag.verdict,
        "group": [r.candidate.label for r in diag.group],
        "rms_before": diag.comparison.rms_over_noise,
        "data_s": round(s_data + l_data, 1),
        "calibration_s": round(t1 - t0, 1),
        "diagnosis_s": round(t2 - t1, 1),
        "paper_sweep_s": round(sweep_s, 3),
        "diagnosis_in_sweeps": round((t2 - t1) / sweep_s),
    }
    print(f"--- {truth}: {diag.verdict} (diagnosis {t2 - t1:.1f} s)")
    print(diag.summary())
    out["candidates"] = len(diag.screen) + len(diag.linear)
    pick = diag.group[0] if diag.group else (diag.ranking[0] if diag.ranking else None)
    if len(diag.group) > 1 and diag.recommendation:
        try:
            pick, sep, sep_data_s = separate(truth, diag, data, folder, seed)
        except RuntimeError as exc:  # the rig could not make the separating run
            print(f"separating run failed: {exc}")
            out["tie_resolved"] = False
            out["separation_error"] = str(exc)
        else:
            out["data_s"] = round(out["data_s"] + sep_data_s, 1)
            out["tie_resolved"] = (
                sep.resolved and truth in TRUE_EFFECTS and _is_true(pick.candidate, truth)
            )
            out["after_separation"] = sep.tied
    if truth in TRUE_EFFECTS:
        out["true_effect_rank"] = _rank(diag, truth)
        if pick is not None:
            values, known = pick.start_values()
            res = augment(
                model,
                data,
                pick.candidate,
                values=values,
                known=known,
                linear_run=linear,
                out=folder / f"{truth}_augmented.toml",
                seed=seed,
            )
            print(res.summary())
            out.update(
                added=pick.candidate.label,
                residual_drop=res.residual_drop,
                final_over_noise=res.after.rms_over_noise,
                augment_s=round(res.seconds, 1),
            )
        else:
            out.update(residual_drop=1.0, final_over_noise=diag.comparison.rms_over_noise)
    out["total_s"] = round(time.perf_counter() - t0, 1)
    return out


def run(quick: bool = False) -> dict:
    """Every truth (``quick``: the damper and the reference, a coarser run)."""
    truths = ["damper_p5"] if quick else list(TRUE_EFFECTS)
    controls = ["reference"] if quick else list(NEGATIVE_CONTROLS)
    folder = cache_dir()
    cases, claims, details = [], 0, []
    for truth in [*truths, *controls]:
        r = run_case(truth, folder, quick=quick)
        details.append(r)
        if truth in TRUE_EFFECTS:
            cases.append(
                {
                    k: r[k]
                    for k in ("truth", "true_effect_rank", "residual_drop", "final_over_noise")
                }
            )
        else:
            claims += int(r["verdict"] == "explained")
    return {
        "cases": cases,
        "negative_control_claims": claims,
        "total_s": round(sum(d["total_s"] for d in details), 1),
        "data_s": round(sum(d["data_s"] for d in details), 1),
        "max_diagnosis_s": max(d["diagnosis_s"] for d in details),
        "candidates": {d["truth"]: d["candidates"] for d in details},
        "ties_resolved": {d["truth"]: d["tie_resolved"] for d in details if "tie_resolved" in d},
        "paper_sweep_s": [
            min(d["paper_sweep_s"] for d in details),
            max(d["paper_sweep_s"] for d in details),
        ],
        "details": details,
    }


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    print(json.dumps(run(quick="--quick" in sys.argv[1:])))
