"""DAQ backends and the registry that opens them by name.

``open_backend("ni", device="Dev1")`` opens the NI-DAQmx driver (:mod:`rig.backends.ni`),
``open_backend("sim", **options)`` the simulated rig (``sim_backend.daq.SimulatedDaq``). Backend
modules are imported only when opened, so importing this package needs neither nidaqmx nor the
simulator. The protocol types are re-exported here.
"""

from __future__ import annotations

import importlib
from typing import Any

from rig.backends.protocol import (
    AcquisitionConfig,
    AIChannelConfig,
    AOChannelConfig,
    BackendError,
    DaqBackend,
    ReadTimeoutError,
    reference_values,
)

__all__ = [
    "AIChannelConfig",
    "AOChannelConfig",
    "AcquisitionConfig",
    "BackendError",
    "DaqBackend",
    "ReadTimeoutError",
    "available_backends",
    "open_backend",
    "reference_values",
]

# name -> (module, class); the module is imported by open_backend only
_BACKENDS: dict[str, tuple[str, str]] = {
    "ni": ("rig.backends.ni", "NiDaqBackend"),
    "sim": ("sim_backend.daq", "SimulatedDaq"),
}


def available_backends() -> tuple[str, ...]:
    """Names :func:`open_backend` accepts."""
    return tuple(_BACKENDS)


def open_backend(name: str, **options: Any) -> DaqBackend:
    """Open a DAQ backend by name.

    Parameters
    ----------
    name : {"ni", "sim"}
        ``"ni"``: :class:`rig.backends.ni.NiDaqBackend`; ``"sim"``:
        ``sim_backend.daq.SimulatedDaq``.
    **options
        Passed to the backend's constructor (for ``"ni"``: ``device``, ``ao_buffer_s``, ...).

    Returns
    -------
    DaqBackend
        The opened, not yet configured backend.

    Raises
    ------
    BackendError
        If the name is unknown (the message lists the known ones), the backend's module cannot
        be imported, or the backend cannot be opened (e.g. the NI-DAQmx driver is missing).
    """
    try:
        module_name, class_name = _BACKENDS[name]
    except (KeyError, TypeError):
        known = ", ".join(repr(n) for n in _BACKENDS)
        raise BackendError(f"unknown DAQ backend {name!r}; known backends: {known}") from None
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise BackendError(
            f"DAQ backend {name!r} is not available: importing {module_name} failed ({exc})"
        ) from exc
    factory = getattr(module, class_name, None)
    if factory is None:
        raise BackendError(
            f"DAQ backend {name!r} is not available: {module_name} has no {class_name}"
        )
    backend = factory(**options)
    if not isinstance(backend, DaqBackend):
        raise BackendError(
            f"DAQ backend {name!r}: {module_name}.{class_name} does not satisfy the "
            "DaqBackend protocol"
        )
    return backend
