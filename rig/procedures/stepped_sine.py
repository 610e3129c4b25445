"""The stepped multi-sine procedure: force-controlled steps, each written as it completes.

:func:`stepped_sine_procedure` turns a :class:`~rig.config.plans.SteppedSinePlan` into commands for
the
engine. For every planned step (levels in plan order, each swept over its frequencies):

1. ``BeginStep`` (a pause/abort checkpoint);
2. the force controller starts from the previous step's gain matrix (warm start; the first step
   from the pretest's loop check) and proposes a drive;
3. ``SetDrive`` + ``Acquire``: settle (longer after a frequency or level change, shorter after a
   control correction), average phase-synchronous blocks once the settling test passes, and
   hand the force phasors and their standard errors to the controller; repeat until the force
   is on target (within the controller's tolerances, or within ``uncertainty_factor``
   standard errors of the target) or the controller stops. Near the fold of a nonlinear
   resonance the force is not a monotonic function of the drive; where the iteration stalls on
   a flat top or bottom of that curve with the target beyond it, control starts again from a
   drive on the far side (a ``"fold"`` warning, :func:`_fold_probe`);
4. the accepted drive's acquisition is extended to ``record_blocks`` blocks (no re-settling),
   and the step (realised frequency, phasors and standard errors of every channel, drive
   phasors, controller outcome) is written at once: ``WriteStep``.

A diverging controller ends the run (``on_divergence = "abort"``, fault ``control-diverged``)
or records its best measurement flagged as not converged; a step that runs out of iterations
or drive is recorded flagged and the run goes on, with a warning.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Generator, Iterable, Mapping

import numpy as np

from analysis.measurement_file import StepRecord
from rig.config.plans import PlannedStep, SteppedSinePlan
from rig.estimation.harmonics import pool_estimates
from rig.procedures.force_control import ControlSettings, ForceController, StepControlRecord
from rig.procedures.gain_prediction import GainHistory
from rig.procedures.pretest import stepped_pretest
from rig.run.commands import (
    Acquire,
    BeginStep,
    Measurement,
    Notify,
    RunContext,
    SetDrive,
    Warn,
    WriteStep,
)
from rig.run.events import ControlIteration, PretestFinished
from rig.run.faults import RunFault
from rig.signals.multisine import plan_period

__all__ = ["combine_measurements", "on_target", "stepped_sine_procedure"]

logger = logging.getLogger(__name__)

# control starts again when the latest error exceeds this and twice the best (restart_after)
RESTART_ERROR = 0.1
# a turning point of the force-drive curve: over the last restart_after measurements the
# fundamental's miss did not halve and its force followed the drive with less than this
# fraction of its own force per volt (flat or falling: past the peak of the force before a
# resonance)
FOLD_SLOPE = 0.25
# creeping: the drives of those measurements span at most this fraction of their mean (wider
# is a wandering iteration, which the restart handles)
FOLD_CREEP = 0.25
# the probe below the fold drives at most this fraction of the drive at the fold
FOLD_PROBE_RATIO = 0.5
# force per volt, relative to the low-level gain, from which a flat top is the peak of the
# rising part (the structure not yet in resonance) rather than the dip after it
LOW_BRANCH_GAIN = 0.5
# the probe beyond the dip multiplies the drive by this
FOLD_JUMP = 2.0


def stepped_sine_procedure(
    plan: SteppedSinePlan,
    completed: Iterable[int] = (),
    initial_gain: np.ndarray | None = None,
    recorded: Mapping[int, tuple[np.ndarray, np.ndarray]] | None = None,
):
    """The procedure (``callable(RunContext) -> generator``) that runs a stepped-sine plan.

    Parameters
    ----------
    plan : SteppedSinePlan
    completed : iterable of int
        Plan indices already on disk (a resumed run skips them).
    initial_gain : ndarray, shape (H,) or (H, H), complex, N/V, optional
        Drive-to-force gain for the first step; default the pretest's loop check (then the
        pretest must be enabled).
    recorded : mapping of int to (drive, force), optional
        Drive and force phasors (H,) of steps on disk, by plan index: a resumed run predicts
        its starting gains from them (:class:`rig.procedures.gain_prediction.GainHistory`).
    """
    done = frozenset(int(i) for i in completed)
    seen = dict(recorded or {})

    def procedure(ctx: RunContext) -> Generator:
        return _run(plan, ctx, done, initial_gain, seen)

    return procedure


def on_target(
    force: np.ndarray,
    std: np.ndarray,
    targets: np.ndarray,
    settings: ControlSettings,
    factor: float,
) -> tuple[bool, str]:
    """Whether a measured force is on target within the tolerances or its own uncertainty.

    Order ``k`` passes if it meets the controller's tolerance (for the fundamental: amplitude
    and phase) or if ``|F_k - T_k| <= factor * std_k``: a deviation the averaging cannot
    resolve is not chased.

    Parameters
    ----------
    force, targets : ndarray, shape (H,), complex, N
    std : ndarray, shape (H,), N
        Standard errors of ``force``.
    settings : ControlSettings
    factor : float
        ``uncertainty_factor`` (0: tolerances only).

    Returns
    -------
    (bool, str)
        Verdict and a one-line reason.
    """
    s = settings
    i1 = s.fundamental_index
    dev = np.abs(force - targets)
    allowance = factor * np.nan_to_num(np.asarray(std, dtype=float))
    t1 = abs(targets[i1])
    amp = abs(force[i1]) / t1 - 1.0
    phase = math.degrees(abs(np.angle(force[i1] / targets[i1]))) if force[i1] != 0 else 180.0
    fund_ok = (
        abs(amp) <= s.fundamental_amplitude_tolerance and phase <= s.fundamental_phase_tolerance_deg
    ) or dev[i1] <= allowance[i1]
    tol = np.maximum(s.harmonic_tolerance * np.abs(targets), s.harmonic_floor_ratio * t1)
    ratio = dev / np.maximum(np.maximum(tol, allowance), np.finfo(float).tiny)
    ratio[i1] = 0.0
    ok = fund_ok and bool(np.all(ratio <= 1.0))
    reason = (
        f"fundamental {amp:+.2%} {phase:.2f} deg (std {np.nan_to_num(std[i1]) / t1:.2%}), other "
        f"orders at {ratio.max():.2f} x max(tolerance, {factor:g} std)"
    )
    return ok, reason


def combine_measurements(a: Measurement, b: Measurement) -> Measurement:
    """One measurement from two consecutive ones at the same drive (their blocks pooled).

    The blocks of ``b`` follow those of ``a`` by whole base periods, so every block phasor
    shares ``a``'s time origin.
    """
    est = pool_estimates(a.estimate, b.estimate)
    extra = None
    if a.extra is not None and b.extra is not None:
        extra = pool_estimates(a.extra, b.extra)
    na, nb = a.estimate.n_blocks, b.estimate.n_blocks
    n = na + nb
    samples = None
    if a.samples is not None and b.samples is not None:
        samples = np.concatenate([a.samples, b.samples])
    rms = np.sqrt((na * a.rms**2 + nb * b.rms**2) / n)
    return dataclasses.replace(a, estimate=est, rms=rms, samples=samples, extra=extra)


def _run(plan: SteppedSinePlan, ctx: RunContext, completed: frozenset, initial_gain, recorded):
    steps = plan.steps()
    todo = [s for s in steps if s.plan_index not in completed]
    if not todo:
        return
    orders = plan.excitation.orders
    gain = None if initial_gain is None else np.asarray(initial_gain, dtype=complex)
    if plan.pretest.enabled:
        f0 = plan.pretest.loop_check_frequency_hz or todo[0].frequency_hz
        report = yield from stepped_pretest(plan.pretest, ctx, orders, f0, plan.acquisition.ramp_s)
        yield Notify(PretestFinished(report))
        if not report.ok:
            raise RunFault("pretest", report.problem_message(), report.problems[0].name)
        if gain is None:
            gain = report.gain_n_per_v
    if gain is None:
        raise ValueError(
            "no drive-to-force gain to start from: enable the pretest or pass initial_gain"
        )
    loop_gain = np.diag(gain) if gain.ndim == 1 else gain
    controller = ForceController(plan.control.settings)
    history = GainHistory(plan.excitation.spec.fundamental_index, orders)
    for index, (drive, force) in sorted(recorded.items()):
        if 0 <= index < len(steps):
            history.add(steps[index], drive, force)
    for step in todo:
        yield BeginStep(step, len(steps))
        start_gain, start_drive = loop_gain, None
        if plan.control.warm_start:
            before = steps[step.plan_index - 1] if step.plan_index > 0 else None
            f = plan_period(step.frequency_hz, ctx.sample_rate_hz, orders).fundamental_hz
            predicted = history.predict(step, before, f)
            if predicted is not None:
                start_gain = predicted
                targets = plan.excitation.spec.force_targets(step.level_n)
                start_drive = history.predict_drive(step, before, targets, f)
        record, final_gain = yield from _one_step(
            plan, ctx, controller, step, start_gain, start_drive, loop_gain
        )
        history.add(step, record.drive, record.force, final_gain, record.frequency_hz)


def _one_step(
    plan: SteppedSinePlan,
    ctx: RunContext,
    controller: ForceController,
    step: PlannedStep,
    start_gain: np.ndarray,
    start_drive: np.ndarray | None = None,
    low_gain: np.ndarray | None = None,
):
    """Control, record and write one step; returns (StepRecord, final gain estimate).

    ``low_gain`` (H, H) is the drive-to-force gain at a low level (the loop check): where the
    step stalls at a turning point of the force-drive curve, control starts again on its far
    side, from a drive chosen with it (:func:`_fold_probe`).
    """
    acq, policy, settings = plan.acquisition, plan.control, plan.control.settings
    fi, i1 = ctx.drive_force_index, settings.fundamental_index
    targets = plan.excitation.spec.force_targets(step.level_n)
    drive = controller.start_step(targets, start_gain, start_drive)
    settle = acq.settle_periods
    history: list[tuple[np.ndarray, Measurement]] = []
    runs: list[StepControlRecord] = []
    where = f"at {step.frequency_hz:.4g} Hz, {step.level_n:g} N (step {step.plan_index})"
    accepted, reason, probed = False, "", False
    while True:
        m = yield from _measure(plan, step.frequency_hz, drive, settle)
        force, force_std = m.phasors[fi], np.nan_to_num(m.std[fi])
        decision = controller.next_drive(drive, force, force_std)
        accepted, reason = on_target(force, force_std, targets, settings, policy.uncertainty_factor)
        accepted = accepted or decision.converged
        history.append((drive, m))
        yield Notify(
            ControlIteration(
                step.plan_index,
                len(history),
                "converged" if accepted else decision.status,
                accepted or decision.done or len(history) >= settings.max_iterations,
                decision.error,
                m.frequency_hz,
                drive.copy(),
                force.copy(),
                force_std.copy(),
            )
        )
        settle = acq.correction_settle_periods
        if accepted:
            break
        out_of_budget = len(history) >= settings.max_iterations
        wandering = _wandering(controller.record.errors, policy)
        stopped = decision.done or out_of_budget or wandering
        window = (controller.record.errors.size, policy.restart_after)
        probe = (
            None if stopped or probed else _fold_probe(history, *window, fi, i1, targets, low_gain)
        )
        if not (stopped or probe is not None):
            drive = decision.drive_v
            continue
        run = _ended_run(controller.record, decision, out_of_budget)
        runs.append(run)
        if probe is not None:
            probed = True
            yield _fold_warning(where, drive[i1], probe[i1])
            drive = controller.start_step(targets, low_gain, probe)
            continue
        _check_divergence(run, first=not runs[:-1], policy=policy, where=where)
        if out_of_budget or run.status == "drive-limit":
            break
        gain, restart_drive = _restart(run, drive, force, history, targets, i1)
        try:
            drive = controller.start_step(targets, gain, restart_drive)
        except ValueError:  # a singular estimate: start from the loop-check shape instead
            drive = controller.start_step(targets, start_gain)
    if accepted:
        final = controller.record
        if not decision.converged:
            final = dataclasses.replace(final, status="converged", reason=reason)
        runs.append(final)
    return (yield from _record_step(plan, ctx, step, history, runs, targets, accepted, where))


def _record_step(plan, ctx, step, history, runs, targets, accepted, where):
    """Write the step from its chosen measurement: the accepted one (extended to the plan's
    record blocks), else the best of all, flagged; returns (StepRecord, final gain estimate)."""
    control = _merge_runs(runs)
    if accepted:
        chosen = len(history) - 1
    else:
        chosen = int(np.argmin(control.errors))
        yield Warn(
            "not-converged",
            f"force control {control.status} {where}: {control.reason}; the best of "
            f"{control.iterations} measurements is recorded, flagged as not converged",
        )
    acq = plan.acquisition
    fi = ctx.drive_force_index
    drive_used, m = history[chosen]
    if chosen == len(history) - 1 and acq.record_blocks > acq.average_blocks:
        more = yield Acquire(
            settle_periods=0,
            blocks=acq.record_blocks - acq.average_blocks,
            block_periods=acq.block_periods,
            keep_samples=acq.store_raw,
            purpose="record",
            extra_orders=plan.extra_orders,
        )
        m = combine_measurements(m, more)
    record = _step_record(plan, step, m, fi, targets, drive_used, control, accepted)
    t0 = m.first_index / ctx.sample_rate_hz
    yield WriteStep(record, control, m.samples, t0, m.settled)
    return record, control.final_gain


def _measure(plan: SteppedSinePlan, frequency_hz: float, drive: np.ndarray, settle: int):
    """Apply ``drive`` and measure (settled, averaged); returns the Measurement."""
    acq = plan.acquisition
    yield SetDrive(frequency_hz, drive, plan.excitation.orders, acq.ramp_s)
    return (
        yield Acquire(
            settle_periods=settle,
            blocks=acq.average_blocks,
            block_periods=acq.block_periods,
            max_settle_periods=acq.max_settle_periods,
            settling_tolerance=acq.settling_tolerance,
            drift_tolerance=acq.drift_tolerance,
            keep_samples=acq.store_raw,
            extra_orders=plan.extra_orders,
        )
    )


def _fold_warning(where: str, stalled_v: complex, probe_v: complex) -> Warn:
    return Warn(
        "fold",
        f"force control {where}: the force stopped following the drive at "
        f"{abs(stalled_v):.4g} V (a turning point of the force-drive curve, the target "
        f"beyond it); control starts again from {abs(probe_v):.4g} V",
    )


def _ended_run(run: StepControlRecord, decision, out_of_budget: bool) -> StepControlRecord:
    """The record of a control run the step ends or starts again: as the controller ended it,
    or stopped here for lack of iterations or to restart."""
    if decision.done:
        return run
    status = "max-iterations" if out_of_budget else "restart"
    return dataclasses.replace(run, status=status, reason=decision.reason)


def _wandering(errors: np.ndarray, policy) -> bool:
    """The control error has grown well past its best of this run: start again."""
    return bool(
        policy.restart_after > 0
        and errors.size >= policy.restart_after
        and errors[-1] > max(2.0 * errors.min(), RESTART_ERROR)
    )


def _check_divergence(run: StepControlRecord, *, first: bool, policy, where: str) -> None:
    """Stop the run when the first control run of a step diverged and never came near."""
    if (
        first
        and run.diverged
        and policy.on_divergence == "abort"
        and float(np.min(run.errors)) > policy.divergence_abort_error
    ):
        raise RunFault(
            "control-diverged",
            f"force control diverged {where}: {run.reason}; check the drive chain "
            "(amplifier gain, shaker, stinger, force-gauge polarity) before resuming",
        )


def _restart(run, drive, force, history, targets, i1):
    """The gain and drive to start a step's control again from.

    The force per volt the latest measurement shows: near the fold of a nonlinear resonance
    the response jumps between branches and the gain learnt across the jump misleads. The new
    drive stays within the range applied in this step, widened by half (no wild extrapolation
    from a single point).
    """
    gain = run.final_gain.copy()
    if drive[i1] != 0 and force[i1] != 0 and np.isfinite(force[i1]):
        gain[i1, i1] = force[i1] / drive[i1]
    applied = [abs(d[i1]) for d, _ in history]
    v1 = targets[i1] / gain[i1, i1]
    v1 *= float(np.clip(abs(v1), 0.5 * min(applied), 1.5 * max(applied))) / abs(v1)
    restart_drive = drive.copy()
    restart_drive[i1] = v1
    return gain, restart_drive


def _step_record(plan, step, m, fi, targets, drive_used, control, accepted) -> StepRecord:
    """The file's row of a step from its chosen measurement."""
    force = m.phasors[fi]
    t1 = abs(targets[plan.excitation.spec.fundamental_index])
    return StepRecord(
        plan_index=step.plan_index,
        level_index=step.level_index,
        sweep_direction=step.sweep_direction,
        frequency_target_hz=step.frequency_hz,
        frequency_hz=m.frequency_hz,
        force=force.copy(),
        force_std=np.nan_to_num(m.std[fi]).copy(),
        response=m.phasors.copy(),
        response_std=np.nan_to_num(m.std).copy(),
        drive=np.asarray(drive_used, dtype=complex),
        n_blocks=m.n_blocks,
        control_iterations=control.iterations,
        control_converged=accepted,
        control_error=float(np.max(np.abs(force - targets)) / t1),
        extra_force=None if m.extra is None else m.extra.phasors[fi].copy(),
        extra_force_std=None if m.extra is None else np.nan_to_num(m.extra.std[fi]).copy(),
    )


def _fold_probe(
    history: list[tuple[np.ndarray, Measurement]],
    run_length: int,
    window: int,
    fi: int,
    i1: int,
    targets: np.ndarray,
    low_gain: np.ndarray | None,
) -> np.ndarray | None:
    """The drive to start again from when the step stalls at a turning point, else None.

    Near a resonance the fundamental force is not a monotonic function of the drive: it rises
    from zero while the structure responds little, peaks as the response grows into the
    resonance (the shaker cannot push a resonating structure: force drop-out), dips, and rises
    again once the response is past the resonance's fold. A target out of reach of the part
    the iteration is on leaves the quasi-Newton steps creeping along a flat top or bottom.
    Stalled means: over the latest ``window`` measurements of this run (``run_length``
    measurements since control last started) the fundamental's
    amplitude error did not halve while their drives stayed within ``FOLD_CREEP`` of each
    other, and a straight line through their fundamental drive and force amplitudes rises
    with less than ``FOLD_SLOPE`` times the force per volt. Then:

    - the force is above the target, or short of it in the dip (force per volt below
      ``LOW_BRANCH_GAIN`` times the low-level gain ``low_gain``): the rising part below holds
      a solution (the force rises from zero); the probe is the drive the low-level gain
      predicts for the target, at most ``FOLD_PROBE_RATIO`` of the current drive;
    - the force is short of the target at the top of the rising part (force per volt near the
      low-level gain): the solution lies beyond the dip; the probe is ``FOLD_JUMP`` times the
      current drive.

    The whole drive vector is scaled.
    """
    if low_gain is None or window < 3 or run_length < window:
        return None
    v = np.array([abs(d[i1]) for d, _ in history[-window:]])
    f = np.array([abs(m.phasors[fi][i1]) for _, m in history[-window:]])
    t1 = abs(targets[i1])
    miss = np.abs(f - t1)
    if miss[1:].min() <= 0.5 * miss[0]:
        return None
    if not (v.mean() > 0 and 1e-3 * v.mean() < np.ptp(v) <= FOLD_CREEP * v.mean()):
        return None
    per_volt = f.mean() / v.mean()
    if np.polyfit(v, f, 1)[0] >= FOLD_SLOPE * per_volt:
        return None
    drive = history[-1][0]
    g_low = max(abs(low_gain[i1, i1]), np.finfo(float).tiny)
    if f[-1] < t1 and per_volt >= LOW_BRANCH_GAIN * g_low:
        return drive * FOLD_JUMP
    return drive * min(t1 / g_low, FOLD_PROBE_RATIO * abs(drive[i1])) / abs(drive[i1])


def _merge_runs(runs: list[StepControlRecord]) -> StepControlRecord:
    """One record of a step whose control was started again (every measurement in order)."""
    if len(runs) == 1:
        return runs[0]
    last = runs[-1]
    return dataclasses.replace(
        last,
        initial_gain=runs[0].initial_gain,
        drives_v=np.concatenate([r.drives_v for r in runs]),
        forces_n=np.concatenate([r.forces_n for r in runs]),
        force_std_n=np.concatenate([r.force_std_n for r in runs]),
        errors=np.concatenate([r.errors for r in runs]),
        clamped=np.concatenate([r.clamped for r in runs]),
        reason=f"{last.reason} (control started again {len(runs) - 1} time(s))",
    )
