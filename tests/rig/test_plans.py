"""Plans: the built-in plans, validation, and the procedures tested by recording their commands."""

import dataclasses
import json
from fractions import Fraction

import numpy as np
import pytest

from rig.config.plans import builtin_plans, describe_plan, load_plan, plan_from_dict
from rig.config.tomlconfig import ConfigError
from rig.procedures.random_test import random_procedure
from rig.procedures.stepped_sine import stepped_sine_procedure
from rig.run.commands import (
    Acquire,
    AcquireRecords,
    BeginStep,
    Notify,
    SetDrive,
    SetWaveform,
    Warn,
    WriteRandom,
    WriteStep,
)
from rig.run.dry_run import ModelPlant
from rig.run.events import ControlIteration, PretestFinished
from rig.run.faults import RunFault
from tests.rig.rig_helpers import context, reduced_plan, setup_at


def test_builtin_plans():
    assert {"paper", "quick", "linear"} <= set(builtin_plans())
    for name in builtin_plans():
        plan = load_plan(name)
        assert plan.name == name and describe_plan(plan)
        assert plan_from_dict(json.loads(json.dumps(plan.to_dict()))) == plan


def test_paper_plan_is_the_papers_test():
    plan = load_plan("paper")
    f = plan.frequencies.frequencies_hz()
    assert f.size == 56 and f[0] == 21.0 and f[-1] == 40.0
    assert np.count_nonzero((f >= 24) & (f <= 28)) == 41
    assert len(set(np.round(f, 6))) == 56  # overlaps (24, 25, 26, 27, 28 Hz) measured once
    assert plan.levels_n == (2.0, 4.0, 6.0, 8.0)
    assert plan.excitation.orders == (Fraction(1), Fraction(2), Fraction(3))
    assert plan.excitation.relative_amplitudes == (1.0, 0.02, 0.02)
    assert plan.points == (3, 6, 7) and plan.setup == "reference"
    steps = plan.steps()
    assert len(steps) == plan.n_steps == 224
    assert [s.plan_index for s in steps] == list(range(224))
    assert [s.level_n for s in steps[:56]] == [2.0] * 56
    assert [s.frequency_hz for s in steps[:56]] == list(f)
    assert steps[56].first_of_sweep and steps[56].level_index == 1
    assert all(s.sweep_direction == 1 for s in steps)
    targets = plan.force_targets()
    assert targets.shape == (4, 3) and np.allclose(np.abs(targets[3]), [8.0, 0.16, 0.16])
    # the controller keeps its default tolerances; the plan's drive limit is its max_drive_v
    s = plan.control.settings
    assert (s.fundamental_amplitude_tolerance, s.harmonic_tolerance) == (0.01, 0.10)
    assert s.max_drive_v == plan.limits.drive_peak_v < load_plan("paper").limits.drive_peak_v + 1
    assert {(r.point, r.channel) for r in plan.limits.response} == {(7, ""), (-1, "force3")}


def test_linear_plan():
    plan = load_plan("linear")
    assert plan.kind == "random" and plan.points == tuple(range(1, 14))
    assert (plan.excitation.f_lo_hz, plan.excitation.f_hi_hz) == (5.0, 800.0)
    tip = plan.limits.response[0]
    assert tip.point == 7 and tip.displacement_abort_m < 0.6e-3  # before the gap closes


def test_up_down_sweeps():
    plan = reduced_plan(levels_n=(2.0,), ranges=((21, 23, 1),))
    plan = dataclasses.replace(
        plan, frequencies=dataclasses.replace(plan.frequencies, direction="up-down")
    )
    steps = plan.steps()
    assert [s.frequency_hz for s in steps] == [21, 22, 23, 23, 22, 21]
    assert [s.sweep_direction for s in steps] == [1, 1, 1, -1, -1, -1]


def _paper_dict():
    return json.loads(json.dumps(load_plan("paper").to_dict()))


@pytest.mark.parametrize(
    "change, key",
    [
        (lambda d: d["excitation"].update(levels_n=[2.0, -4.0]), "excitation.levels_n[1]"),
        (lambda d: d["excitation"].update(orders=[1, 2, 2]), "excitation.orders"),
        (lambda d: d["excitation"].update(relative_amplitudes=[1.0, 0.02]), "excitation"),
        (lambda d: d["frequencies"]["ranges"][0].update(stop_hz=40.5), "frequencies.ranges[0]"),
        (lambda d: d["frequencies"].update(direction="sideways"), "frequencies.direction"),
        (lambda d: d["acquisition"].update(average_blocks=2), "acquisition"),
        (lambda d: d["acquisition"].update(avarage_blocks=16), "acquisition"),
        (lambda d: d["control"].update(max_iterations=0), "control"),
        (lambda d: d["control"].update(orders=[1]), "control.orders"),
        (
            lambda d: d["limits"]["response"][0].update(displacement_alarm_m=11e-3),
            "limits.response[0]",
        ),
        (lambda d: d["limits"].update(drive_peak_v=0), "limits.drive_peak_v"),
        (lambda d: d.update(points=[]), "points"),
    ],
)
def test_plan_errors_name_the_key(change, key):
    data = _paper_dict()
    change(data)
    with pytest.raises(ConfigError) as err:
        plan_from_dict(data, "plan my.toml")
    assert f"plan my.toml: {key}" in str(err.value)


@pytest.mark.parametrize(
    "change, path, problem",
    [
        # scalars are as strict as TOML: true is not an integer, "2" not a number
        (
            lambda d: d["acquisition"].update(average_blocks=True),
            ("acquisition", "average_blocks"),
            "expected an integer, got True",
        ),
        (lambda d: d["pretest"].update(noise_s="2"), ("pretest", "noise_s"), "expected a number"),
        (lambda d: d["pretest"].update(noise_s=float("inf")), ("pretest", "noise_s"), "finite"),
        # every misspelt key of the table, and what it knows
        (
            lambda d: d["control"].update(max_iteration=3, warmstart=True),
            ("control",),
            "unknown key(s) 'max_iteration', 'warmstart' (known here: coupling_uncertainty,",
        ),
    ],
)
def test_plan_values_are_read_strictly(change, path, problem):
    data = _paper_dict()
    change(data)
    with pytest.raises(ConfigError) as err:
        plan_from_dict(data, "plan my.toml")
    assert err.value.path == path and problem in err.value.problem


def test_a_setting_given_in_python_names_its_class_and_key_path():
    from rig.config.plans import ExcitationSettings

    with pytest.raises(ConfigError) as err:
        ExcitationSettings(levels_n=(2.0, -1.0))
    assert err.value.path == ("levels_n", 1)
    assert str(err.value) == "ExcitationSettings.levels_n[1]: must be > 0, got -1.0"
    # the default amplitudes follow the orders, in Python as in a file
    assert ExcitationSettings(orders=(1, 3)).relative_amplitudes == (1.0, 0.02)


@pytest.mark.parametrize("name", ["paper", "quick", "linear"])
def test_to_dict_reads_back_and_names_each_limit_by_channel_or_point(name):
    plan = load_plan(name)
    data = json.loads(json.dumps(plan.to_dict()))
    assert plan_from_dict(data, name) == plan
    assert data["kind"] == plan.kind and data["excitation"] == plan.to_dict()["excitation"]
    for row in data["limits"]["response"]:
        assert ("channel" in row) != ("point" in row)


def test_own_plan_file(tmp_path):
    text = (
        (builtin_plans()["quick"]).read_text().replace("levels_n = [2.0, 8.0]", "levels_n = [3.0]")
    )
    path = tmp_path / "mine.toml"
    path.write_text(text)
    plan = load_plan(path)
    assert plan.levels_n == (3.0,) and plan.n_steps == 5
    with pytest.raises(ConfigError, match="not a built-in plan"):
        load_plan(tmp_path / "missing.toml")


def test_a_plan_beyond_the_step_limit_is_refused_before_its_steps_are_listed(tmp_path):
    from rig.config.plans import MAX_PLAN_STEPS, PlanTooLarge

    # one range of 19 billion frequencies: refused from its settings, at its key
    text = builtin_plans()["quick"].read_text()
    data = _paper_dict()
    data["frequencies"]["ranges"] = [{"start_hz": 21.0, "stop_hz": 40.0, "step_hz": 1e-9}]
    with pytest.raises(ConfigError) as err:
        plan_from_dict(data, "plan big.toml")
    assert "plan big.toml: frequencies.ranges[0]" in str(err.value)
    assert "19,000,000,001 frequencies" in str(err.value) and "step_hz" in str(err.value)
    assert isinstance(err.value.__cause__, PlanTooLarge)
    # ranges within the limit whose levels and sweeps take the plan beyond it
    data = _paper_dict()
    data["frequencies"] = {
        "ranges": [{"start_hz": 20.0, "stop_hz": 40.0, "step_hz": 0.001}],
        "direction": "up-down",
    }
    data["excitation"]["levels_n"] = [1.0, 2.0, 3.0]
    with pytest.raises(
        ConfigError, match=f"120,006 steps, more than the maximum of {MAX_PLAN_STEPS:,}"
    ):
        plan_from_dict(data, "plan big.toml")
    # the same from a plan file, as 'rig run FILE' reads it
    path = tmp_path / "big.toml"
    path.write_text(text.replace("step_hz = 1.0", "step_hz = 1e-9", 1))
    assert "step_hz = 1e-9" in path.read_text()
    with pytest.raises(ConfigError, match=r"big\.toml.*frequencies\.ranges\[0\].*step_hz"):
        load_plan(path)


# ------------------------------------------------------------------------ recorded procedures


def _smooth_gain(f, orders):
    """A drive-to-force gain that changes with frequency like a shaker on a structure."""
    k = np.array([float(o) for o in orders])
    return 40.0 / (1.0 + 0.3j * (k * f - 25.0) / 5.0)


def test_stepped_procedure_commands_on_a_model_plant():
    setup = setup_at()
    plan = reduced_plan(levels_n=(2.0, 6.0), ranges=((22.0, 24.0, 0.5),))
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain)
    commands = rig.run(stepped_sine_procedure(plan))
    kinds = [type(c).__name__ for c in commands]
    # pretest first: 0 V noise floor, then the low-level loop check at every order
    assert kinds[:5] == ["SetDrive", "Acquire", "SetDrive", "Acquire", "Notify"]
    assert not np.any(commands[0].drive_v) and not commands[1].check_signals
    assert np.allclose(np.abs(commands[2].drive_v), plan.pretest.loop_check_drive_v)
    assert isinstance(commands[4].event, PretestFinished) and commands[4].event.report.ok
    begins = [c for c in commands if isinstance(c, BeginStep)]
    assert [b.step.plan_index for b in begins] == list(range(plan.n_steps))
    assert len(rig.steps) == plan.n_steps
    for write in rig.steps:
        r = write.record
        target = plan.excitation.spec.force_targets(plan.levels_n[r.level_index])
        assert np.max(np.abs(r.force - target)) <= 0.01 * abs(target[0])
        assert r.control_converged and r.n_blocks == plan.acquisition.record_blocks
        assert r.frequency_hz == pytest.approx(r.frequency_target_hz, rel=2e-3)
    iterations = [w.record.control_iterations for w in rig.steps]
    assert iterations[0] <= 2 and np.median(iterations) <= 2  # warm starts along the sweep
    # each step: drives, acquisitions (the first with the long settling), then the record
    first = commands.index(begins[1])
    acquires = [c for c in commands[first:] if isinstance(c, Acquire)]
    assert acquires[0].settle_periods == plan.acquisition.settle_periods
    assert acquires[0].blocks == plan.acquisition.average_blocks
    assert any(a.purpose == "record" and a.settle_periods == 0 for a in acquires)
    iteration_events = [c.event for c in commands if isinstance(c, Notify)]
    assert any(isinstance(e, ControlIteration) and e.accepted for e in iteration_events)


def test_completed_steps_are_skipped():
    setup = setup_at()
    plan = reduced_plan(levels_n=(2.0,), ranges=((21.0, 25.0, 1.0),))
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain)
    rig.run(stepped_sine_procedure(plan, completed={0, 1, 3}))
    assert [w.record.plan_index for w in rig.steps] == [2, 4]
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain)
    assert rig.run(stepped_sine_procedure(plan, completed=range(5))) == []


def test_controller_learns_the_coupling_of_the_orders():
    setup = setup_at()
    plan = reduced_plan(levels_n=(4.0,), ranges=((21.0, 23.0, 1.0),))
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain, coupling=0.05)
    rig.run(stepped_sine_procedure(plan))
    for write in rig.steps:
        assert write.record.control_converged
        # the fundamental generates 0.2 N at orders 2 and 3; the drive cancels it
        assert np.max(np.abs(write.record.force[1:] - 0.08)) <= 0.1 * 0.08 + 1e-9


def test_wrong_polarity_makes_the_controller_diverge():
    setup = setup_at()
    plan = reduced_plan(levels_n=(2.0,), ranges=((21.0, 22.0, 1.0),))
    settings = dataclasses.replace(plan.control.settings, max_gain_phase_change_deg=90.0)
    plan = dataclasses.replace(
        plan,
        pretest=dataclasses.replace(plan.pretest, enabled=False),
        control=dataclasses.replace(plan.control, settings=settings),
    )
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain)
    wrong = -_smooth_gain(21.0, plan.excitation.orders)
    with pytest.raises(RunFault) as err:
        rig.run(stepped_sine_procedure(plan, initial_gain=wrong))
    assert err.value.kind == "control-diverged"
    assert "diverged at 21 Hz, 2 N" in err.value.message and not rig.steps


def test_random_procedure_commands():
    setup = setup_at()
    plan = load_plan("linear")
    plan = dataclasses.replace(
        plan,
        excitation=dataclasses.replace(plan.excitation, record_s=1.0),
        acquisition=dataclasses.replace(plan.acquisition, average_records=3),
        pretest=dataclasses.replace(plan.pretest, noise_s=0.5),
    )
    rig = ModelPlant(context(setup, plan.points, 2560.0), _smooth_gain)
    commands = rig.run(random_procedure(plan))
    waves = [c for c in commands if isinstance(c, SetWaveform)]
    records = [c for c in commands if isinstance(c, AcquireRecords)]
    assert [w.label for w in waves] == ["zero", "calibration", "random"]
    assert [(r.purpose, r.records) for r in records] == [
        ("noise", 1),
        ("calibration", 2),
        ("average", 3),
    ]
    assert not np.any(waves[0].period_v)
    # the test level follows from the calibration: the model plant gives 5 N per V
    rms = np.sqrt(np.mean(waves[2].period_v ** 2))
    assert rms * 5.0 == pytest.approx(plan.excitation.force_rms_n, rel=1e-6)
    assert isinstance(commands[-1], WriteRandom)
    frf = rig.frf
    assert frf.frequency_hz[0] >= 5.0 and frf.frequency_hz[-1] <= 800.0
    assert np.allclose(np.delete(frf.h1, 0, axis=1), 2.0, atol=0.01)
    assert np.all(frf.coherence > 0.99)
    assert frf.n_averages == 3 and frf.rms_force_n == pytest.approx(4.0, rel=1e-6)


def test_setdrive_commands_respect_the_orders():
    setup = setup_at()
    plan = reduced_plan(levels_n=(2.0,), ranges=((30.0, 30.0, 1.0),))
    rig = ModelPlant(context(setup, sample_rate_hz=5120.0), _smooth_gain)
    commands = rig.run(stepped_sine_procedure(plan))
    drives = [c for c in commands if isinstance(c, SetDrive)]
    assert all(d.orders == plan.excitation.orders and d.drive_v.shape == (3,) for d in drives)
    assert all(isinstance(c, WriteStep) for c in commands if type(c).__name__ == "WriteStep")


# ------------------------------------------------------------------ a force-drive curve with a fold


class _FoldCurve:
    """Fundamental force amplitude a non-monotonic function of the drive amplitude.

    As a shaker drives a structure into a hardening resonance: the force rises with the drive
    (67 N/V), peaks at 5.4 N (0.09 V) as the response grows into the resonance, dips to 2.2 N
    (0.148 V) and rises again past the fold. The other orders are those of ``_smooth_gain``.
    """

    a = np.array([0.0, 0.03, 0.06, 0.09, 0.12, 0.148, 0.18, 0.22, 0.3, 0.5])
    f = np.array([0.0, 2.0, 4.0, 5.4, 3.6, 2.2, 3.5, 6.4, 12.0, 25.0])

    def __init__(self) -> None:
        from scipy.interpolate import PchipInterpolator

        self.curve = PchipInterpolator(self.a, self.f)
        self.rig: ModelPlant | None = None

    def __call__(self, f, orders):
        g = _smooth_gain(f, orders)
        v1 = abs(self.rig._drive[1][0])
        if v1 > 0:
            g[0] = float(self.curve(v1)) / v1 * g[0] / abs(g[0])
        return g


def _fold_step(level_n: float, start_v: float, restart_after: int = 4):
    """One force-controlled step on the fold curve, started at ``start_v`` on the fundamental."""
    plan = reduced_plan(levels_n=(level_n,), ranges=((22.0, 22.0, 1.0),))
    control = dataclasses.replace(load_plan("paper").control, restart_after=restart_after)
    plan = dataclasses.replace(
        plan, pretest=dataclasses.replace(plan.pretest, enabled=False), control=control
    )
    curve = _FoldCurve()
    rig = ModelPlant(context(setup_at(), sample_rate_hz=5120.0), curve)
    curve.rig = rig
    gain = _smooth_gain(22.0, plan.excitation.orders)
    gain[0] = level_n / start_v * gain[0] / abs(gain[0])
    commands = rig.run(stepped_sine_procedure(plan, initial_gain=gain))
    folds = [c for c in commands if isinstance(c, Warn) and c.kind == "fold"]
    return rig.steps[0].record, folds


def test_a_target_out_of_reach_past_the_peak_is_found_on_the_rising_part():
    # 2 N from the dip (2.2 N at best there): the controller creeps along the flat bottom,
    # then starts again from below the peak and finds 2 N at 0.03 V
    record, folds = _fold_step(2.0, 0.148)
    assert record.control_converged and len(folds) == 1
    assert abs(record.drive[0]) == pytest.approx(0.03, rel=0.05)
    assert abs(abs(record.force[0]) - 2.0) <= 0.02
    # without the probe (restart_after 0) it stays on the flat bottom
    record, folds = _fold_step(2.0, 0.148, restart_after=0)
    assert not record.control_converged and not folds


def test_a_target_above_the_peak_is_found_beyond_the_dip():
    # 6 N from the peak (5.4 N): nothing below reaches it; the drive doubles past the dip
    record, folds = _fold_step(6.0, 0.09)
    assert record.control_converged and len(folds) == 1
    assert 0.2 < abs(record.drive[0]) < 0.23 and abs(abs(record.force[0]) - 6.0) <= 0.06
    record, folds = _fold_step(6.0, 0.09, restart_after=0)
    assert not record.control_converged and not folds


# ------------------------------------------------------------------------ dry run


def test_dry_run_counts_the_time_the_measurements_take():
    from rig.run.dry_run import dry_run

    base = reduced_plan(levels_n=(2.0,), ranges=((25.0, 25.0, 1.0),))
    acq = base.acquisition
    run = dry_run(base)
    assert run.n_steps == 1 and len(run.step_seconds) == 1
    # one step at 25 Hz on a linear plant: on target at once, then the record blocks; its
    # time is ramp + (settle + average blocks) periods + the extra record blocks, in 1/25 s
    periods = acq.settle_periods + acq.record_blocks * acq.block_periods
    assert run.step_seconds[0] == pytest.approx(acq.ramp_s + periods / 25.0, rel=2e-3)
    # 8 more averaged blocks per measurement add 8 periods to every measurement
    blocks = {"average_blocks": acq.average_blocks + 8, "record_blocks": acq.record_blocks + 8}
    more = dataclasses.replace(acq, **blocks)
    run2 = dry_run(dataclasses.replace(base, acquisition=more))
    assert run2.n_measurements == run.n_measurements
    assert run2.step_seconds[0] - run.step_seconds[0] == pytest.approx(8 / 25.0, rel=2e-3)
    assert run2.seconds > run.seconds


def test_plans_show_lists_the_steps_and_the_time(capsys):
    from rig.cli.main import main

    assert main(["plans", "show", "quick", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    plan = load_plan("quick")
    assert out["n_steps"] == plan.n_steps == len(out["steps"])
    assert [s["frequency_hz"] for s in out["steps"]] == [s.frequency_hz for s in plan.steps()]
    steps_s = sum(s["seconds_at_least"] for s in out["steps"])
    assert steps_s < out["seconds_at_least"] < steps_s + 10.0  # plus the pretest
    assert main(["plans", "show", "paper"]) == 0
    text = capsys.readouterr().out
    assert "2 N, up: 56 steps, 21 .. 40 Hz" in text and "acquisition at least" in text
    assert main(["plans", "show", "linear"]) == 0
    assert "66 records of 8 s" in capsys.readouterr().out
