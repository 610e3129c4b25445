"""Conformance checks every DAQ backend must pass (:class:`rig.backends.protocol.DaqBackend`).

A backend is described by a :class:`BackendCase` (how to make one, a configuration for it, and
optional probes); each function in :data:`CHECKS` takes a case and fails with an assertion if
the backend breaks the protocol. ``tests/rig/test_backend_conformance.py`` runs every check on
every case; adding a backend is one line in its list of cases.

The checks cover: the protocol shape; ``configure`` returning the realised positive rate;
``write_periodic`` before and after ``start`` (returned index, the new waveform in force from
it, no jumps); read shapes, dtype and ``first_index`` continuity; ``stop`` ramping to 0 V and
being idempotent; ``close`` being idempotent and final; read timeouts raising
``ReadTimeoutError``; refusal of drives beyond the output limit; rejection of bad
configurations and bad arguments with ``BackendError``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest

from rig.backends.protocol import (
    AcquisitionConfig,
    AIChannelConfig,
    AOChannelConfig,
    BackendError,
    DaqBackend,
    ReadTimeoutError,
)

__all__ = ["CHECKS", "BackendCase", "standard_config", "sine_period"]

PERIOD = 64  # samples per period of the test drive
RAMP_S = 0.05


def standard_config(device: str = "Dev1", sample_rate_hz: float = 2048.0) -> AcquisitionConfig:
    """Impedance-head force and acceleration, one accelerometer and a drive loop-back."""
    return AcquisitionConfig(
        sample_rate_hz=sample_rate_hz,
        ao=AOChannelConfig(physical=f"{device}/ao0", limit_v=2.0),
        ai=(
            AIChannelConfig("force", f"{device}/ai0", "force", 22.5, "mV/N", point=1),
            AIChannelConfig("head_acc", f"{device}/ai1", "acceleration", 100.0, "mV/g", point=1),
            AIChannelConfig("tip_acc", f"{device}/ai2", "acceleration", 10.0, "mV/g", point=5),
            AIChannelConfig("drive", f"{device}/ai3", "voltage", 1.0, "V/V", iepe=False),
        ),
    )


def sine_period(amplitude_v: float = 0.5, n: int = PERIOD) -> np.ndarray:
    """One period of a sine, ``n`` samples, V."""
    return amplitude_v * np.sin(2 * np.pi * np.arange(n) / n)


@dataclass(frozen=True)
class BackendCase:
    """How to exercise one backend in the conformance checks.

    Parameters
    ----------
    name : str
        Test id.
    make : callable
        Returns a fresh, unconfigured backend.
    config : AcquisitionConfig
        A valid configuration for it (four input channels as in :func:`standard_config`).
    output : callable, optional
        ``output(backend) -> ndarray (n,)``: the drive samples generated since ``start``, in
        order. Enables the checks on the drive waveform itself.
    stall : callable, optional
        ``stall(backend)`` makes input samples stop arriving. Without it the backend is taken to
        run in real time, and a read of more samples than can arrive in the timeout is used.
    """

    name: str
    make: Callable[[], DaqBackend]
    config: AcquisitionConfig = field(default_factory=standard_config)
    output: Callable[[DaqBackend], np.ndarray] | None = None
    stall: Callable[[DaqBackend], None] | None = None


CHECKS: list[Callable[[BackendCase], None]] = []


def _check(func: Callable[[BackendCase], None]) -> Callable[[BackendCase], None]:
    CHECKS.append(func)
    return func


class _Opened:
    """A backend made from a case and closed on exit, whatever happens."""

    def __init__(self, case: BackendCase, configure: bool = True) -> None:
        self.case = case
        self.backend = case.make()
        self.rate = case.config.sample_rate_hz
        self.configure = configure

    def __enter__(self) -> DaqBackend:
        if self.configure:
            self.rate = self.backend.configure(self.case.config)
        return self.backend

    def __exit__(self, *exc: object) -> None:
        self.backend.close()


def _read_until(backend: DaqBackend, index: int, block: int = 200) -> int:
    """Read blocks until sample ``index`` has been read; return the next index."""
    next_index = 0
    while next_index <= index:
        data, first = backend.read(block, timeout_s=5.0)
        next_index = first + data.shape[0]
    return next_index


def _is_cyclic_shift(segment: np.ndarray, wave: np.ndarray, atol: float = 1e-9) -> bool:
    return any(np.allclose(segment, np.roll(wave, -s), atol=atol) for s in range(wave.size))


def _max_step(wave: np.ndarray) -> float:
    return float(np.max(np.abs(np.diff(np.concatenate([wave, wave[:1]])))))


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", text)]


@_check
def check_satisfies_protocol(case: BackendCase) -> None:
    backend = case.make()
    try:
        assert isinstance(backend, DaqBackend)
        assert isinstance(backend.name, str) and backend.name
    finally:
        backend.close()


@_check
def check_configure_returns_realised_rate(case: BackendCase) -> None:
    opened = _Opened(case)
    with opened as backend:
        rate = opened.rate
        assert isinstance(rate, float) and math.isfinite(rate) and rate > 0
        assert backend.sample_rate_hz == rate
        assert abs(rate - case.config.sample_rate_hz) <= 0.01 * case.config.sample_rate_hz


@_check
def check_write_before_start(case: BackendCase) -> None:
    opened = _Opened(case)
    with opened as backend:
        wave = sine_period()
        index = backend.write_periodic(wave, RAMP_S)
        ramp = RAMP_S * opened.rate
        assert isinstance(index, int | np.integer)
        assert ramp - 1 <= index < ramp + wave.size + 1, "before start: 0 plus the ramp"
        backend.start()
        _read_until(backend, index + 2 * wave.size)
        if case.output is not None:
            out = case.output(backend)
            assert _is_cyclic_shift(out[index : index + wave.size], wave)
            assert _max_step(out[: index + 2 * wave.size]) <= 1.05 * _max_step(wave)


@_check
def check_write_after_start(case: BackendCase) -> None:
    opened = _Opened(case)
    with opened as backend:
        wave = sine_period()
        backend.write_periodic(wave, 0.0)
        backend.start()
        data, first = backend.read(300, timeout_s=5.0)
        next_index = first + data.shape[0]
        new = sine_period(0.25)
        index = backend.write_periodic(new, RAMP_S)
        assert isinstance(index, int | np.integer)
        assert index >= next_index + RAMP_S * opened.rate - 1, "a fade cannot start in the past"
        _read_until(backend, index + 2 * new.size)
        if case.output is not None:
            out = case.output(backend)
            assert _is_cyclic_shift(out[index : index + new.size], new)
            assert _max_step(out[: index + 2 * new.size]) <= 2.0 * _max_step(wave)


@_check
def check_read_shapes_and_continuity(case: BackendCase) -> None:
    with _Opened(case) as backend:
        backend.write_periodic(sine_period(), RAMP_S)
        backend.start()
        expected_first = 0
        for n in (1, 7, 100, 1000, 33):
            data, first = backend.read(n, timeout_s=5.0)
            assert isinstance(data, np.ndarray)
            assert data.shape == (n, len(case.config.ai))
            assert data.dtype == np.float64
            assert np.all(np.isfinite(data))
            assert first == expected_first
            expected_first += n


@_check
def check_calls_out_of_order_raise(case: BackendCase) -> None:
    with _Opened(case, configure=False) as backend:
        with pytest.raises(BackendError):
            backend.write_periodic(sine_period(), RAMP_S)
        with pytest.raises(BackendError):
            backend.start()
        backend.configure(case.config)
        with pytest.raises(BackendError):
            backend.read(10, timeout_s=1.0)


@_check
def check_stop_ramps_to_zero_and_is_idempotent(case: BackendCase) -> None:
    with _Opened(case) as backend:
        wave = sine_period(1.0)
        backend.write_periodic(wave, RAMP_S)
        backend.start()
        backend.read(500, timeout_s=5.0)
        backend.stop()
        backend.stop()
        with pytest.raises(BackendError):
            backend.read(10, timeout_s=1.0)
        if case.output is not None:
            out = case.output(backend)
            assert out.size > 500
            assert out[-1] == 0.0, "the output must end at exactly 0 V"
            assert _max_step(out) <= 1.05 * _max_step(wave), "stop must ramp, not jump"


@_check
def check_close_is_idempotent_and_final(case: BackendCase) -> None:
    unused = case.make()
    unused.close()
    unused.close()
    backend = case.make()
    backend.configure(case.config)
    backend.write_periodic(sine_period(), RAMP_S)
    backend.start()
    backend.read(100, timeout_s=5.0)
    backend.close()
    backend.close()
    with pytest.raises(BackendError):
        backend.read(10, timeout_s=1.0)
    with pytest.raises(BackendError):
        backend.write_periodic(sine_period(), RAMP_S)


@_check
def check_read_timeout_raises(case: BackendCase) -> None:
    opened = _Opened(case)
    with opened as backend:
        backend.start()
        backend.read(10, timeout_s=5.0)
        if case.stall is not None:
            case.stall(backend)
            n = 64
        else:
            n = int(2 * opened.rate)
        with pytest.raises(ReadTimeoutError):
            backend.read(n, timeout_s=0.05)


@_check
def check_refuses_drive_beyond_limit(case: BackendCase) -> None:
    limit = case.config.ao.limit_v
    with _Opened(case) as backend:
        too_big = sine_period(1.25 * limit)
        peak = float(np.max(np.abs(too_big)))
        for started in (False, True):
            if started:
                backend.write_periodic(sine_period(), 0.0)
                backend.start()
            with pytest.raises(BackendError) as info:
                backend.write_periodic(too_big, RAMP_S)
            numbers = _numbers(str(info.value))
            assert any(math.isclose(x, limit, rel_tol=1e-3) for x in numbers), "name the limit"
            assert any(math.isclose(x, peak, rel_tol=1e-3) for x in numbers), "name the peak"
        backend.read(1000, timeout_s=5.0)
        if case.output is not None:
            assert np.max(np.abs(case.output(backend))) <= limit


@_check
def check_rejects_bad_configuration_and_arguments(case: BackendCase) -> None:
    config = case.config
    wrong_unit = AIChannelConfig(
        "force", config.ai[0].physical, "force", 22.5, "mV/g", point=config.ai[0].point
    )
    bad = AcquisitionConfig(config.sample_rate_hz, config.ao, (wrong_unit, *config.ai[1:]))
    with _Opened(case, configure=False) as backend:
        with pytest.raises(BackendError):
            backend.configure("not a configuration")  # type: ignore[arg-type]
        with pytest.raises(BackendError):
            backend.configure(bad)
        backend.configure(config)
        for wave in (np.zeros((4, 2)), np.zeros(0), np.array([0.0, np.nan, 0.1])):
            with pytest.raises(BackendError):
                backend.write_periodic(wave, RAMP_S)
        with pytest.raises(BackendError):
            backend.write_periodic(sine_period(), -0.1)
