"""The DAQ backend protocol: the one seam between the run engine and hardware.

Every backend (the NI driver in :mod:`rig.backends.ni`, the simulated rig in
:mod:`sim_backend`) satisfies :class:`DaqBackend` *by shape*; the simulator does not import
this module. A conformance test runs the same checks against each backend.

Time base
---------
Analogue output and analogue inputs share one sample clock and one start trigger, so a
sample index is a phase reference: input sample ``k`` (counted from :meth:`DaqBackend.start`)
was taken at the same instant the output sample ``k`` was produced.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = [
    "AIChannelConfig",
    "AOChannelConfig",
    "AcquisitionConfig",
    "BackendError",
    "DaqBackend",
    "ReadTimeoutError",
    "reference_values",
]

QUANTITIES = ("force", "acceleration", "voltage")


class BackendError(RuntimeError):
    """A backend could not do what was asked; the message says what and where."""


class ReadTimeoutError(BackendError):
    """``read`` did not get the requested samples within its timeout."""


@dataclass(frozen=True)
class AOChannelConfig:
    """The drive output channel (to the power amplifier input).

    Parameters
    ----------
    physical : str
        Device channel, e.g. ``"Dev1/ao0"``.
    limit_v : float
        Hard output-voltage limit [V]; the backend refuses samples beyond it.
    """

    physical: str = "Dev1/ao0"
    limit_v: float = 2.0

    def __post_init__(self) -> None:
        if not (0 < self.limit_v <= 10.0):
            raise ValueError(f"AOChannelConfig.limit_v: must be in (0, 10] V, got {self.limit_v}")


@dataclass(frozen=True)
class AIChannelConfig:
    """One analogue input channel.

    Parameters
    ----------
    name : str
        Unique channel name (also the name in the measurement file's channel table).
    physical : str
        Device channel, e.g. ``"Dev1/ai0"``.
    quantity : {"force", "acceleration", "voltage"}
        What the channel measures; samples are returned in N, m/s^2 or V.
    sensitivity : float
        Sensor sensitivity in ``sensitivity_unit`` (mV/N for force, mV/g for acceleration,
        1 for voltage).
    sensitivity_unit : str
        ``"mV/N"``, ``"mV/g"`` or ``"V/V"``.
    range_v : float
        Input range of the ADC [V] (symmetric); a sensor voltage beyond it clips.
    iepe : bool
        Whether the channel powers an IEPE sensor (constant-current excitation, AC coupling).
    excitation_a : float
        IEPE excitation current [A].
    point, direction : int, str
        Where the sensor sits on the structure (measurement point and axis).
    """

    name: str
    physical: str
    quantity: str
    sensitivity: float
    sensitivity_unit: str
    range_v: float = 5.0
    iepe: bool = True
    excitation_a: float = 0.004
    point: int = 0
    direction: str = "y"

    def __post_init__(self) -> None:
        if self.quantity not in QUANTITIES:
            raise ValueError(
                f"AIChannelConfig {self.name!r}.quantity: expected one of {QUANTITIES}, "
                f"got {self.quantity!r}"
            )
        if not self.sensitivity > 0:
            raise ValueError(
                f"AIChannelConfig {self.name!r}.sensitivity: must be > 0, got {self.sensitivity}"
            )
        if not self.range_v > 0:
            raise ValueError(f"AIChannelConfig {self.name!r}.range_v: must be > 0")


@dataclass(frozen=True)
class AcquisitionConfig:
    """Clock, buffers and channels of one acquisition session.

    Parameters
    ----------
    sample_rate_hz : float
        Requested sample rate [Hz]; the backend reports the realised one.
    ao : AOChannelConfig
        The drive output.
    ai : tuple of AIChannelConfig
        Inputs, in acquisition order (this order is the column order of :meth:`DaqBackend.read`).
    buffer_s : float
        Input buffer length [s]; reading slower than real time for longer overflows it.
    """

    sample_rate_hz: float
    ao: AOChannelConfig
    ai: tuple[AIChannelConfig, ...]
    buffer_s: float = 10.0
    watchdog_s: float = 1.0
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not self.sample_rate_hz > 0:
            raise ValueError(
                f"AcquisitionConfig.sample_rate_hz: must be > 0, got {self.sample_rate_hz}"
            )
        if not self.ai:
            raise ValueError("AcquisitionConfig.ai: at least one input channel is needed")
        names = [c.name for c in self.ai]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"AcquisitionConfig.ai: duplicate channel names {sorted(dup)}")


@runtime_checkable
class DaqBackend(Protocol):
    """What the run engine needs from a DAQ device.

    Output is a regenerated periodic waveform. :meth:`write_periodic` replaces it at a period
    boundary with a raised-cosine cross-fade, so level changes are ramped on the device side and
    the engine never has to stream samples in real time.
    """

    name: str

    @property
    def sample_rate_hz(self) -> float:
        """Realised sample rate [Hz] (valid after :meth:`configure`)."""
        ...

    def configure(self, config: AcquisitionConfig) -> float:
        """Create the output and input channels; return the realised sample rate [Hz]."""
        ...

    def write_periodic(self, period_v: np.ndarray, ramp_s: float) -> int:
        """Replace the regenerated output waveform.

        Parameters
        ----------
        period_v : ndarray, shape (n,), V
            One or more whole periods of the new drive; regenerated until the next call.
        ramp_s : float
            Length of the raised-cosine cross-fade from the current waveform [s].

        Returns
        -------
        int
            Sample index (from :meth:`start`) at which the new waveform is fully in force;
            before :meth:`start`, 0 plus the ramp.
        """
        ...

    def start(self) -> None:
        """Start output and input on one trigger."""
        ...

    def read(self, n_samples: int, timeout_s: float) -> tuple[np.ndarray, int]:
        """Read the next input samples.

        Returns
        -------
        data : ndarray, shape (n_samples, n_channels)
            Samples in physical units (N, m/s^2, V) in channel order.
        first_index : int
            Sample index of ``data[0]`` counted from :meth:`start`.

        Raises
        ------
        ReadTimeoutError
            If the samples did not arrive within ``timeout_s``.
        """
        ...

    def stop(self) -> None:
        """Ramp the output to 0 V and stop both tasks (idempotent)."""
        ...

    def close(self) -> None:
        """Stop (output at 0 V) and release the device (idempotent)."""
        ...


def reference_values(backend: object) -> dict | None:
    """What the backend knows of the structure under test, or None.

    A simulated rig knows the "truth" it simulates (its parameter values, units and modal
    damping: ``parameters``, ``units``, ``modal_damping``, ``source``) and says so through an
    optional ``reference_values()`` method; hardware knows nothing of the kind and has none.
    The answer is for judging an analysis (``truth.json`` beside the results), never for
    feeding one: the measurement file does not carry it.
    """
    method = getattr(backend, "reference_values", None)
    return method() if callable(method) else None
