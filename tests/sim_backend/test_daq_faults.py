"""Fault injection, real-time pacing and argument checks of the simulated DAQ."""

from __future__ import annotations

import time

import numpy as np
import pytest

from rig.backends.protocol import BackendError, ReadTimeoutError
from sim_backend.amplifier import AmplifierModel
from sim_backend.daq import SimulatedDaq
from sim_backend.errors import SimulatorError
from sim_backend.sensors import FaultSwitches
from sim_backend.serial_amplifier import AmplifierProtocol
from tests.sim_backend.rig_setup import FS, multisine, paper_config

N = 80


def running(**kwargs) -> SimulatedDaq:
    daq = SimulatedDaq(**kwargs)
    daq.configure(paper_config())
    daq.write_periodic(multisine(N, 0.02), 0.1)
    daq.start()
    return daq


def test_disconnected_sensor_reads_only_its_noise_floor() -> None:
    daq = running(seed=1, faults=FaultSwitches(disconnected=("acc7",)))
    data, _ = daq.read(int(10 * FS), 5.0)
    sigma = daq.truth.noise.acceleration_ms2_per_rthz * np.sqrt(FS / 2)
    assert np.std(data[:, 3]) == pytest.approx(sigma, rel=0.05)
    assert np.std(data[:, 2]) > 2 * sigma  # its neighbour at point 6 sees the beam move
    daq.set_faults(FaultSwitches())
    data, _ = daq.read(4096, 5.0)
    assert np.std(data[:, 3]) > 2 * sigma
    daq.close()


def test_clipped_sensor_is_flat_beyond_its_level() -> None:
    daq = running(noise=False, faults=FaultSwitches(clip_levels={"acc6": 1.0}))
    data, _ = daq.read(int(10 * FS), 5.0)
    assert np.abs(data[:, 2]).max() == pytest.approx(1.0, abs=0.01)  # within an ADC step
    assert np.mean(np.abs(data[-4096:, 2]) > 0.999) > 0.2
    daq.close()


def test_read_timeout_raises_the_protocols_error_and_recovers() -> None:
    daq = running()
    daq.read(100, 5.0)
    daq.set_faults(FaultSwitches(read_timeout=True))
    with pytest.raises(ReadTimeoutError):
        daq.read(10, 0.01)
    daq.set_faults(FaultSwitches())
    _, first = daq.read(10, 5.0)
    assert first == 100  # nothing was consumed by the timed-out read
    daq.close()


def test_excess_current_trips_the_amplifier_which_mutes_the_drive() -> None:
    amplifier = AmplifierModel(daq_truth_amplifier())
    amplifier.enable()
    port = AmplifierProtocol(amplifier)
    daq = SimulatedDaq(amplifier=amplifier, noise=False)
    daq.configure(paper_config())
    daq.write_periodic(multisine(64, 0.05), 0.1)
    daq.start()
    daq.read(int(2 * FS), 5.0)
    assert port.handle_line("STAT:OVLD?") == "0"
    assert 0 < float(port.handle_line("MEAS:CURR?")) < amplifier.constants.current_limit_a
    index = daq.write_periodic(multisine(64, 1.5), 0.2)  # about 6 A: beyond the 5 A limit
    data, first = daq.read(index + int(3 * FS), 5.0)
    assert port.handle_line("STAT:OVLD?") == "1"
    assert port.handle_line("OUTP?") == "0"
    force = data[:, 0]
    assert np.abs(force[-int(FS) :]).max() < 0.01 * np.abs(force[: index - first]).max()
    assert np.abs(data[-int(FS) :, 4]).max() > 0.5  # the DAQ still puts out its drive
    daq.close()


def test_overload_fault_switch_latches_the_amplifier() -> None:
    daq = running(noise=False)
    daq.read(int(2 * FS), 5.0)
    daq.set_faults(FaultSwitches(amplifier_overload=True))
    data, _ = daq.read(int(3 * FS), 5.0)
    state = daq.amplifier.state()
    assert state.overload and not state.enabled
    assert np.abs(data[-1024:, 0]).max() < 0.02 * np.abs(data[:1024, 0]).max()
    daq.close()


def daq_truth_amplifier():
    from sim_backend.truth import load_truth

    return load_truth("reference").amplifier


def test_realtime_reads_are_paced_by_the_clock() -> None:
    daq = running(realtime=True)
    t0 = time.monotonic()
    daq.read(int(0.25 * FS), 2.0)
    elapsed = time.monotonic() - t0
    assert 0.24 < elapsed < 1.0
    with pytest.raises(ReadTimeoutError):
        daq.read(int(1.0 * FS), 0.05)
    daq.close()


def test_fast_mode_runs_far_ahead_of_the_clock() -> None:
    daq = running()
    t0 = time.monotonic()
    daq.read(int(60 * FS), 5.0)
    # 60 s of samples: a read paced by the clock takes 60 s; not paced, a small fraction of it
    # (about 0.3 s on an idle machine; the bound leaves room for a loaded one)
    assert time.monotonic() - t0 < 6.0
    daq.close()


def test_errors_are_the_protocols_when_rig_is_loaded() -> None:
    daq = SimulatedDaq()
    with pytest.raises(BackendError) as info:
        daq.read(10, 1.0)
    assert isinstance(info.value, SimulatorError)
    with pytest.raises(BackendError, match="unknown truth"):
        SimulatedDaq("no_such_truth")
    bad = paper_config()
    from rig.backends.protocol import AcquisitionConfig, AIChannelConfig

    off_structure = AIChannelConfig("acc99", "Dev1/ai9", "acceleration", 100.0, "mV/g", point=99)
    with pytest.raises(BackendError, match="point 99"):
        daq.configure(AcquisitionConfig(FS, bad.ao, (*bad.ai, off_structure)))
    with pytest.raises(BackendError, match="unknown channel"):
        daq.configure(bad)
        daq.set_faults(FaultSwitches(disconnected=("nope",)))
    daq.close()
