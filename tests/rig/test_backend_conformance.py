"""Run the DAQ backend conformance checks on every backend.

Each backend is one :class:`BackendCase` in :data:`CASES`; the simulated rig joins with a line
such as ``BackendCase("sim", make=lambda: open_backend("sim"))``.
"""

from __future__ import annotations

import weakref

import numpy as np
import pytest

from rig.backends import open_backend
from rig.backends.ni import NiDaqBackend
from sim_backend.sensors import FaultSwitches
from tests.rig.backend_conformance import CHECKS, BackendCase
from tests.rig.nidaqmx_standin import StandinDevice, loopback

_DEVICES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _ni_with_standin() -> NiDaqBackend:
    device = StandinDevice("Dev1", ai_source=loopback([44.4, 98.1, 981.0, 1.0]))
    backend = NiDaqBackend(
        "Dev1", task_factory=device.task_factory, watchdog_factory=device.watchdog_factory
    )
    _DEVICES[backend] = device
    return backend


def _ni_output(backend: NiDaqBackend) -> np.ndarray:
    return _DEVICES[backend].ao_samples


def _ni_stall(backend: NiDaqBackend) -> None:
    device = _DEVICES[backend]
    device.stall_after = device.clock


CASES = [
    BackendCase("ni-standin", make=_ni_with_standin, output=_ni_output, stall=_ni_stall),
    BackendCase(
        "sim",
        make=lambda: open_backend("sim", record_output=True),
        output=lambda b: b.output_samples(),
        stall=lambda b: b.set_faults(FaultSwitches(read_timeout=True)),
    ),
]


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_conformance(case: BackendCase, check) -> None:
    check(case)
