"""Errors of the simulated DAQ, recognisable as the rig protocol's errors.

The simulator satisfies the DAQ backend protocol by shape and does not import ``rig``. Its
errors are :class:`SimulatorError` and :class:`SimulatorTimeout`; when the protocol module
``rig.backends.protocol`` has been loaded by the application (it has whenever a run engine uses
the simulator), every error raised is also an instance of the protocol's ``BackendError`` or
``ReadTimeoutError``, so code written against the protocol catches it.
"""

from __future__ import annotations

import sys

__all__ = ["SimulatorError", "SimulatorTimeout", "backend_error", "timeout_error"]

_PROTOCOL_MODULE = "rig.backends.protocol"
_COMBINED: dict[tuple[type, type], type] = {}


class SimulatorError(RuntimeError):
    """The simulated DAQ could not do what was asked; the message says what."""


class SimulatorTimeout(SimulatorError):
    """``read`` did not get the requested samples within its timeout."""


def _make(local: type[SimulatorError], protocol_name: str, message: str) -> SimulatorError:
    protocol = sys.modules.get(_PROTOCOL_MODULE)
    base = getattr(protocol, protocol_name, None) if protocol is not None else None
    if base is None:
        return local(message)
    key = (local, base)
    cls = _COMBINED.get(key)
    if cls is None:
        cls = type(local.__name__, (local, base), {"__module__": __name__})
        _COMBINED[key] = cls
    return cls(message)


def backend_error(message: str) -> SimulatorError:
    """A :class:`SimulatorError` (and the protocol's ``BackendError`` when it is loaded)."""
    return _make(SimulatorError, "BackendError", message)


def timeout_error(message: str) -> SimulatorError:
    """A :class:`SimulatorTimeout` (and the protocol's ``ReadTimeoutError`` when loaded)."""
    return _make(SimulatorTimeout, "ReadTimeoutError", message)
