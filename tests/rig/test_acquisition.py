"""The engine's acquisition component (pure numbers) and commands registered by the caller."""

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import pytest

from rig.run.acquisition import Output, first_sample, settling_test
from rig.run.commands import Acquire, SetDrive
from rig.run.engine import RunEngine
from rig.run.faults import RunFault
from tests.rig.rig_helpers import assert_ramped_to_zero, reduced_plan, setup_at, sim_daq

ORDERS = (Fraction(1), Fraction(2), Fraction(3))


def test_a_measurement_starts_after_settling_on_a_period_boundary():
    out = Output(np.zeros(100), 100, steady_index=37, band_hz=None)
    assert first_sample(out, cursor=0, settle_periods=3) == 337
    # already read past that point: the next sample in phase with the steady output
    start = first_sample(out, cursor=400, settle_periods=3)
    assert start >= 400 and (start - 37) % 100 == 0 and start < 500


class _Estimate:
    """The part of a harmonic estimate the settling test reads: block phasors (B, C, H)."""

    def __init__(self, block_phasors):
        self.block_phasors = np.asarray(block_phasors)


def _acquire(**kw):
    base = dict(blocks=8, block_periods=2, settle_periods=0, settling_tolerance=0.01)
    return Acquire(**{**base, **kw})


def test_steady_blocks_settle_and_a_drift_does_not():
    rng = np.random.default_rng(3)
    steady = (1.0 + 1e-4 * rng.standard_normal((16, 2, 3))) * np.array([1.0, 0.02, 0.02])
    ok, _ = settling_test(_Estimate(steady), ORDERS, _acquire(blocks=16))
    assert ok
    # a shift of 0.8 % between the window's halves: each block-to-block change is below the
    # 1 % tolerance, the halves' means differ by more than the 0.5 % drift tolerance and
    # more than 3 standard errors of their difference
    shifted = steady * np.where(np.arange(16) < 8, 1.0, 1.008)[:, None, None]
    ok, message = settling_test(_Estimate(shifted), ORDERS, _acquire(blocks=16))
    assert not ok and "drifting" in message


@dataclass(frozen=True)
class _Mark:
    label: str


def _engine():
    setup = setup_at()
    plan = reduced_plan()
    daq = sim_daq(setup, record_output=True)
    engine = RunEngine(daq, setup, setup.channels_for_points(plan.points), plan.limits)
    return engine, daq


def test_a_registered_command_is_executed_and_answers_the_procedure():
    engine, daq = _engine()
    seen = []
    engine.register_command(_Mark, lambda eng, cmd: f"{cmd.label} at {eng.state}")

    def procedure(ctx):
        seen.append((yield _Mark("first")))
        yield SetDrive(22.0, np.array([0.05, 0, 0], complex), ORDERS, ramp_s=0.05)
        yield Acquire(settle_periods=10, blocks=4)
        seen.append((yield _Mark("second")))

    outcome = engine.run(procedure)
    assert outcome.status == "success", outcome.message
    assert seen == ["first at running", "second at running"]
    assert_ramped_to_zero(daq)


def test_a_fault_from_a_registered_command_ends_the_run_with_the_output_ramped():
    engine, daq = _engine()

    def trip(eng, cmd):
        raise RunFault("response-limit", f"{cmd.label}: limit exceeded")

    engine.register_command(_Mark, trip)

    def procedure(ctx):
        yield SetDrive(22.0, np.array([0.05, 0, 0], complex), ORDERS, ramp_s=0.05)
        yield Acquire(settle_periods=10, blocks=4)
        yield _Mark("trip")

    outcome = engine.run(procedure)
    assert outcome.status == "aborted" and outcome.fault_kind == "response-limit"
    assert "Output ramped to 0 V" in outcome.message
    assert_ramped_to_zero(daq)


def test_registration_is_checked():
    engine, _ = _engine()
    engine.register_command(_Mark, lambda eng, cmd: None)
    with pytest.raises(ValueError, match="already registered"):
        engine.register_command(_Mark, lambda eng, cmd: None)
    with pytest.raises(ValueError, match="SetDrive is already registered"):
        engine.register_command(SetDrive, lambda eng, cmd: None)
    with pytest.raises(TypeError, match="not callable"):
        engine.register_command(int, "handler")
