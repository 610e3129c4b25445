"""The newest samples of a run, for the time-trace plots.

:class:`TappedBackend` wraps a DAQ backend and hands a copy of every block the engine reads to
a :class:`SampleTap`, which keeps the newest half second (thread-safe); the GUI takes a
:class:`TimeTraces` snapshot on its redraw timer. The engine cannot tell the difference.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SampleTap", "TappedBackend", "TimeTraces"]


@dataclass(frozen=True)
class TimeTraces:
    """The latest samples of every channel.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        Time of each sample relative to the newest [s] (<= 0).
    data : ndarray, shape (n, C)
        Samples in channel units.
    names, units : tuple of str, length C
    sample_rate_hz : float
    """

    time_s: np.ndarray
    data: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    sample_rate_hz: float


class SampleTap:
    """Keeps the newest ``seconds`` of samples the engine read (thread-safe)."""

    def __init__(self, seconds: float = 0.5) -> None:
        self.seconds = float(seconds)
        self._lock = threading.Lock()
        self._buf: np.ndarray | None = None
        self._fs = math.nan
        self._names: tuple[str, ...] = ()
        self._units: tuple[str, ...] = ()

    def configured(self, sample_rate_hz: float, names, units) -> None:
        with self._lock:
            self._fs = float(sample_rate_hz)
            self._names, self._units = tuple(names), tuple(units)
            self._buf = np.zeros((0, len(self._names)))

    def add(self, data: np.ndarray) -> None:
        with self._lock:
            if self._buf is None or not math.isfinite(self._fs):
                return
            keep = max(1, int(self.seconds * self._fs))
            data = np.asarray(data, dtype=float)
            self._buf = np.concatenate([self._buf, data[-keep:]])[-keep:]

    def snapshot(self) -> TimeTraces | None:
        """A copy of the newest samples (None before the first read)."""
        with self._lock:
            if self._buf is None or self._buf.shape[0] == 0:
                return None
            data = self._buf.copy()
            fs = self._fs
        t = (np.arange(data.shape[0]) - (data.shape[0] - 1)) / fs
        return TimeTraces(t, data, self._names, self._units, fs)


_UNITS = {"force": "N", "acceleration": "m/s²", "voltage": "V"}


class TappedBackend:
    """A DAQ backend that hands a copy of every block read to a :class:`SampleTap`.

    Everything else goes to the wrapped backend unchanged; the engine cannot tell the
    difference.
    """

    def __init__(self, backend, tap: SampleTap) -> None:
        self._backend = backend
        self._tap = tap
        self.name = getattr(backend, "name", "daq")

    @property
    def sample_rate_hz(self) -> float:
        return self._backend.sample_rate_hz

    def configure(self, config) -> float:
        fs = self._backend.configure(config)
        self._tap.configured(
            fs, [c.name for c in config.ai], [_UNITS.get(c.quantity, "") for c in config.ai]
        )
        return fs

    def write_periodic(self, period_v: np.ndarray, ramp_s: float) -> int:
        return self._backend.write_periodic(period_v, ramp_s)

    def start(self) -> None:
        self._backend.start()

    def read(self, n_samples: int, timeout_s: float):
        data, first = self._backend.read(n_samples, timeout_s)
        self._tap.add(data)
        return data, first

    def stop(self) -> None:
        self._backend.stop()

    def close(self) -> None:
        self._backend.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._backend, name)
