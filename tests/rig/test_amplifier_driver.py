"""The amplifier driver against the simulated amplifier, through a real pseudo-terminal."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest

from rig.instruments.amplifier import AmplifierStatus, PowerAmplifier
from rig.instruments.scpi import InstrumentError, InstrumentIdentity, InstrumentTimeout
from sim_backend.amplifier import AmplifierConstants, AmplifierModel
from sim_backend.serial_amplifier import SimulatedAmplifierPort

TIMEOUT_S = 0.5
CONSTANTS = AmplifierConstants(gain_v_per_v=10.0, gain_max_v_per_v=20.0, current_limit_a=4.0)


@pytest.fixture
def sim() -> Iterator[SimulatedAmplifierPort]:
    port = SimulatedAmplifierPort(AmplifierModel(CONSTANTS))
    try:
        yield port
    finally:
        port.close()
    assert not port.running


@pytest.fixture
def amp(sim: SimulatedAmplifierPort) -> Iterator[PowerAmplifier]:
    with PowerAmplifier(sim.port, timeout_s=TIMEOUT_S) as driver:
        yield driver


def test_port_is_a_real_tty(sim: SimulatedAmplifierPort) -> None:
    assert sim.port.startswith("/dev/")
    fd = os.open(sim.port, os.O_RDWR | os.O_NOCTTY)
    try:
        assert os.isatty(fd)
    finally:
        os.close(fd)


def test_identify(amp: PowerAmplifier) -> None:
    assert amp.identify() == InstrumentIdentity("SIMRIG", "PA-SIM-100", "SN0001", "1.0.0")


def test_enable_and_mute(amp: PowerAmplifier, sim: SimulatedAmplifierPort) -> None:
    assert not amp.is_enabled
    amp.enable()
    assert amp.is_enabled
    assert sim.model.state().live
    amp.mute()
    assert not amp.is_enabled
    state = sim.model.state()
    assert (state.enabled, state.muted) == (False, True)
    amp.enable()
    assert sim.model.state().live


def test_gain_round_trip(amp: PowerAmplifier, sim: SimulatedAmplifierPort) -> None:
    assert amp.gain_range == (0.0, 20.0)
    amp.set_gain(7.25)
    assert amp.gain == pytest.approx(7.25, rel=1e-9)
    assert sim.model.state().gain_v_per_v == pytest.approx(7.25, rel=1e-9)


def test_out_of_range_gain_is_refused_by_driver_and_instrument(
    amp: PowerAmplifier, sim: SimulatedAmplifierPort
) -> None:
    with pytest.raises(ValueError, match=r"outside the range \[0, 20\]"):
        amp.set_gain(25.0)
    # bypass the driver's check: the instrument refuses and queues -222
    amp.write("GAIN 25")
    with pytest.raises(InstrumentError, match=r'-222,"Data out of range') as info:
        amp.check_errors()
    assert [e.code for e in info.value.errors] == [-222]
    assert amp.gain == pytest.approx(10.0)
    amp.check_errors()  # the queue is empty again


def test_unknown_command_and_bad_values_queue_errors(amp: PowerAmplifier) -> None:
    amp.write("FROB 1")
    amp.write("OUTP MAYBE")
    amp.write("GAIN abc")
    amp.write("GAIN")
    amp.write("*RST 1")
    codes = [e.code for e in amp.errors()]
    assert codes == [-113, -224, -104, -109, -108]
    assert amp.errors() == []


def test_long_forms_and_case_are_accepted(amp: PowerAmplifier) -> None:
    amp.write_checked("output:mute on")
    assert amp.query(":OUTPut:MUTE?") == "1"
    assert amp.query("status:ovld?") == "0"
    with pytest.raises(InstrumentTimeout):
        amp.query("OUT?")  # not a short form: unanswered, -113 queued
    assert [e.code for e in amp.errors()] == [-113]


def test_status_reflects_the_model(amp: PowerAmplifier, sim: SimulatedAmplifierPort) -> None:
    amp.set_remote(True)
    amp.set_gain(5.0)
    amp.enable()
    sim.model.check_current(2.0)
    status = amp.status()
    assert (status.enabled, status.muted, status.overload, status.remote) == (
        True,
        False,
        False,
        True,
    )
    assert status.current_a == pytest.approx(2.0)
    assert status.gain_v_per_v == pytest.approx(5.0)
    assert status.temperature_c == pytest.approx(sim.model.state().temperature_c, abs=1e-5)
    assert status.drive_ok
    assert status.temperature_c > CONSTANTS.ambient_temperature_c
    assert amp.measure_current_a() == pytest.approx(2.0)
    assert amp.measure_temperature_c() == pytest.approx(status.temperature_c)


def test_overload_shows_in_status_and_blocks_enable_until_cleared(
    amp: PowerAmplifier, sim: SimulatedAmplifierPort
) -> None:
    amp.enable()
    assert sim.model.check_current(CONSTANTS.current_limit_a * 1.5)
    status = amp.status()
    assert status.overload and not status.enabled and not status.drive_ok
    assert amp.overload
    with pytest.raises(InstrumentError, match=r"-221,.*overload latched"):
        amp.enable()
    assert not amp.is_enabled
    sim.model.check_current(0.1)  # the current falls: the latch holds
    assert amp.overload
    amp.clear_overload()
    assert not amp.overload
    assert not amp.is_enabled  # clearing does not switch the output on
    amp.enable()
    assert amp.status().drive_ok


def test_forced_overload_and_reset(amp: PowerAmplifier, sim: SimulatedAmplifierPort) -> None:
    amp.set_gain(3.0)
    amp.enable()
    sim.model.force_overload()
    amp.reset()
    status = amp.status()
    assert status.overload  # *RST keeps the latch
    assert status.gain_v_per_v == pytest.approx(CONSTANTS.gain_v_per_v)
    assert not status.enabled and not status.muted


def test_silent_instrument_times_out_within_the_timeout(
    amp: PowerAmplifier, sim: SimulatedAmplifierPort
) -> None:
    sim.silent = True
    start = time.monotonic()
    with pytest.raises(InstrumentTimeout) as info:
        amp.query("GAIN?")
    elapsed = time.monotonic() - start
    assert "'GAIN?'" in str(info.value) and sim.port in str(info.value)
    assert TIMEOUT_S * 0.9 <= elapsed < TIMEOUT_S + 0.5
    sim.silent = False
    assert amp.gain == pytest.approx(10.0)


def test_concurrent_queries_get_their_own_replies(amp: PowerAmplifier) -> None:
    failures: list[str] = []

    def ask_identity() -> None:
        for _ in range(60):
            if amp.identify().model != "PA-SIM-100":
                failures.append("identify")

    def ask_gain() -> None:
        for _ in range(60):
            if amp.gain != 10.0:
                failures.append("gain")

    threads = [threading.Thread(target=f) for f in (ask_identity, ask_gain, ask_identity)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert not any(t.is_alive() for t in threads)
    assert failures == []


def test_close_stops_the_thread_and_releases_the_pty() -> None:
    sim = SimulatedAmplifierPort()
    with PowerAmplifier(sim.port, timeout_s=TIMEOUT_S) as amp:
        assert amp.query("*OPC?") == "1"
    names = {t.name for t in threading.enumerate()}
    assert f"simulated amplifier on {sim.port}" in names
    sim.close()
    sim.close()  # idempotent
    assert not sim.running
    names = {t.name for t in threading.enumerate()}
    assert f"simulated amplifier on {sim.port}" not in names
    with pytest.raises(OSError):
        os.fstat(sim._master)


def test_status_validates_its_fields() -> None:
    with pytest.raises(ValueError, match="AmplifierStatus.current_a"):
        AmplifierStatus(True, False, False, -1.0, 5.0, 25.0, True)
    with pytest.raises(TypeError, match="AmplifierStatus.enabled"):
        AmplifierStatus(1, False, False, 1.0, 5.0, 25.0, True)  # type: ignore[arg-type]
