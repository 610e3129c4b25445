"""Faults on the simulated rig: each ends the run as a user would want, says what happened in
the file's exit_message, ramps the output to 0 V and keeps every completed step."""

import dataclasses

import numpy as np
import pytest

from analysis.measurement_file import read_measurement
from rig.backends.protocol import BackendError
from rig.config.plans import ControlPolicy, ControlSettings, Limits, ResponseLimit
from rig.run.commands import WriteStep
from rig.run.events import FaultRaised, RunWarning, StepFinished
from rig.run.safety import PLATEAU_EXPONENT, PLATEAU_EXPONENT_ANY_LEVEL, flat_tops
from rig.run.session import TestRun, open_rig
from sim_backend.amplifier import AmplifierModel
from sim_backend.daq import FaultSwitches, SimulatedDaq
from sim_backend.serial_amplifier import SimulatedAmplifierPort
from tests.rig.rig_helpers import (
    assert_ramped_to_zero,
    reduced_plan,
    run_on_sim,
    setup_at,
    sim_daq,
)

PLAN = reduced_plan(levels_n=(2.0, 4.0), ranges=((21.0, 22.0, 1.0),))


def _after_step(n, action):
    """A subscriber that calls ``action()`` once the n-th step is on disk."""

    def on_event(event):
        if isinstance(event, StepFinished) and event.n_done == n:
            action()

    return on_event


def _ended(path, status, *phrases, steps):
    data = read_measurement(path)
    assert not data.complete and data.exit_status == status
    for phrase in phrases:
        assert phrase in data.exit_message, data.exit_message
    assert "Output ramped to 0 V" in data.exit_message
    assert list(data.plan_index) == list(range(steps))
    return data


def test_amplifier_overload_through_the_serial_driver(tmp_path):
    setup = setup_at()
    model = AmplifierModel()
    model.enable()
    with SimulatedAmplifierPort(model) as port:
        lab = dataclasses.replace(
            setup, amplifier=dataclasses.replace(setup.amplifier, port=port.port)
        )
        options = {
            "truth": "reference",
            "seed": 7,
            "amplifier": model,
            "record_output": True,
            "sensor_masses_kg": lab.sensor_masses_kg(),
        }
        with open_rig("sim", lab, backend_options=options, lock_dir=tmp_path) as rig:
            assert rig.amplifier is not None and model.state().enabled
            daq = rig.backend
            run = TestRun(daq, PLAN, lab, tmp_path / "amp.h5", amplifier=rig.amplifier)
            trip = _after_step(1, lambda: daq.set_faults(FaultSwitches(amplifier_overload=True)))
            faults = []
            run.engine.bus.subscribe(trip)
            run.engine.bus.subscribe(faults.append, kinds=(FaultRaised,))
            summary = run.execute()
            assert_ramped_to_zero(daq)
            assert model.state().muted or not model.state().enabled
    assert summary.fault_kind == "amplifier-overload"
    assert [f.kind for f in faults] == ["amplifier-overload"]
    _ended(tmp_path / "amp.h5", "aborted", "power amplifier reported an overload", steps=1)


def test_amplifier_overload_without_remote_control_is_a_lost_force(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup, record_output=True)
    trip = _after_step(1, lambda: daq.set_faults(FaultSwitches(amplifier_overload=True)))
    summary, run, daq = run_on_sim(
        PLAN, tmp_path / "f.h5", setup=setup, daq=daq, subscribers=[trip]
    )
    assert summary.fault_kind == "no-force"
    _ended(tmp_path / "f.h5", "aborted", "no force at the drive point", "tripped", steps=1)
    assert_ramped_to_zero(daq)


def test_sensor_that_stops_responding(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup, record_output=True)
    cut = _after_step(1, lambda: daq.set_faults(FaultSwitches(disconnected=("acc7",))))
    summary, run, daq = run_on_sim(PLAN, tmp_path / "s.h5", setup=setup, daq=daq, subscribers=[cut])
    assert summary.fault_kind == "sensor"
    _ended(tmp_path / "s.h5", "aborted", "'acc7' (point 7", "stopped responding", steps=1)
    assert_ramped_to_zero(daq)


def test_disconnected_sensor_is_named_by_the_pretest(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup, FaultSwitches(disconnected=("acc6",)), record_output=True)
    summary, run, daq = run_on_sim(PLAN, tmp_path / "p.h5", setup=setup, daq=daq)
    assert summary.fault_kind == "pretest"
    data = _ended(tmp_path / "p.h5", "aborted", "pretest: channel 'acc6' (point 6 y)", steps=0)
    assert "acc7" not in data.exit_message and "does not respond" in data.exit_message


def _sensitive_tip(setup, mv_per_g: float):
    """``setup`` with the tip's accelerometer ``mv_per_g`` sensitive (its +-5 V input range
    then holds +-5000 / mv_per_g g)."""
    chans = tuple(
        dataclasses.replace(c, sensitivity=mv_per_g) if c.name == "acc7" else c
        for c in setup.channels
    )
    return dataclasses.replace(setup, channels=chans)


def test_saturated_sensor_is_reported_as_clipping(tmp_path):
    # a 1000 mV/g accelerometer at the tip: 12 m/s^2 is 1.2 V of its 5 V input range
    setup = _sensitive_tip(setup_at(), 1000.0)
    plan = reduced_plan(levels_n=(8.0,), ranges=((21.0, 24.0, 3.0),))
    daq = sim_daq(setup, record_output=True)
    # at 24 Hz and 8 N the tip's acceleration is about 25 m/s^2; its sensor now stops at 12
    clip = _after_step(1, lambda: daq.set_faults(FaultSwitches(clip_levels={"acc7": 12.0})))
    summary, run, daq = run_on_sim(
        plan, tmp_path / "c.h5", setup=setup, daq=daq, subscribers=[clip]
    )
    assert summary.fault_kind == "clipping"
    _ended(tmp_path / "c.h5", "aborted", "'acc7' (point 7", "flat-topped", "saturates", steps=1)
    assert_ramped_to_zero(daq)


def test_a_sensor_saturating_far_below_its_range_is_reported_as_faulty(tmp_path):
    # the same cut-off at 12 m/s^2 on the shipped 10 mV/g sensor (+-5 V output swing: +-490 g)
    # is 0.25 % of its full scale: no range explains it, the sensor is faulty; order 1 of the
    # clipped 25 m/s^2 would be 40 % low and order 3 several times too high if it were stored
    setup = setup_at()
    tip = next(c for c in setup.channels if c.name == "acc7")
    assert tip.output_swing_v == 5.0 and tip.full_scale_units > 4000.0
    plan = reduced_plan(levels_n=(8.0,), ranges=((21.0, 24.0, 3.0),))
    daq = sim_daq(setup, record_output=True)
    clip = _after_step(1, lambda: daq.set_faults(FaultSwitches(clip_levels={"acc7": 12.0})))
    summary, run, daq = run_on_sim(
        plan, tmp_path / "c.h5", setup=setup, daq=daq, subscribers=[clip]
    )
    assert summary.fault_kind == "clipping"
    phrases = ("'acc7' (point 7", "flat-topped", "saturates below its range", "faulty")
    _ended(tmp_path / "c.h5", "aborted", *phrases, steps=1)
    assert_ramped_to_zero(daq)


def test_a_saturated_force_gauge_is_named_as_such_not_as_lost_force(tmp_path):
    setup = setup_at()
    plan = reduced_plan(levels_n=(8.0,), ranges=((21.0, 24.0, 3.0),))
    daq = sim_daq(setup, record_output=True)
    clip = _after_step(1, lambda: daq.set_faults(FaultSwitches(clip_levels={"force3": 4.0})))
    summary, run, daq = run_on_sim(
        plan, tmp_path / "f.h5", setup=setup, daq=daq, subscribers=[clip]
    )
    assert summary.fault_kind == "clipping", summary.message
    data = _ended(tmp_path / "f.h5", "aborted", "'force3'", "force gauge saturates", steps=1)
    assert "no force" not in data.exit_message
    assert_ramped_to_zero(daq)


def _period(y):
    return np.tile(y, 8)[:, None]


def test_peak_exponent_tells_a_plateau_from_smooth_flat_peaks():
    # smooth peaks: 2 for a sine, about 3.5 for the flattest peak orders 1 and 3 can make
    # (third harmonic 1/9 in phase), under 5 with order 5 as well; a clipped sine grows without
    # bound as the cut deepens. Tolerances: the exponent is read from two sample counts.
    n = 1024
    t = 2 * np.pi * np.arange(n) / n
    noise = np.array([0.0])

    def exponent(y):
        return float(flat_tops(_period(y), n, noise)[1][0])

    assert exponent(np.sin(t)) == pytest.approx(2.0, abs=0.1)
    smooth = [np.sin(t) + c * np.sin(3 * t) for c in (0.05, 0.1, 1 / 9, 0.14, 0.2)]
    smooth.append(np.sin(t) + np.sin(3 * t) / 6 + np.sin(5 * t) / 50)  # flat to order 6
    assert max(exponent(y) for y in smooth) < 5.1 < PLATEAU_EXPONENT_ANY_LEVEL
    cuts = {p: exponent(np.clip(np.sin(t), -p, p)) for p in (0.9, 0.75, 0.6, 0.48, 0.3)}
    assert cuts[0.9] > PLATEAU_EXPONENT
    assert all(cuts[p] > PLATEAU_EXPONENT_ANY_LEVEL for p in (0.6, 0.48, 0.3)), cuts
    assert list(cuts.values()) == sorted(cuts.values())
    # one-sided flat top (a stop on one side): not a saturated sensor
    assert exponent(np.minimum(np.sin(t), 0.5) + 0.25) == 0.0


def test_channel_beyond_its_input_range(tmp_path):
    setup = setup_at()
    chans = tuple(
        dataclasses.replace(c, range_v=0.028) if c.name == "acc7" else c for c in setup.channels
    )
    # +-0.028 V is +-26 m/s^2 at acc7: enough at 2 N and 23 Hz (8 m/s^2 plus noise), not at 8 N
    setup = dataclasses.replace(setup, channels=chans)
    plan = reduced_plan(levels_n=(2.0, 8.0), ranges=((23.0, 23.0, 1.0),))
    summary, run, daq = run_on_sim(plan, tmp_path / "r.h5", setup=setup)
    assert summary.fault_kind == "clipping"
    _ended(tmp_path / "r.h5", "aborted", "'acc7'", "reached its input range", "range_v", steps=1)


def test_daq_read_timeout(tmp_path):
    setup = setup_at()
    daq = sim_daq(setup, record_output=True)
    stall = _after_step(1, lambda: daq.set_faults(FaultSwitches(read_timeout=True)))
    summary, run, daq = run_on_sim(
        PLAN, tmp_path / "t.h5", setup=setup, daq=daq, subscribers=[stall]
    )
    assert summary.fault_kind == "daq"
    _ended(tmp_path / "t.h5", "failed", "DAQ stopped delivering samples", steps=1)
    assert_ramped_to_zero(daq)


def test_diverging_controller(tmp_path):
    """Someone turns the amplifier's gain down mid-run: the force per volt falls 30 times,
    which the controller (default settings) calls non-physical; the run stops."""
    setup = setup_at()
    plan = dataclasses.replace(
        PLAN, control=ControlPolicy(ControlSettings(orders=PLAN.excitation.orders))
    )
    daq = sim_daq(setup, record_output=True)
    knob = _after_step(1, lambda: daq.amplifier.set_gain(0.3))
    summary, run, daq = run_on_sim(
        plan, tmp_path / "d.h5", setup=setup, daq=daq, subscribers=[knob]
    )
    assert summary.fault_kind == "control-diverged"
    _ended(tmp_path / "d.h5", "aborted", "force control diverged at 22 Hz, 2 N", steps=1)
    assert_ramped_to_zero(daq)


def test_exception_in_plan_code(tmp_path):
    setup = setup_at()

    def buggy(procedure):
        def wrapped(ctx):
            gen = procedure(ctx)
            result, written = None, 0
            while True:
                try:
                    command = gen.send(result)
                except StopIteration:
                    return
                written += isinstance(command, WriteStep)
                result = yield command
                if written == 2:
                    raise ZeroDivisionError("a bug in plan code")

        return wrapped

    daq = sim_daq(setup, record_output=True)
    summary, run, daq = run_on_sim(
        PLAN, tmp_path / "e.h5", setup=setup, daq=daq, procedure_wrapper=buggy
    )
    assert summary.status == "failed"
    _ended(
        tmp_path / "e.h5",
        "failed",
        "error in the test procedure: ZeroDivisionError: a bug in plan code",
        steps=2,
    )
    assert_ramped_to_zero(daq)


def test_ctrl_c(tmp_path):
    setup = setup_at()

    def press_ctrl_c():
        raise KeyboardInterrupt

    daq = sim_daq(setup, record_output=True)
    summary, run, daq = run_on_sim(
        PLAN, tmp_path / "k.h5", setup=setup, daq=daq, subscribers=[_after_step(2, press_ctrl_c)]
    )
    assert summary.interrupted and summary.status == "aborted"
    _ended(tmp_path / "k.h5", "aborted", "interrupted by the user (Ctrl-C)", steps=2)
    assert_ramped_to_zero(daq)


def test_response_limits_alarm_then_abort(tmp_path):
    setup = setup_at()
    tip = ResponseLimit(point=7, displacement_alarm_m=0.1e-3, displacement_abort_m=0.5e-3)
    plan = dataclasses.replace(
        PLAN,
        limits=Limits(drive_peak_v=PLAN.limits.drive_peak_v, response=(tip,)),
        excitation=dataclasses.replace(PLAN.excitation, levels_n=(2.0, 8.0)),
    )
    warnings = []
    summary, run, daq = run_on_sim(
        plan, tmp_path / "l.h5", setup=setup, subscribers=[warnings.append]
    )
    alarms = [w for w in warnings if isinstance(w, RunWarning) and w.kind == "response-alarm"]
    assert alarms and "above the alarm limit 0.0001 m" in alarms[0].message
    assert summary.fault_kind == "response-limit"
    data = _ended(
        tmp_path / "l.h5", "aborted", "'acc7'", "exceeded the abort limit 0.0005 m", steps=2
    )
    tip_disp = np.abs(data.response[:, 3, 0]) / (2 * np.pi * data.frequency_hz) ** 2
    assert np.all(tip_disp < 0.5e-3)


@pytest.mark.parametrize("pause", [True])
def test_pause_on_a_recoverable_fault_then_resume(tmp_path, pause):
    """With pause_on_fault (a GUI), a disconnected sensor pauses the run; reconnected and
    resumed, the run completes."""
    import threading

    setup = setup_at()
    daq = sim_daq(setup, record_output=True)
    holder = {}

    def on_event(event):
        if isinstance(event, StepFinished) and event.n_done == 1:
            daq.set_faults(FaultSwitches(disconnected=("acc6",)))
        if isinstance(event, FaultRaised) and event.paused:

            def fix():
                daq.set_faults(FaultSwitches())
                holder["run"].engine.resume()

            threading.Thread(target=fix).start()

    run = TestRun(daq, PLAN, setup, tmp_path / "pf.h5", pause_on_fault=pause)
    holder["run"] = run
    faults = []
    run.engine.bus.subscribe(on_event)
    run.engine.bus.subscribe(faults.append, kinds=(FaultRaised,))
    summary = run.execute()
    daq.close()
    assert [f.kind for f in faults] == ["sensor"] and faults[0].paused
    assert summary.status == "success" and summary.n_done == PLAN.n_steps


class _StopFails(SimulatedDaq):
    """The simulated rig whose output stage does not answer the stop request."""

    def stop(self) -> None:
        if self._state == "running":
            raise BackendError("the output task did not stop (device not responding)")
        super().stop()


def _stop_fails_daq(setup):
    return _StopFails("reference", sensor_masses_kg=setup.sensor_masses_kg(), seed=7)


@pytest.mark.parametrize("abort_after", [None, 1])
def test_a_failed_ramp_to_zero_is_said_never_claimed(tmp_path, abort_after):
    setup = setup_at()
    daq = _stop_fails_daq(setup)
    subscribers = []
    if abort_after:
        subscribers = [
            _after_step(1, lambda: run_holder[0].engine.abort("stopped by the operator"))
        ]
    run_holder = []
    try:
        run = TestRun(daq, PLAN, setup, tmp_path / "s.h5")
        run_holder.append(run)
        for s in subscribers:
            run.engine.bus.subscribe(s)
        summary = run.execute()
    finally:
        daq._state = "closed"  # the stand-in cannot be stopped
    data = read_measurement(tmp_path / "s.h5")
    for text in (data.exit_message, summary.message):
        assert "Output ramped to 0 V" not in text
        assert "Ramping the output to 0 V FAILED" in text
        assert "did not stop (device not responding)" in text
        assert "may not be at 0 V" in text
    assert not summary.output_at_zero and data.output_at_zero is False
    assert any("may not be at 0 V" in line for line in summary.lines())
    if abort_after:
        assert summary.status == "aborted" and "stopped by the operator" in data.exit_message
    else:
        assert summary.status == "success"
