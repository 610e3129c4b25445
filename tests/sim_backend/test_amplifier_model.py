"""The simulated amplifier's electrical model: transfer, protection, thread safety."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from sim_backend.amplifier import (
    AmplifierConstants,
    AmplifierModel,
    OverloadLatchedError,
)
from sim_backend.serial_amplifier import AmplifierProtocol


def live_model(**constants: float) -> AmplifierModel:
    model = AmplifierModel(AmplifierConstants(**constants))
    model.enable()
    return model


# -- constants ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"bandwidth_hz": 0.0}, "bandwidth_hz"),
        ({"current_limit_a": -1.0}, "current_limit_a"),
        ({"output_resistance_ohm": -0.1}, "output_resistance_ohm"),
        ({"heating_c_per_a2": -1.0}, "heating_c_per_a2"),
        ({"gain_v_per_v": 30.0}, "gain_v_per_v"),
        ({"gain_min_v_per_v": 5.0, "gain_max_v_per_v": 2.0, "gain_v_per_v": 3.0}, "gain_min"),
        ({"ambient_temperature_c": float("nan")}, "ambient_temperature_c"),
    ],
)
def test_invalid_constants_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"AmplifierConstants.{field}"):
        AmplifierConstants(**kwargs)


def test_constants_refuse_non_numbers() -> None:
    with pytest.raises(ValueError, match="AmplifierConstants.bandwidth_hz: expected a number"):
        AmplifierConstants(bandwidth_hz="fast")  # type: ignore[arg-type]


# -- transfer -------------------------------------------------------------------------------


def test_output_matches_the_analytic_first_order_response() -> None:
    gain, fc = 8.0, 1_000.0
    model = live_model(gain_v_per_v=gain, bandwidth_hz=fc)
    f = np.array([0.0, 100.0, 1_000.0, 5_000.0, 50_000.0])
    u = np.array([1.0, 0.5j, 2.0 - 1.0j, 0.1, 1.0])
    out = model.output_voltage(u, f)
    # |H| = G / sqrt(1 + (f/fc)^2), arg H = -atan(f/fc)
    magnitude = gain / np.sqrt(1.0 + (f / fc) ** 2)
    phase = -np.arctan(f / fc)
    np.testing.assert_allclose(out, magnitude * np.exp(1j * phase) * u, rtol=1e-12)
    assert abs(out[2] / u[2]) == pytest.approx(gain / np.sqrt(2.0), rel=1e-12)  # -3 dB
    assert np.angle(out[2] / u[2]) == pytest.approx(-np.pi / 4, rel=1e-12)
    np.testing.assert_allclose(model.frequency_response(f) * u, out, rtol=1e-15)


def test_time_domain_sine_through_the_filter_matches_the_phasor() -> None:
    # integrate dy/dt = wc (G x - y) for a sine and compare the steady state with the phasor
    gain, fc, f = 4.0, 200.0, 150.0
    model = live_model(gain_v_per_v=gain, bandwidth_hz=fc)
    wc, fs = 2 * np.pi * fc, 400_000.0
    t = np.arange(int(0.1 * fs)) / fs
    x = np.cos(2 * np.pi * f * t)
    # exact step for an input linear between samples (first-order hold)
    a = np.exp(-wc / fs)
    b = 1.0 - (1.0 - a) * fs / wc
    y = np.zeros_like(x)
    for k in range(1, len(t)):
        y[k] = a * y[k - 1] + gain * ((1.0 - a) * x[k - 1] + b * (x[k] - x[k - 1]))
    expected = np.real(model.output_voltage(1.0, f) * np.exp(2j * np.pi * f * t))
    last = slice(-int(fs / f) * 5, None)
    np.testing.assert_allclose(y[last], expected[last], atol=1e-3 * gain)


def test_broadcast_over_harmonics() -> None:
    model = live_model(gain_v_per_v=2.0, bandwidth_hz=500.0)
    u = np.ones((3, 4), dtype=complex)
    f = 50.0 * np.arange(1, 5)
    out = model.output_voltage(u, f)
    assert out.shape == (3, 4)
    np.testing.assert_allclose(out[1], 2.0 / (1 + 1j * f / 500.0))


def test_output_is_zero_when_off_muted_or_overloaded() -> None:
    model = AmplifierModel()
    assert np.all(model.output_voltage(1.0 + 0j, 100.0) == 0)  # off at power-on
    model.enable()
    assert abs(model.output_voltage(1.0, 100.0)) > 0
    model.set_muted(True)
    assert model.output_voltage(1.0, 100.0) == 0
    model.set_muted(False)
    model.force_overload()
    assert model.output_voltage(np.ones(3), np.full(3, 100.0)).tolist() == [0, 0, 0]


@pytest.mark.parametrize("frequency", [-1.0, float("nan"), float("inf")])
def test_bad_frequency_is_refused(frequency: float) -> None:
    with pytest.raises(ValueError, match="frequency_hz"):
        AmplifierModel().output_voltage(1.0, frequency)


def test_set_gain_checks_the_range() -> None:
    model = AmplifierModel(AmplifierConstants(gain_max_v_per_v=15.0))
    model.set_gain(15.0)
    assert model.state().gain_v_per_v == 15.0
    with pytest.raises(ValueError, match="gain_v_per_v"):
        model.set_gain(15.01)
    with pytest.raises(ValueError, match="gain_v_per_v"):
        model.set_gain(float("nan"))
    with pytest.raises(ValueError, match="gain_v_per_v: expected a number"):
        model.set_gain("loud")  # type: ignore[arg-type]
    assert model.state().gain_v_per_v == 15.0


# -- protection -----------------------------------------------------------------------------


def test_current_above_the_limit_trips_and_latches() -> None:
    model = live_model(current_limit_a=3.0)
    assert not model.check_current(3.0)  # at the limit: no trip
    assert model.state().live
    assert model.check_current(np.array([0.5, -3.2, 1.0j]))  # largest magnitude counts
    state = model.state()
    assert state.overload and not state.enabled and state.current_a == pytest.approx(3.2)
    assert model.check_current(0.0)  # latched
    with pytest.raises(OverloadLatchedError):
        model.enable()
    model.reset()
    assert model.state().overload  # reset keeps the latch
    model.clear_overload()
    assert not model.state().overload and not model.state().enabled
    model.enable()
    assert model.state().live


def test_temperature_rises_with_current() -> None:
    model = live_model(ambient_temperature_c=20.0, heating_c_per_a2=2.0)
    model.check_current(3.0)
    assert model.state().temperature_c == pytest.approx(20.0 + 2.0 * 9.0 / 2)


def test_protocol_reports_forced_overload() -> None:
    protocol = AmplifierProtocol(live_model())
    protocol.model.force_overload("test")
    assert protocol.handle_line("STAT:OVLD?") == "1"
    assert protocol.handle_line("OUTP ON") is None
    assert protocol.handle_line("SYST:ERR?") == '-221,"Settings conflict;overload latched"'
    assert protocol.handle_line("SYST:ERR?") == '0,"No error"'


def test_protocol_error_queue_overflows_into_350() -> None:
    protocol = AmplifierProtocol(AmplifierModel())
    for _ in range(20):
        protocol.handle_line("NOPE")
    replies = [protocol.handle_line("SYST:ERR?") for _ in range(17)]
    assert replies[:15] == ['-113,"Undefined header"'] * 15
    assert replies[15] == '-350,"Queue overflow"'
    assert replies[16] == '0,"No error"'


# -- threads --------------------------------------------------------------------------------


def test_state_stays_consistent_under_concurrent_access() -> None:
    model = live_model(current_limit_a=1.0)
    stop = threading.Event()
    violations: list[str] = []
    n = 3000

    def front_panel() -> None:
        for _ in range(n):
            try:
                model.enable()
            except OverloadLatchedError:
                model.clear_overload()
            model.set_muted(False)

    def daq() -> None:
        for i in range(n):
            model.check_current(2.0 if i % 2 else 0.5)
            model.output_voltage(np.ones(4), np.arange(4.0))

    def observer() -> None:
        while not stop.is_set():
            s = model.state()
            if s.enabled and s.overload:
                violations.append(f"enabled while overloaded: {s}")

    workers = [threading.Thread(target=f) for f in (front_panel, daq)]
    watch = threading.Thread(target=observer)
    watch.start()
    for t in workers:
        t.start()
    for t in workers:
        t.join(20.0)
    stop.set()
    watch.join(5.0)
    assert not any(t.is_alive() for t in [*workers, watch])
    assert violations == []
    assert model.state().current_a in (0.5, 2.0)
