"""Tests of the NI-DAQmx driver and the backend registry.

Most tests run the driver against the recording stand-in for nidaqmx's task API
(:mod:`tests.rig.nidaqmx_standin`), checking both the calls it makes (bound to the installed
nidaqmx signatures) and the drive waveform it produces on the emulated device. The tests of a
missing driver use the real, installed nidaqmx. Tests marked ``hardware`` need a real device
(``pytest --ni-device Dev1``) wired as their docstrings say.
"""

from __future__ import annotations

import atexit
import gc
import logging
import math
import subprocess
import sys
import types
import weakref
from pathlib import Path

import nidaqmx
import nidaqmx.errors
import nidaqmx.system
import numpy as np
import pytest
from nidaqmx.constants import (
    AccelSensitivityUnits,
    AccelUnits,
    AcquisitionType,
    AOIdleOutputBehavior,
    Coupling,
    ExcitationSource,
    ExcitationVoltageOrCurrent,
    ForceIEPESensorSensitivityUnits,
    ForceUnits,
    RegenerationMode,
    TaskMode,
    WatchdogAOExpirState,
)
from nidaqmx.errors import DaqError

import rig.backends
import rig.backends.protocol as protocol
from rig.backends import open_backend
from rig.backends.ni import STANDARD_GRAVITY, NiDaqBackend, _close_at_exit
from rig.backends.protocol import (
    AcquisitionConfig,
    AIChannelConfig,
    AOChannelConfig,
    BackendError,
    ReadTimeoutError,
)
from tests.rig.backend_conformance import sine_period, standard_config
from tests.rig.nidaqmx_standin import StandinDevice, loopback

RATE = 2048.0
GAINS = [44.4, 98.1, 981.0, 1.0]  # N/V, (m/s^2)/V, (m/s^2)/V, V/V of the loop-back source
DRIVER_MESSAGE = "Install NI-DAQmx or use --backend sim"


def make(device: StandinDevice | None = None, **options) -> tuple[NiDaqBackend, StandinDevice]:
    device = device or StandinDevice("Dev1", ai_source=loopback(GAINS))
    backend = NiDaqBackend(
        "Dev1",
        task_factory=device.task_factory,
        watchdog_factory=device.watchdog_factory,
        **options,
    )
    return backend, device


def tiled(wave: np.ndarray, anchor: int, start: int, stop: int) -> np.ndarray:
    return wave[(np.arange(start, stop) - anchor) % wave.size]


def raised_cosine(length: int) -> np.ndarray:
    return 0.5 - 0.5 * np.cos(np.pi * (np.arange(length) + 1) / length)


def read_until(backend: NiDaqBackend, index: int, block: int = 300) -> int:
    next_index = 0
    while next_index <= index:
        data, first = backend.read(block, timeout_s=1.0)
        next_index = first + data.shape[0]
    return next_index


def args_of(device: StandinDevice, name: str, kind: str | None = None) -> list[dict]:
    return [c.args for c in device.calls_named(name, kind)]


@pytest.fixture
def running():
    """A started backend regenerating a 0.5 V sine of 64 samples; closed afterwards."""
    backend, device = make()
    backend.configure(standard_config())
    wave = sine_period(0.5)
    backend.write_periodic(wave, 0.0)
    backend.start()
    yield backend, device, wave
    backend.close()


# ---------------------------------------------------------------- without the NI driver


def test_constructor_without_driver_says_what_to_do():
    with pytest.raises(BackendError) as info:
        NiDaqBackend("Dev1")
    message = str(info.value)
    assert message.startswith("NI-DAQmx driver not found (")
    assert message.endswith(DRIVER_MESSAGE)
    assert isinstance(info.value.__cause__, nidaqmx.errors.DaqNotFoundError)
    assert not isinstance(info.value.__cause__, DaqError)


def test_configure_with_real_nidaqmx_task_without_driver():
    backend = NiDaqBackend(
        "Dev1", task_factory=nidaqmx.Task, watchdog_factory=nidaqmx.system.WatchdogTask
    )
    with pytest.raises(BackendError, match="NI-DAQmx driver not found") as info:
        backend.configure(standard_config())
    assert DRIVER_MESSAGE in str(info.value)
    backend.close()


def test_open_backend_ni_without_driver():
    with pytest.raises(BackendError, match=r"NI-DAQmx driver not found \(.*use --backend sim"):
        open_backend("ni", device="Dev1")


def test_importing_the_backends_does_not_import_nidaqmx():
    code = (
        "import sys, rig.backends, rig.backends.ni, rig.backends.ni_watchdog; "
        "assert 'nidaqmx' not in sys.modules, 'nidaqmx imported'"
    )
    root = Path(__file__).resolve().parents[2]
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    assert result.returncode == 0, result.stderr


# ---------------------------------------------------------------- registry


def test_registry_reexports_the_protocol_and_lists_backends():
    for name in protocol.__all__:
        assert getattr(rig.backends, name) is getattr(protocol, name)
    assert rig.backends.available_backends() == ("ni", "sim")


def test_unknown_backend_lists_the_known_ones():
    with pytest.raises(BackendError) as info:
        open_backend("labjack")
    assert "'labjack'" in str(info.value)
    assert "'ni'" in str(info.value) and "'sim'" in str(info.value)


def test_open_backend_ni_passes_options():
    device = StandinDevice()
    backend = open_backend(
        "ni",
        device="Dev1",
        task_factory=device.task_factory,
        watchdog_factory=device.watchdog_factory,
        ao_buffer_s=0.25,
    )
    assert isinstance(backend, NiDaqBackend)
    backend.configure(standard_config())
    backend.start()
    assert backend.ao_buffer_samples >= round(0.25 * backend.sample_rate_hz)
    backend.close()


def test_sim_backend_is_imported_lazily_with_options(monkeypatch):
    class SimulatedDaq(NiDaqBackend):
        def __init__(self, **options):
            self.options = options
            device = StandinDevice()
            super().__init__("Dev1", device.task_factory, device.watchdog_factory)

    module = types.ModuleType("sim_backend.daq")
    module.SimulatedDaq = SimulatedDaq
    monkeypatch.setitem(sys.modules, "sim_backend.daq", module)
    backend = open_backend("sim", seed=3, truth="bump")
    assert isinstance(backend, SimulatedDaq)
    assert backend.options == {"seed": 3, "truth": "bump"}


def test_missing_sim_backend_module_gives_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "sim_backend.daq", None)  # import now fails
    with pytest.raises(BackendError, match=r"backend 'sim' is not available.*sim_backend\.daq"):
        open_backend("sim")


def test_backend_not_satisfying_the_protocol_is_refused(monkeypatch):
    module = types.ModuleType("sim_backend.daq")
    module.SimulatedDaq = lambda **options: object()
    monkeypatch.setitem(sys.modules, "sim_backend.daq", module)
    with pytest.raises(BackendError, match="does not satisfy the DaqBackend protocol"):
        open_backend("sim")


# ---------------------------------------------------------------- configuration


def _check_output_task(device) -> None:
    """The drive zeroed on demand, then its continuous, regenerating, triggered task."""
    zero = args_of(device, "write", "ao-on-demand")
    assert zero and zero[0]["data"] == 0.0 and zero[0]["auto_start"] is True
    assert device.tasks[0].closed, "the on-demand task that zeroes the drive is closed"

    (ao_chan,) = args_of(device, "ao_channels.add_ao_voltage_chan", "ao")
    assert ao_chan["physical_channel"] == "Dev1/ao0"
    assert (ao_chan["min_val"], ao_chan["max_val"]) == (-2.0, 2.0)
    (ao_timing,) = args_of(device, "timing.cfg_samp_clk_timing", "ao")
    assert ao_timing["rate"] == RATE and ao_timing["sample_mode"] is AcquisitionType.CONTINUOUS
    (regen,) = args_of(device, "set out_stream.regen_mode", "ao")
    assert regen["value"] is RegenerationMode.ALLOW_REGENERATION
    (trigger,) = args_of(device, "triggers.start_trigger.cfg_dig_edge_start_trig", "ao")
    assert trigger["trigger_source"] == "/Dev1/ai/StartTrigger"
    (idle,) = args_of(device, "set ao_channels['Dev1/ao0'].ao_idle_output_behavior", "ao")
    assert idle["value"] is AOIdleOutputBehavior.ZERO_VOLTS
    assert args_of(device, "control", "ao") == [{"action": TaskMode.TASK_VERIFY}]


def _check_input_channels(device, config) -> None:
    """IEPE force and accelerations in their units with internal excitation, AC coupled."""
    (force,) = args_of(device, "ai_channels.add_ai_force_iepe_chan")
    assert force["physical_channel"] == "Dev1/ai0" and force["name_to_assign_to_channel"] == "force"
    assert force["units"] is ForceUnits.NEWTONS
    assert force["sensitivity"] == 22.5
    assert force["sensitivity_units"] is ForceIEPESensorSensitivityUnits.MILLIVOLTS_PER_NEWTON
    assert force["current_excit_source"] is ExcitationSource.INTERNAL
    assert force["current_excit_val"] == 0.004
    assert force["max_val"] == pytest.approx(5.0 * 1000 / 22.5) == -force["min_val"]
    accels = args_of(device, "ai_channels.add_ai_accel_chan")
    assert [a["name_to_assign_to_channel"] for a in accels] == ["head_acc", "tip_acc"]
    for accel, sensitivity in zip(accels, (100.0, 10.0), strict=True):
        assert accel["units"] is AccelUnits.G
        assert accel["sensitivity"] == sensitivity
        assert accel["sensitivity_units"] is AccelSensitivityUnits.MILLIVOLTS_PER_G
        assert accel["current_excit_source"] is ExcitationSource.INTERNAL
        assert accel["current_excit_val"] == 0.004
        assert accel["max_val"] == pytest.approx(5.0 * 1000 / sensitivity)
    (volt,) = args_of(device, "ai_channels.add_ai_voltage_chan")
    assert (volt["min_val"], volt["max_val"]) == (-5.0, 5.0)
    couplings = device.calls_named("set ai_channels['force'].ai_coupling")
    couplings += device.calls_named("set ai_channels['head_acc'].ai_coupling")
    couplings += device.calls_named("set ai_channels['tip_acc'].ai_coupling")
    assert [c.args["value"] for c in couplings] == [Coupling.AC] * 3
    assert not device.calls_named("set ai_channels['drive'].ai_coupling")
    (ai_timing,) = args_of(device, "timing.cfg_samp_clk_timing", "ai")
    assert ai_timing["sample_mode"] is AcquisitionType.CONTINUOUS
    assert ai_timing["samps_per_chan"] == math.ceil(config.buffer_s * RATE)


def _check_watchdog(device, config) -> None:
    """A watchdog that zeroes the drive when it expires."""
    (watchdog,) = args_of(device, "WatchdogTask")
    assert watchdog["device_name"] == "Dev1" and watchdog["timeout"] == config.watchdog_s
    (states,) = args_of(device, "cfg_watchdog_ao_expir_states")
    (state,) = states["expiration_states"]
    assert state.physical_channel == "Dev1/ao0" and state.expiration_state == 0.0
    assert state.output_type is WatchdogAOExpirState.VOLTAGE


def test_configure_creates_the_documented_tasks():
    backend, device = make()
    config = standard_config()
    rate = backend.configure(config)
    assert rate == 100e6 / round(100e6 / RATE) != RATE  # the realised rate, read back
    assert backend.sample_rate_hz == rate

    _check_output_task(device)
    _check_input_channels(device, config)
    _check_watchdog(device, config)
    assert backend.watchdog_armed
    backend.close()


def test_accelerations_in_si_whichever_units_the_channel_uses():
    results = {}
    for units in ("g", "m/s^2"):
        backend, device = make(accel_units=units)
        backend.configure(standard_config())
        backend.write_periodic(sine_period(0.5), 0.0)
        backend.start()
        data, first = backend.read(256, timeout_s=1.0)
        drive = device.ao_samples[first : first + 256]
        np.testing.assert_allclose(data, drive[:, None] * np.asarray(GAINS), atol=1e-12)
        results[units] = args_of(device, "ai_channels.add_ai_accel_chan")[0]
        backend.close()
    assert results["m/s^2"]["units"] is AccelUnits.METERS_PER_SECOND_SQUARED
    assert results["m/s^2"]["max_val"] == pytest.approx(results["g"]["max_val"] * STANDARD_GRAVITY)


def test_iepe_voltage_channel_gets_current_excitation_and_ac_coupling():
    backend, device = make()
    config = standard_config()
    iepe_volt = AIChannelConfig("mic", "Dev1/ai3", "voltage", 2.0, "V/V", excitation_a=0.002)
    backend.configure(AcquisitionConfig(RATE, config.ao, (*config.ai[:3], iepe_volt)))
    sets = {c.name.split(".")[-1]: c.args["value"] for c in device.calls if "['mic']" in c.name}
    assert sets == {
        "ai_excit_src": ExcitationSource.INTERNAL,
        "ai_excit_voltage_or_current": ExcitationVoltageOrCurrent.USE_CURRENT,
        "ai_excit_val": 0.002,
        "ai_coupling": Coupling.AC,
    }
    backend.write_periodic(sine_period(0.5), 0.0)
    backend.start()
    data, first = backend.read(128, timeout_s=1.0)
    np.testing.assert_allclose(data[:, 3], device.ao_samples[first : first + 128] / 2.0)
    backend.close()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"ao": AOChannelConfig("Dev2/ao0")}, "'Dev2/ao0' is not on device 'Dev1'"),
        ({"buffer_s": 0.0}, "buffer_s must be > 0"),
        ({"watchdog_s": -1.0}, "watchdog_s must be > 0"),
        (
            {"ai": (AIChannelConfig("acc", "Dev1/ai1", "acceleration", 100.0, "mV/N"),)},
            "sensitivity_unit must be 'mV/g' for a acceleration channel",
        ),
        (
            {"ai": (AIChannelConfig("f", "Dev1/ai0", "force", 2.0, "mV/N", excitation_a=0.5),)},
            "excitation_a must be in",
        ),
    ],
)
def test_bad_configuration_is_refused_before_touching_the_device(change, message):
    backend, device = make()
    config = standard_config()
    fields = {"sample_rate_hz": RATE, "ao": config.ao, "ai": config.ai} | change
    with pytest.raises(BackendError, match=message):
        backend.configure(AcquisitionConfig(**fields))
    assert device.tasks == []
    backend.close()


def test_cdaq_module_channels_belong_to_the_chassis():
    device = StandinDevice("cDAQ1")
    backend = NiDaqBackend("cDAQ1", device.task_factory, device.watchdog_factory)
    backend.configure(standard_config("cDAQ1Mod1"))
    (trigger,) = args_of(device, "triggers.start_trigger.cfg_dig_edge_start_trig")
    assert trigger["trigger_source"] == "/cDAQ1/ai/StartTrigger"
    backend.close()


@pytest.mark.parametrize(
    "options",
    [
        {"accel_units": "ft/s^2"},
        {"ao_buffer_s": 0.0},
        {"stop_ramp_s": -0.5},
        {"stop_timeout_s": math.inf},
        {"device": ""},
    ],
)
def test_bad_constructor_options_are_refused(options):
    device = StandinDevice()
    options = {"device": "Dev1"} | options
    with pytest.raises(BackendError):
        NiDaqBackend(
            task_factory=device.task_factory, watchdog_factory=device.watchdog_factory, **options
        )


def test_unequal_realised_rates_are_refused_and_tasks_closed():
    backend, device = make(StandinDevice(ao_timebase_hz=80e6))
    with pytest.raises(BackendError, match="realised .* for the inputs but .* for the output"):
        backend.configure(standard_config(sample_rate_hz=3000.0))
    assert device.tasks and all(task.closed for task in device.tasks)


def test_daq_error_during_configure_names_the_step_and_closes_tasks():
    backend, device = make()
    device.fail_next("ai.ai_channels.add_ai_accel_chan", DaqError("no such terminal", -200077))
    with pytest.raises(BackendError, match="creating the input task on Dev1 failed") as info:
        backend.configure(standard_config())
    assert isinstance(info.value.__cause__, DaqError)
    assert all(task.closed for task in device.tasks)
    backend.close()


def test_device_without_on_demand_output_still_configures(caplog):
    backend, device = make()
    device.fail_next("ao-on-demand.write", DaqError("requires sample clock timing", -200077))
    with caplog.at_level(logging.WARNING):
        assert backend.configure(standard_config()) > 0
    assert "could not set Dev1/ao0 to 0 V on demand" in caplog.text
    backend.close()


def test_channel_held_by_another_task_suggests_a_device_reset():
    backend, device = make()
    other = device.task_factory()
    other.ao_channels.add_ao_voltage_chan("Dev1/ao0")
    other.timing.cfg_samp_clk_timing(1000.0, sample_mode=AcquisitionType.CONTINUOUS)
    other.out_stream.output_buf_size = 4
    other.write(np.zeros(4), auto_start=False)  # reserves Dev1/ao0
    with pytest.raises(BackendError, match=r"in use by another task.*reset_device"):
        backend.configure(standard_config())
    backend.close()


def test_configure_again_releases_the_previous_tasks(running):
    backend, device, _ = running
    first = list(device.tasks)
    backend.configure(standard_config())
    assert all(task.closed for task in first)
    backend.write_periodic(sine_period(0.3), 0.0)
    backend.start()
    data, first_index = backend.read(100, timeout_s=1.0)
    assert first_index == 0
    np.testing.assert_allclose(data[:, 3], device.ao_samples[:100])


# ---------------------------------------------------------------- start and the data path


def test_start_order_and_loopback_phase_reference():
    backend, device = make(StandinDevice(ai_source=loopback(GAINS), onboard_fifo=500))
    backend.configure(standard_config())
    wave = sine_period(0.5)
    backend.write_periodic(wave, 0.1)
    backend.start()
    names = [(c.kind, c.name) for c in device.calls]
    order = [
        names.index(("watchdog", "start")),
        names.index(("ao", "write")),
        names.index(("ao", "start")),
        names.index(("ai", "start")),
    ]
    assert order == sorted(order), "watchdog armed, buffer written, output armed, then inputs"
    buffer_len = backend.ao_buffer_samples
    assert buffer_len % wave.size == 0 and buffer_len >= 2 * backend.write_margin_samples
    assert backend.write_margin_samples >= 500, "the margin covers the device FIFO"
    blocks, firsts = [], []
    for n in (100, 1, 2500, 37):
        data, first = backend.read(n, timeout_s=1.0)
        blocks.append(data)
        firsts.append(first)
    assert firsts == [0, 100, 101, 2601]
    data = np.concatenate(blocks)
    drive = device.ao_samples[: data.shape[0]]
    np.testing.assert_allclose(data, drive[:, None] * np.asarray(GAINS), atol=1e-12)


def test_every_read_block_resets_the_watchdog(running):
    backend, device, _ = running
    before = len(device.calls_named("reset_timer"))
    backend.read(10 * backend.ao_buffer_samples, timeout_s=1.0)
    resets = len(device.calls_named("reset_timer")) - before
    reads = len(device.calls_named("read", None))
    assert resets >= 10 and resets >= reads - 1


# ---------------------------------------------------------------- write_periodic


def test_write_before_start_fades_in_from_zero():
    backend, device = make()
    backend.configure(standard_config())
    wave = sine_period(1.0)
    assert backend.write_periodic(wave, 0.0) == 0
    index = backend.write_periodic(wave, 0.1)  # replaces the program: 0.1 s -> 4 periods
    assert index == math.ceil(0.1 * backend.sample_rate_hz / wave.size) * wave.size == 256
    backend.start()
    read_until(backend, 1000)
    out = device.ao_samples
    np.testing.assert_allclose(out[:index], raised_cosine(index) * tiled(wave, 0, 0, index))
    np.testing.assert_allclose(out[index:1000], tiled(wave, 0, index, 1000))
    backend.close()


@pytest.mark.parametrize("fifo", [0, 300])
def test_cross_fade_at_the_same_period_is_an_in_phase_amplitude_ramp(fifo):
    backend, device = make(StandinDevice(ai_source=loopback(GAINS), onboard_fifo=fifo))
    backend.configure(standard_config())
    old = sine_period(0.5)
    backend.write_periodic(old, 0.0)
    backend.start()
    data, first = backend.read(700, timeout_s=1.0)
    new = sine_period(1.5)
    index = backend.write_periodic(new, 0.2)
    fade = math.ceil(0.2 * RATE / new.size) * new.size
    start = index - fade
    assert start % old.size == 0, "the fade starts at a period boundary of the old waveform"
    assert start >= first + 700 + backend.write_margin_samples
    assert start <= 700 + backend.ao_buffer_samples + backend.write_margin_samples + old.size
    read_until(backend, index + 3 * backend.ao_buffer_samples)
    out = device.ao_samples
    np.testing.assert_allclose(out[:start], tiled(old, 0, 0, start), atol=1e-15)
    np.testing.assert_allclose(  # 0.5 -> 1.5 V: old + w (new - old) = (1 + 2 w) old
        out[start:index], (1 + 2 * raised_cosine(fade)) * tiled(old, 0, start, index), atol=1e-12
    )
    end = index + 3 * backend.ao_buffer_samples
    np.testing.assert_allclose(out[index:end], tiled(new, start, index, end), atol=1e-15)
    data, first = backend.read(500, timeout_s=1.0)
    np.testing.assert_allclose(data[:, 3], device.ao_samples[first : first + 500])
    backend.close()


def test_steady_waveform_dividing_the_buffer_is_regenerated_without_writes(running):
    backend, device, _ = running
    new = sine_period(0.8, n=128)
    index = backend.write_periodic(new, 0.1)
    read_until(backend, index + 2 * backend.ao_buffer_samples)
    writes = len(device.calls_named("write"))
    backend.read(10 * backend.ao_buffer_samples, timeout_s=1.0)
    assert len(device.calls_named("write")) == writes, "the device regenerates the buffer alone"
    start = index - math.ceil(0.1 * RATE / 128) * 128
    out = device.ao_samples
    np.testing.assert_allclose(out[index:], tiled(new, start, index, out.size), atol=1e-15)


def test_frequency_step_to_a_period_not_dividing_the_buffer_is_fed_from_reads(running, caplog):
    backend, device, old = running
    new = sine_period(0.7, n=50)
    assert backend.ao_buffer_samples % 50 != 0
    with caplog.at_level(logging.INFO, logger="rig.backends.ni"):
        index = backend.write_periodic(new, 0.1)
    assert "does not divide the output buffer" in caplog.text
    fade = math.ceil(0.1 * RATE / 50) * 50
    start = index - fade
    assert start % old.size == 0
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        backend.read(5 * backend.ao_buffer_samples, timeout_s=1.0)  # one long read
        for _ in range(20):
            backend.read(97, timeout_s=1.0)
    assert not caplog.records
    out = device.ao_samples
    weight = raised_cosine(fade)
    expected_fade = tiled(old, 0, start, index) + weight * (
        tiled(new, start, start, index) - tiled(old, 0, start, index)
    )
    np.testing.assert_allclose(out[start:index], expected_fade, atol=1e-12)
    np.testing.assert_allclose(out[index:], tiled(new, start, index, out.size), atol=1e-15)


def test_new_write_during_a_fade_starts_at_a_period_of_the_waveform_fading_in(running):
    backend, device, old = running
    middle = sine_period(0.7, n=50)
    index_b = backend.write_periodic(middle, 0.5)  # a long fade, written from reads
    start_b = index_b - math.ceil(0.5 * RATE / 50) * 50
    backend.read(331, timeout_s=1.0)
    final = sine_period(0.4, n=40)
    index_c = backend.write_periodic(final, 0.1)
    start_c = index_c - math.ceil(0.1 * RATE / 40) * 40
    assert start_b < start_c < index_b, "the second fade starts while the first runs"
    assert (start_c - start_b) % middle.size == 0
    end = read_until(backend, index_c + 2 * backend.ao_buffer_samples)
    out = device.ao_samples[:end]
    k = np.arange(end)
    a, b, c = old[k % 64], middle[(k - start_b) % 50], final[(k - start_c) % 40]
    w_b = np.clip((k - start_b + 1) / (index_b - start_b), 0, 1)
    w_c = np.clip((k - start_c + 1) / (index_c - start_c), 0, 1)
    first = a + (0.5 - 0.5 * np.cos(np.pi * w_b)) * (b - a)
    expected = first + (0.5 - 0.5 * np.cos(np.pi * w_c)) * (c - first)
    np.testing.assert_allclose(out, expected, atol=1e-12)
    assert np.max(np.abs(np.diff(out))) < 0.1


def test_host_stall_during_a_fade_is_reported_and_writes_land_right_afterwards(running, caplog):
    backend, device, _ = running
    backend.write_periodic(sine_period(0.7, n=50), 1.0)  # a long fade, fed from reads
    device.advance(backend.ao_buffer_samples + 100)  # the host stalls for more than a buffer
    with caplog.at_level(logging.WARNING, logger="rig.backends.ni"):
        backend.read(10, timeout_s=1.0)
    assert "ran dry" in caplog.text
    final = sine_period(0.2, n=40)
    index = backend.write_periodic(final, 0.0)
    read_until(backend, index + 4 * backend.ao_buffer_samples)
    out = device.ao_samples
    np.testing.assert_allclose(out[index:], tiled(final, index, index, out.size), atol=1e-15)


def test_steady_state_survives_a_stalled_host_until_the_watchdog(running):
    backend, device, wave = running
    buffer_len = backend.ao_buffer_samples
    device.advance(int(1.9 * buffer_len))  # two laps, under the 1 s watchdog (buffer 0.5 s)
    out = device.ao_samples
    np.testing.assert_allclose(out, tiled(wave, 0, 0, out.size), atol=1e-15)
    data, first = backend.read(200, timeout_s=1.0)
    assert first == 0, "samples acquired meanwhile wait in the input buffer"
    np.testing.assert_allclose(data[:, 3], out[:200])


def test_watchdog_expiry_forces_zero_and_is_reported(running):
    backend, device, _ = running
    backend.read(100, timeout_s=1.0)
    clock = device.clock
    timeout = round(standard_config().watchdog_s * backend.sample_rate_hz)
    device.advance(timeout + 500)  # the host hangs
    dac = device.dac_samples
    expiry = len(dac) - (device.clock - clock) + timeout
    assert np.any(dac[expiry - 300 : expiry] != 0.0)
    assert np.all(dac[expiry:] == 0.0)
    with pytest.raises(BackendError, match="watchdog on Dev1 expired"):
        backend.read(10, timeout_s=1.0)
    backend.close()
    assert all(task.closed for task in device.tasks)
    assert device.calls_named("clear_expiration") and device.watchdogs[0].closed


def test_device_without_watchdog_warns_that_only_the_amplifier_mute_protects(caplog):
    backend, device = make(StandinDevice(has_watchdog=False))
    with caplog.at_level(logging.WARNING):
        backend.configure(standard_config())
    assert "the amplifier mute is then the only protection for a hard kill" in caplog.text
    assert not backend.watchdog_armed
    backend.write_periodic(sine_period(), 0.0)
    backend.start()
    data, _ = backend.read(500, timeout_s=1.0)
    np.testing.assert_allclose(data[:, 3], device.ao_samples[:500])
    backend.close()


def test_drive_beyond_the_limit_is_refused_and_nothing_written(running):
    backend, device, _ = running
    writes = len(device.calls_named("write"))
    too_big = sine_period(2.5)
    with pytest.raises(BackendError) as info:
        backend.write_periodic(too_big, 0.1)
    assert "peak 2.5 V exceeds the output limit 2 V of Dev1/ao0" in str(info.value)
    assert len(device.calls_named("write")) == writes
    with pytest.raises(BackendError, match="NaN or infinite"):
        backend.write_periodic(np.array([0.0, np.inf]), 0.1)
    with pytest.raises(BackendError, match="non-empty 1-D"):
        backend.write_periodic(np.zeros((2, 64)), 0.1)
    with pytest.raises(BackendError, match="ramp_s must be finite and >= 0"):
        backend.write_periodic(sine_period(), float("nan"))


# ---------------------------------------------------------------- read timeouts and overflow


def test_timeout_at_a_block_boundary_keeps_the_samples_read(running):
    backend, device, _ = running
    backend.read(100, timeout_s=1.0)
    chunk = (backend.ao_buffer_samples - backend.write_margin_samples) // 2
    device.stall_after = device.clock + chunk  # exactly one input block arrives
    with pytest.raises(ReadTimeoutError, match=f"{2 * chunk} samples did not arrive"):
        backend.read(2 * chunk, timeout_s=0.01)
    device.stall_after = None
    data, first = backend.read(2 * chunk, timeout_s=1.0)
    assert first == 100
    np.testing.assert_allclose(data[:, 3], device.ao_samples[100 : 100 + 2 * chunk])


def test_samples_consumed_by_a_timed_out_read_are_skipped_in_first_index(running):
    backend, device, _ = running
    backend.read(100, timeout_s=1.0)
    device.stall_after = device.clock + 10
    with pytest.raises(ReadTimeoutError, match="0 read, 10 consumed by the timed-out read") as info:
        backend.read(50, timeout_s=0.01)
    assert isinstance(info.value, BackendError)
    device.stall_after = None
    data, first = backend.read(50, timeout_s=1.0)
    assert first == 110
    np.testing.assert_allclose(data[:, 3], device.ao_samples[110:160])


def test_input_buffer_overflow_is_explained():
    backend, device = make()
    config = standard_config()
    backend.configure(AcquisitionConfig(RATE, config.ao, config.ai, buffer_s=2.0, watchdog_s=5.0))
    backend.start()
    device.advance(round(3 * backend.sample_rate_hz))  # longer than buffer_s
    with pytest.raises(BackendError, match=r"input buffer overflowed.*buffer_s = 2 s"):
        backend.read(10, timeout_s=1.0)
    backend.close()


# ---------------------------------------------------------------- stop and close


def test_stop_ramps_to_exactly_zero_then_stops_everything():
    backend, device = make(stop_ramp_s=0.25)
    backend.configure(standard_config())
    wave = sine_period(1.0)
    backend.write_periodic(wave, 0.0)
    backend.start()
    backend.read(1000, timeout_s=1.0)
    backend.stop()
    out = device.ao_samples
    ramp = round(0.25 * backend.sample_rate_hz)
    steady = tiled(wave, 0, 0, out.size)
    start = int(np.flatnonzero(np.abs(out - steady) > 1e-12)[0])
    start -= steady[start - 1] == 0.0  # the first faded sample may sit on a zero of the sine
    assert start >= 1000 + backend.write_margin_samples
    np.testing.assert_allclose(
        out[start : start + ramp], (1 - raised_cosine(ramp)) * steady[start : start + ramp]
    )
    assert np.all(out[start + ramp - 1 :] == 0.0) and device.dac_v == 0.0
    stops = [c.kind for c in device.calls if c.name == "stop"]
    assert stops == ["ao", "ai", "watchdog"]
    calls = len(device.calls)
    backend.stop()
    assert len(device.calls) == calls, "a second stop does nothing"
    assert device.on_demand_writes == [0.0], "only the zeroing at configure"
    backend.close()


def test_restart_after_stop_rewrites_the_buffer_from_index_zero():
    backend, device = make()
    backend.configure(standard_config())
    backend.write_periodic(sine_period(0.5), 0.0)
    backend.start()
    backend.read(500, timeout_s=1.0)
    backend.stop()
    wave = sine_period(0.9, n=32)
    backend.write_periodic(wave, 0.0)
    backend.start()
    data, first = backend.read(400, timeout_s=1.0)
    assert first == 0
    np.testing.assert_allclose(device.ao_samples[:400], tiled(wave, 0, 0, 400))
    np.testing.assert_allclose(data[:, 3], device.ao_samples[:400])
    backend.close()


@pytest.mark.parametrize("idle_zero", [True, False])
def test_failed_ramp_falls_back_to_an_abrupt_stop_at_zero(idle_zero, caplog):
    backend, device = make(StandinDevice(idle_zero=idle_zero))
    backend.configure(standard_config())
    backend.write_periodic(sine_period(1.0), 0.0)
    backend.start()
    backend.read(300, timeout_s=1.0)
    assert device.on_demand_writes == [0.0]  # at configure
    device.fail_next("ai.read", DaqError("device disconnected", -200324))
    with caplog.at_level(logging.ERROR):
        backend.stop()  # the output is at 0 V after all, so no exception
    assert "ramp to 0 V failed" in caplog.text
    assert abs(device.ao_samples[-1]) > 0.01, "stopped mid-waveform"
    assert device.dac_v == 0.0
    (stop_call,) = device.calls_named("stop", "ao")
    control = device.calls_named("control", "ao")[-1]
    assert control.args["action"] is TaskMode.TASK_UNRESERVE
    assert device.calls.index(stop_call) < device.calls.index(control)
    if idle_zero:
        assert "idle output behaviour holds Dev1/ao0 at 0 V" in caplog.text
        assert device.on_demand_writes == [0.0]
    else:
        assert "Dev1/ao0 set to 0 V on demand" in caplog.text
        assert device.on_demand_writes == [0.0, 0.0]
    backend.close()


def test_device_without_idle_output_control_still_configures(caplog):
    backend, device = make(StandinDevice(idle_zero=False))
    with caplog.at_level(logging.INFO, logger="rig.backends.ni"):
        backend.configure(standard_config())
    assert "Dev1/ao0 cannot be set to 0 V when idle" in caplog.text
    assert device.calls_named("del ao_channels['Dev1/ao0'].ao_idle_output_behavior", "ao")
    verify = [a for a in args_of(device, "control", "ao") if a["action"] is TaskMode.TASK_VERIFY]
    assert len(verify) == 2
    backend.close()


def test_close_closes_every_task_even_when_stopping_fails(running):
    backend, device, _ = running
    device.fail_next("ai.read", DaqError("device disconnected", -200324))
    device.fail_next("ao.stop", DaqError("device disconnected", -200324))
    device.fail_next("ao-on-demand.write", DaqError("device disconnected", -200324))
    with pytest.raises(BackendError, match="may not be at 0 V"):
        backend.close()
    assert all(task.closed for task in device.tasks)
    assert all(watchdog.closed for watchdog in device.watchdogs)
    backend.close()  # idempotent, even after a failed close
    with pytest.raises(BackendError, match="closed"):
        backend.configure(standard_config())


def test_context_manager_and_garbage_collection_close_the_device():
    backend, device = make()
    with backend:
        backend.configure(standard_config())
        backend.write_periodic(sine_period(), 0.0)
        backend.start()
        backend.read(100, timeout_s=1.0)
    assert all(task.closed for task in device.tasks) and device.dac_v == 0.0

    backend, device = make()
    backend.configure(standard_config())
    backend.write_periodic(sine_period(), 0.0)
    backend.start()
    backend.read(100, timeout_s=1.0)
    ref = weakref.ref(backend)
    del backend
    gc.collect()
    assert ref() is None
    assert all(task.closed for task in device.tasks)
    assert device.ao_samples[-1] == 0.0 and device.dac_v == 0.0


def test_exit_hook_is_registered_while_configured_and_closes(monkeypatch):
    hooks = []
    monkeypatch.setattr(atexit, "register", hooks.append)
    monkeypatch.setattr(atexit, "unregister", hooks.remove)
    backend, device = make()
    backend.configure(standard_config())
    (hook,) = hooks
    backend.start()
    hook()  # what the interpreter runs at exit
    assert all(task.closed for task in device.tasks) and device.dac_v == 0.0
    assert hooks == []
    _close_at_exit(weakref.ref(backend))  # closing twice is harmless


# ---------------------------------------------------------------- real hardware


def _loopback_config(device: str) -> AcquisitionConfig:
    return AcquisitionConfig(
        sample_rate_hz=10240.0,
        ao=AOChannelConfig(f"{device}/ao0", limit_v=1.0),
        ai=(AIChannelConfig("loopback", f"{device}/ai0", "voltage", 1.0, "V/V", iepe=False),),
    )


def _amplitude_phase(data: np.ndarray, first: int, period: int) -> complex:
    """Complex amplitude of the drive harmonic; phase referred to sample index 0."""
    t = first + np.arange(data.size)
    return 2 * np.mean(data * np.exp(-2j * np.pi * t / period))


@pytest.mark.hardware
def test_hardware_loopback_sine_and_stop_at_zero(ni_device):
    """Needs ``ao0`` wired to ``ai0`` of the named device and nothing else on ``ao0``.

    Disconnect the power amplifier. Checks that the read-back sine has the written amplitude,
    that its phase against the sample index is the same in two reads far apart (the index is a
    phase reference; converter delays, e.g. of delta-sigma devices, only add a constant), and
    that ``ao0`` reads 0 V after stop.
    """
    backend = NiDaqBackend(ni_device)
    try:
        backend.configure(_loopback_config(ni_device))
        period = 128
        backend.write_periodic(0.5 * np.sin(2 * np.pi * np.arange(period) / period), 0.05)
        backend.start()
        read_until(backend, 4096, block=1024)
        data, first = backend.read(64 * period, timeout_s=5.0)
        response = _amplitude_phase(data[:, 0], first, period)
        assert abs(abs(response) - 0.5) < 0.01
        backend.read(10 * 1024, timeout_s=5.0)
        data, first = backend.read(64 * period, timeout_s=5.0)
        later = _amplitude_phase(data[:, 0], first, period)
        assert abs(np.angle(later / response)) < 0.01
        backend.stop()
    finally:
        backend.close()
    with nidaqmx.Task() as task:
        task.ai_channels.add_ai_voltage_chan(f"{ni_device}/ai0", min_val=-1.0, max_val=1.0)
        assert abs(float(np.mean(task.read(number_of_samples_per_channel=100)))) < 0.01


@pytest.mark.hardware
def test_hardware_cross_fade_reaches_the_new_level_at_the_returned_index(ni_device):
    """Needs ``ao0`` wired to ``ai0`` of the named device, amplifier disconnected."""
    backend = NiDaqBackend(ni_device)
    try:
        backend.configure(_loopback_config(ni_device))
        period = 128
        unit = np.sin(2 * np.pi * np.arange(period) / period)
        backend.write_periodic(0.2 * unit, 0.05)
        backend.start()
        read_until(backend, 2048, block=1024)
        index = backend.write_periodic(0.6 * unit, 0.2)
        next_index = read_until(backend, index - 1, block=256)
        data, first = backend.read(16 * period, timeout_s=5.0)
        assert first == next_index >= index
        response = _amplitude_phase(data[:, 0], first, period)
        assert abs(abs(response) - 0.6) < 0.01
    finally:
        backend.close()
