"""Driver for the drive-chain power amplifier (protocol: ``docs/amplifier-protocol.md``).

Every setting is followed by a read of the error queue, so a refused setting raises
:class:`~rig.instruments.scpi.InstrumentError` at once, with the instrument's message.
Closing the driver leaves the amplifier as it is: ramp the drive down and :meth:`mute` first.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from rig.instruments.scpi import InstrumentReplyError, ScpiInstrument

__all__ = ["AmplifierStatus", "PowerAmplifier"]

logger = logging.getLogger(__name__)

_STATUS_KEYS = ("OUTP", "MUTE", "OVLD", "GAIN", "CURR", "TEMP", "REM")


@dataclass(frozen=True)
class AmplifierStatus:
    """One ``STAT?`` reply.

    Parameters
    ----------
    enabled : bool
        Output stage on.
    muted : bool
        Signal mute on (the output stage delivers 0 V).
    overload : bool
        Overload latch set (the output stage is off until the latch is cleared and re-enabled).
    current_a : float
        Peak output current [A], >= 0.
    gain_v_per_v : float
        Voltage gain [V/V], >= 0.
    temperature_c : float
        Heat-sink temperature [degC].
    remote : bool
        Remote operation (front panel locked).
    """

    enabled: bool
    muted: bool
    overload: bool
    current_a: float
    gain_v_per_v: float
    temperature_c: float
    remote: bool

    def __post_init__(self) -> None:
        for name in ("enabled", "muted", "overload", "remote"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(
                    f"AmplifierStatus.{name}: expected a bool, got {getattr(self, name)!r}"
                )
        for name in ("current_a", "gain_v_per_v", "temperature_c"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"AmplifierStatus.{name}: must be finite, got {value!r}")
        if self.current_a < 0:
            raise ValueError(f"AmplifierStatus.current_a: must be >= 0 A, got {self.current_a}")
        if self.gain_v_per_v < 0:
            raise ValueError(
                f"AmplifierStatus.gain_v_per_v: must be >= 0 V/V, got {self.gain_v_per_v}"
            )

    @property
    def drive_ok(self) -> bool:
        """Whether a drive signal reaches the shaker (on, not muted, no overload)."""
        return self.enabled and not self.muted and not self.overload


class PowerAmplifier(ScpiInstrument):
    """The power amplifier between the DAQ output and the shaker.

    Parameters are those of :class:`~rig.instruments.scpi.ScpiInstrument`; the defaults match the
    protocol (115200 baud, LF terminations).

    Examples
    --------
    >>> with PowerAmplifier("/dev/ttyUSB0") as amp:  # doctest: +SKIP
    ...     amp.set_gain(5.0)
    ...     amp.enable()
    ...     print(amp.status())
    """

    def __init__(
        self,
        port_or_url: str,
        *,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        write_termination: str = "\n",
        read_termination: str = "\n",
    ) -> None:
        super().__init__(
            port_or_url,
            baudrate=baudrate,
            timeout_s=timeout_s,
            write_termination=write_termination,
            read_termination=read_termination,
        )
        self._gain_range: tuple[float, float] | None = None

    # -- output -----------------------------------------------------------------------------

    def enable(self) -> None:
        """Unmute and switch the output stage on.

        Raises
        ------
        InstrumentError
            If the instrument refuses (``-221`` while the overload latch is set).
        """
        with self._lock:
            self.write_checked("OUTP:MUTE OFF")
            self.write_checked("OUTP ON")
        logger.info("%s: output enabled", self.port)

    def mute(self) -> None:
        """Mute the signal and switch the output stage off (the safe state)."""
        with self._lock:
            self.write_checked("OUTP:MUTE ON")
            self.write_checked("OUTP OFF")
        logger.info("%s: output muted and off", self.port)

    @property
    def is_enabled(self) -> bool:
        """Whether the output stage is on and not muted."""
        with self._lock:
            on = self._query_bool("OUTP?")
            muted = self._query_bool("OUTP:MUTE?")
        return on and not muted

    # -- gain -------------------------------------------------------------------------------

    @property
    def gain_range(self) -> tuple[float, float]:
        """Smallest and largest settable gain [V/V] (asked once, then cached)."""
        with self._lock:
            if self._gain_range is None:
                low = self._query_float("GAIN? MIN")
                high = self._query_float("GAIN? MAX")
                if not low <= high:
                    raise InstrumentReplyError(f"{self.port}: gain range [{low}, {high}] is empty")
                self._gain_range = (low, high)
            return self._gain_range

    def set_gain(self, v_per_v: float) -> None:
        """Set the voltage gain.

        Parameters
        ----------
        v_per_v : float
            Gain [V/V], within :attr:`gain_range`.

        Raises
        ------
        ValueError
            If the value is not a finite number within the instrument's range (nothing is sent).
        InstrumentError
            If the instrument refuses the value.
        """
        if isinstance(v_per_v, bool) or not isinstance(v_per_v, int | float):
            raise ValueError(f"set_gain v_per_v: expected a number, got {v_per_v!r}")
        value = float(v_per_v)
        if not math.isfinite(value):
            raise ValueError(f"set_gain v_per_v: must be finite, got {v_per_v!r}")
        low, high = self.gain_range
        if not low <= value <= high:
            raise ValueError(
                f"set_gain v_per_v: {value:g} V/V is outside the range [{low:g}, {high:g}] V/V "
                f"of the amplifier at {self.port}"
            )
        self.write_checked(f"GAIN {value:.6E}")
        logger.info("%s: gain set to %g V/V", self.port, value)

    @property
    def gain(self) -> float:
        """Voltage gain [V/V]."""
        return self._query_float("GAIN?")

    # -- protection and readings ------------------------------------------------------------

    @property
    def overload(self) -> bool:
        """Whether the overload latch is set."""
        return self._query_bool("STAT:OVLD?")

    def clear_overload(self) -> None:
        """Clear the overload latch; the output stays off until :meth:`enable`."""
        self.write_checked("STAT:OVLD:CLE")
        logger.info("%s: overload latch cleared", self.port)

    def measure_current_a(self) -> float:
        """Peak output current [A]."""
        return self._query_float("MEAS:CURR?")

    def measure_temperature_c(self) -> float:
        """Heat-sink temperature [degC]."""
        return self._query_float("MEAS:TEMP?")

    def set_remote(self, remote: bool = True) -> None:
        """Remote operation (front panel locked) or, with ``remote=False``, local."""
        self.write_checked("SYST:REM" if remote else "SYST:LOC")

    def status(self) -> AmplifierStatus:
        """Every state variable from one ``STAT?`` reply.

        Raises
        ------
        InstrumentReplyError
            If the reply lacks a key or a value does not parse.
        """
        reply = self.query("STAT?")
        values: dict[str, str] = {}
        for item in reply.split(","):
            key, sep, value = item.partition("=")
            if not sep:
                raise InstrumentReplyError(
                    f"STAT? reply from {self.port}: {item!r} is not KEY=value in {reply!r}"
                )
            values[key.strip().upper()] = value.strip()
        missing = [k for k in _STATUS_KEYS if k not in values]
        if missing:
            raise InstrumentReplyError(f"STAT? reply from {self.port} lacks {missing}: {reply!r}")
        try:
            return AmplifierStatus(
                enabled=self._parse_bool("STAT? OUTP", values["OUTP"]),
                muted=self._parse_bool("STAT? MUTE", values["MUTE"]),
                overload=self._parse_bool("STAT? OVLD", values["OVLD"]),
                current_a=self._parse_float("STAT? CURR", values["CURR"]),
                gain_v_per_v=self._parse_float("STAT? GAIN", values["GAIN"]),
                temperature_c=self._parse_float("STAT? TEMP", values["TEMP"]),
                remote=self._parse_bool("STAT? REM", values["REM"]),
            )
        except ValueError as exc:
            raise InstrumentReplyError(f"STAT? reply from {self.port}: {exc}: {reply!r}") from exc

    # -- reply parsing ----------------------------------------------------------------------

    def _query_bool(self, command: str) -> bool:
        return self._parse_bool(command, self.query(command))

    def _query_float(self, command: str) -> float:
        return self._parse_float(command, self.query(command))

    def _parse_bool(self, what: str, text: str) -> bool:
        if text == "1":
            return True
        if text == "0":
            return False
        raise InstrumentReplyError(f"{what} reply from {self.port} is not 1 or 0: {text!r}")

    def _parse_float(self, what: str, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise InstrumentReplyError(
                f"{what} reply from {self.port} is not a finite number: {text!r}"
            )
        return value
