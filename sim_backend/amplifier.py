"""Electrical model of the drive-chain power amplifier (DAQ output -> amplifier -> shaker).

The amplifier is a voltage source with a first-order low-pass voltage gain and an output
resistance (a Thevenin source): the simulated DAQ computes the open-circuit output voltage with
:meth:`AmplifierModel.output_voltage`, solves the shaker circuit, and reports the peak current
back with :meth:`AmplifierModel.check_current`, which trips the latching overload protection.

Phasor convention: a signal ``x(t) = Re(X exp(+j 2 pi f t))`` is represented by ``X``.

The serial front panel (:mod:`sim_backend.serial_amplifier`) and the DAQ simulation use one
model from different threads; every method holds the model's lock.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

import numpy as np

from analysis.settings import NonNegative, Number, Positive, SettingError, declare, settings

__all__ = ["AmplifierConstants", "AmplifierModel", "AmplifierState", "OverloadLatchedError"]

logger = logging.getLogger(__name__)


class OverloadLatchedError(RuntimeError):
    """The output cannot be switched on while the overload latch is set."""


def _frequencies(frequency_hz: float | np.ndarray) -> np.ndarray:
    f = np.asarray(frequency_hz, dtype=float)
    if not np.all(np.isfinite(f)) or np.any(f < 0):
        raise ValueError(f"frequency_hz: must be finite and >= 0, got {frequency_hz!r}")
    return f


@settings()
class AmplifierConstants:
    """Fixed properties of one amplifier.

    The settable gain range is ``0 <= gain_min_v_per_v < gain_max_v_per_v`` with the power-on
    gain within it. A sinusoidal peak current ``I`` heats the heat sink by
    ``heating_c_per_a2 * I**2 / 2``.
    """

    gain_v_per_v: Number = declare(
        "Low-frequency voltage gain at power-on and after reset [V/V].", 10.0
    )
    bandwidth_hz: Positive = declare(
        "-3 dB corner of the first-order low-pass gain [Hz].", 20_000.0
    )
    current_limit_a: Positive = declare(
        "Peak output current above which the overload protection trips [A].", 5.0
    )
    output_resistance_ohm: NonNegative = declare(
        "Source resistance in series with the output [ohm].", 0.05
    )
    gain_min_v_per_v: Number = declare("Lowest settable gain [V/V].", 0.0)
    gain_max_v_per_v: Number = declare("Highest settable gain [V/V].", 20.0)
    ambient_temperature_c: Number = declare(
        "Heat-sink temperature with no output current [degC].", 25.0
    )
    heating_c_per_a2: NonNegative = declare(
        "Steady heat-sink temperature rise per mean-square output current [degC/A^2].", 1.5
    )

    def __post_init__(self) -> None:
        low, high = self.gain_min_v_per_v, self.gain_max_v_per_v
        if not 0 <= low < high:
            raise SettingError(
                ("gain_min_v_per_v",), f"need 0 <= min < max gain, got [{low}, {high}]"
            )
        if not low <= self.gain_v_per_v <= high:
            raise SettingError(
                ("gain_v_per_v",),
                f"{self.gain_v_per_v} is outside the settable range [{low}, {high}]",
            )


@dataclass(frozen=True)
class AmplifierState:
    """A consistent snapshot of the amplifier's state.

    Parameters
    ----------
    enabled : bool
        Output stage on.
    muted : bool
        Signal mute on.
    overload : bool
        Overload latch set.
    gain_v_per_v : float
        Present low-frequency gain [V/V].
    current_a : float
        Last reported peak output current [A].
    temperature_c : float
        Heat-sink temperature [degC].
    """

    enabled: bool
    muted: bool
    overload: bool
    gain_v_per_v: float
    current_a: float
    temperature_c: float

    @property
    def live(self) -> bool:
        """Whether the input reaches the output (on, not muted, no overload)."""
        return self.enabled and not self.muted and not self.overload


class AmplifierModel:
    """The simulated amplifier's settings, state and transfer behaviour.

    Parameters
    ----------
    constants : AmplifierConstants, optional
        Fixed properties; the defaults when omitted.
    """

    def __init__(self, constants: AmplifierConstants | None = None) -> None:
        if constants is None:
            constants = AmplifierConstants()
        if not isinstance(constants, AmplifierConstants):
            raise TypeError(f"constants: expected AmplifierConstants, got {constants!r}")
        self._constants = constants
        self._lock = threading.Lock()
        self._enabled = False
        self._muted = False
        self._overload = False
        self._gain = constants.gain_v_per_v
        self._current_a = 0.0

    @property
    def constants(self) -> AmplifierConstants:
        """Fixed properties of this amplifier."""
        return self._constants

    def state(self) -> AmplifierState:
        """A consistent snapshot of every state variable."""
        with self._lock:
            return AmplifierState(
                enabled=self._enabled,
                muted=self._muted,
                overload=self._overload,
                gain_v_per_v=self._gain,
                current_a=self._current_a,
                temperature_c=self._temperature_c(),
            )

    def _temperature_c(self) -> float:
        c = self._constants
        return c.ambient_temperature_c + c.heating_c_per_a2 * self._current_a**2 / 2

    # -- controls ---------------------------------------------------------------------------

    def enable(self) -> None:
        """Switch the output stage on.

        Raises
        ------
        OverloadLatchedError
            While the overload latch is set.
        """
        with self._lock:
            if self._overload:
                raise OverloadLatchedError("output cannot be switched on: overload latched")
            self._enabled = True

    def disable(self) -> None:
        """Switch the output stage off."""
        with self._lock:
            self._enabled = False

    def set_muted(self, muted: bool) -> None:
        """Signal mute on (``True``: 0 V out with the stage on) or off."""
        if not isinstance(muted, bool):
            raise TypeError(f"muted: expected a bool, got {muted!r}")
        with self._lock:
            self._muted = muted

    def set_gain(self, gain_v_per_v: float) -> None:
        """Set the low-frequency gain [V/V].

        Raises
        ------
        ValueError
            If the value is not finite or outside the settable range.
        """
        c = self._constants
        try:
            value = float(gain_v_per_v)
        except (TypeError, ValueError):
            raise ValueError(f"gain_v_per_v: expected a number, got {gain_v_per_v!r}") from None
        if not (math.isfinite(value) and c.gain_min_v_per_v <= value <= c.gain_max_v_per_v):
            raise ValueError(
                f"gain_v_per_v: {gain_v_per_v!r} is outside [{c.gain_min_v_per_v:g}, "
                f"{c.gain_max_v_per_v:g}] V/V"
            )
        with self._lock:
            self._gain = value

    def reset(self) -> None:
        """Power-on settings: output off, mute off, default gain; the overload latch stays."""
        with self._lock:
            self._enabled = False
            self._muted = False
            self._gain = self._constants.gain_v_per_v

    # -- protection -------------------------------------------------------------------------

    def check_current(self, current_a_peak: float | np.ndarray) -> bool:
        """Record the output current and trip the overload protection if it is too high.

        Parameters
        ----------
        current_a_peak : float or ndarray, A
            Peak output current; for an array (e.g. per harmonic or per sample) the largest
            magnitude counts.

        Returns
        -------
        bool
            Whether the overload latch is set (now or before).
        """
        peak = float(np.max(np.abs(np.asarray(current_a_peak, dtype=complex)), initial=0.0))
        if not math.isfinite(peak):
            raise ValueError(f"current_a_peak: must be finite, got {current_a_peak!r}")
        with self._lock:
            self._current_a = peak
            if peak > self._constants.current_limit_a and not self._overload:
                self._trip(
                    f"peak current {peak:.3g} A > limit {self._constants.current_limit_a:g} A"
                )
            return self._overload

    def force_overload(self, reason: str = "forced") -> None:
        """Fault injection: trip the overload protection as if the current were too high."""
        with self._lock:
            self._trip(reason)

    def clear_overload(self) -> None:
        """Clear the overload latch; the output stays off until :meth:`enable`."""
        with self._lock:
            if self._overload:
                logger.info("amplifier overload latch cleared")
            self._overload = False

    def _trip(self, reason: str) -> None:
        self._overload = True
        self._enabled = False
        logger.warning("amplifier overload tripped (%s): output off", reason)

    # -- transfer ---------------------------------------------------------------------------

    def frequency_response(self, frequency_hz: float | np.ndarray) -> np.ndarray:
        """Small-signal voltage gain at the present gain setting, ignoring the output state.

        ``G / (1 + j f / f_c)`` with ``G`` the gain and ``f_c`` the bandwidth.

        Parameters
        ----------
        frequency_hz : float or ndarray, Hz
            Frequencies, >= 0.

        Returns
        -------
        ndarray, complex, shape of ``frequency_hz``, V/V
        """
        f = _frequencies(frequency_hz)
        with self._lock:
            gain = self._gain
        return gain / (1.0 + 1j * f / self._constants.bandwidth_hz)

    def output_voltage(
        self, input_v_phasor: complex | np.ndarray, frequency_hz: float | np.ndarray
    ) -> np.ndarray:
        """Open-circuit output voltage for an input voltage.

        Parameters
        ----------
        input_v_phasor : complex or ndarray, V
            Input voltage phasors (e.g. one per harmonic).
        frequency_hz : float or ndarray, Hz
            Frequency of each phasor; broadcast against ``input_v_phasor``.

        Returns
        -------
        ndarray, complex, broadcast shape, V
            ``frequency_response(f) * input``; zero while the output is off, muted or
            overloaded. The load sees this through ``output_resistance_ohm``.
        """
        u = np.asarray(input_v_phasor, dtype=complex)
        f = _frequencies(frequency_hz)
        with self._lock:
            gain = self._gain if self._enabled and not self._muted and not self._overload else 0.0
        return gain / (1.0 + 1j * f / self._constants.bandwidth_hz) * u
