"""A small SCPI-style instrument layer on pyserial.

:class:`ScpiInstrument` opens its connection with :func:`serial.serial_for_url`, so a real port
(``/dev/ttyUSB0``, ``COM3``), a pseudo-terminal, ``socket://host:port`` and ``loop://`` all work.
Each exchange (one command, or one command and its reply) holds a lock, so several threads may
share one instrument.

Errors
------
:class:`InstrumentError` is the base of every error raised here. Errors the instrument reports in
its ``SYST:ERR?`` queue are raised by :meth:`ScpiInstrument.check_errors` as
:class:`InstrumentError` with the queue entries in ``errors``; a missing reply raises
:class:`InstrumentTimeout`; a reply that cannot be parsed raises :class:`InstrumentReplyError`.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import serial

__all__ = [
    "InstrumentError",
    "InstrumentIdentity",
    "InstrumentReplyError",
    "InstrumentTimeout",
    "ScpiError",
    "ScpiInstrument",
]

logger = logging.getLogger(__name__)

_ERROR_REPLY = re.compile(r'^\s*([+-]?\d+)\s*,\s*"(.*)"\s*$')
_MAX_ERROR_READS = 100
_MAX_STALE_BYTES = 65536


@dataclass(frozen=True)
class ScpiError:
    """One entry of an instrument's error queue.

    Parameters
    ----------
    code : int
        SCPI error code; negative codes are the standard ones, ``0`` means no error.
    message : str
        The instrument's text, possibly with a detail after a semicolon.
    """

    code: int
    message: str

    def __post_init__(self) -> None:
        if isinstance(self.code, bool) or not isinstance(self.code, int):
            raise TypeError(f"ScpiError.code: expected an int, got {self.code!r}")
        if not isinstance(self.message, str):
            raise TypeError(f"ScpiError.message: expected a str, got {self.message!r}")

    def __str__(self) -> str:
        return f'{self.code},"{self.message}"'


@dataclass(frozen=True)
class InstrumentIdentity:
    """The four fields of an ``*IDN?`` reply.

    Parameters
    ----------
    manufacturer, model, serial, firmware : str
        Fields in reply order; none may be empty.
    """

    manufacturer: str
    model: str
    serial: str
    firmware: str

    def __post_init__(self) -> None:
        for name in ("manufacturer", "model", "serial", "firmware"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip():
                raise ValueError(
                    f"InstrumentIdentity.{name}: must be a non-empty str, got {value!r}"
                )


class InstrumentError(RuntimeError):
    """An instrument failed or reported errors.

    Parameters
    ----------
    message : str
        What happened and on which port.
    errors : sequence of ScpiError, optional
        The entries of the instrument's error queue, when that is the cause.
    """

    def __init__(self, message: str, errors: tuple[ScpiError, ...] = ()) -> None:
        super().__init__(message)
        self.errors: tuple[ScpiError, ...] = tuple(errors)


class InstrumentTimeout(InstrumentError, TimeoutError):
    """No complete reply (or the write did not finish) within the timeout."""


class InstrumentReplyError(InstrumentError):
    """The instrument answered something that does not parse as the expected reply."""


def _check_termination(name: str, value: object) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"ScpiInstrument.{name}: must be a non-empty str, got {value!r}")
    if not value.isascii():
        raise ValueError(f"ScpiInstrument.{name}: must be ASCII, got {value!r}")
    return value


class ScpiInstrument:
    """A line-oriented SCPI instrument on a serial connection.

    Parameters
    ----------
    port_or_url : str
        Device path (``/dev/ttyUSB0``, ``/dev/pts/5``, ``COM3``) or pyserial URL
        (``socket://host:port``, ``loop://``, ``spy://...``).
    baudrate : int
        Line speed [baud] (ignored by URL handlers without a line).
    timeout_s : float
        Longest wait for a complete reply, and for a write to finish [s].
    write_termination : str
        Appended to every command.
    read_termination : str
        Ends every reply; removed, together with surrounding white space, from the returned text.

    Raises
    ------
    ValueError
        If a setting is invalid.
    InstrumentError
        If the port cannot be opened.
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
        cls = type(self).__name__
        if not isinstance(port_or_url, str) or not port_or_url:
            raise ValueError(f"{cls}.port_or_url: must be a non-empty str, got {port_or_url!r}")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise ValueError(f"{cls}.baudrate: must be a positive int, got {baudrate!r}")
        if isinstance(timeout_s, bool) or not isinstance(timeout_s, int | float):
            raise ValueError(f"{cls}.timeout_s: must be a number of seconds, got {timeout_s!r}")
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"{cls}.timeout_s: must be finite and > 0 s, got {timeout_s!r}")
        self._write_term = _check_termination("write_termination", write_termination)
        self._read_term = _check_termination("read_termination", read_termination)
        self._port = port_or_url
        self._timeout_s = float(timeout_s)
        self._lock = threading.RLock()
        try:
            self._serial = serial.serial_for_url(
                port_or_url,
                baudrate=baudrate,
                timeout=self._timeout_s,
                write_timeout=self._timeout_s,
            )
        except (serial.SerialException, ValueError, OSError) as exc:
            raise InstrumentError(f"cannot open instrument port {port_or_url!r}: {exc}") from exc
        logger.debug("opened %s at %d baud", port_or_url, baudrate)

    # -- connection -------------------------------------------------------------------------

    @property
    def port(self) -> str:
        """The device path or URL this instrument was opened with."""
        return self._port

    @property
    def timeout_s(self) -> float:
        """Reply timeout [s]."""
        return self._timeout_s

    @property
    def is_open(self) -> bool:
        """Whether the connection is open."""
        return bool(self._serial.is_open)

    def close(self) -> None:
        """Close the connection (idempotent)."""
        with self._lock:
            if self._serial.is_open:
                self._serial.close()
                logger.debug("closed %s", self._port)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return f"{type(self).__name__}({self._port!r}, {state})"

    # -- exchanges --------------------------------------------------------------------------

    def write(self, command: str) -> None:
        """Send one command (the write termination is appended).

        Raises
        ------
        ValueError
            If ``command`` is empty, not ASCII, or contains a termination.
        InstrumentTimeout
            If the write did not finish within the timeout.
        InstrumentError
            If the port is closed or failed.
        """
        data = self._encode(command)
        with self._lock:
            self._send(command, data)

    def query(self, command: str) -> str:
        """Send one command and return its one-line reply.

        Input that arrived before the command (a late reply to an earlier, timed-out query) is
        discarded first, so replies cannot shift by one.

        Returns
        -------
        str
            The reply without its read termination and surrounding white space.

        Raises
        ------
        InstrumentTimeout
            If no complete reply arrived within the timeout; the message names the command,
            the port and what (if anything) was received.
        """
        data = self._encode(command)
        term = self._read_term.encode("ascii")
        with self._lock:
            self._discard_stale_input()
            self._send(command, data)
            try:
                raw = self._serial.read_until(term)
            except serial.SerialException as exc:
                raise InstrumentError(
                    f"reading the reply to {command!r} from {self._port} failed: {exc}"
                ) from exc
            if not raw.endswith(term):
                raise InstrumentTimeout(
                    f"no reply to {command!r} from {self._port} within {self._timeout_s:g} s"
                    + (f" (received only {raw!r})" if raw else "")
                )
        reply = raw[: -len(term)].decode("ascii", errors="replace").strip()
        logger.debug("%s %r -> %r", self._port, command, reply)
        return reply

    def _encode(self, command: str) -> bytes:
        if not isinstance(command, str) or not command.strip():
            raise ValueError(f"command: must be a non-empty str, got {command!r}")
        if not command.isascii():
            raise ValueError(f"command: must be ASCII, got {command!r}")
        for term in {self._write_term, self._read_term, "\n", "\r"}:
            if term in command:
                raise ValueError(f"command: must not contain the termination {term!r}: {command!r}")
        return (command + self._write_term).encode("ascii")

    def _send(self, command: str, data: bytes) -> None:
        if not self._serial.is_open:
            raise InstrumentError(f"cannot send {command!r}: port {self._port} is closed")
        try:
            self._serial.write(data)
            self._serial.flush()
        except serial.SerialTimeoutException as exc:
            raise InstrumentTimeout(
                f"writing {command!r} to {self._port} did not finish within {self._timeout_s:g} s"
            ) from exc
        except serial.SerialException as exc:
            raise InstrumentError(f"writing {command!r} to {self._port} failed: {exc}") from exc
        logger.debug("%s <- %r", self._port, command)

    def _discard_stale_input(self) -> None:
        stale = b""
        try:
            while len(stale) < _MAX_STALE_BYTES:
                waiting = self._serial.in_waiting
                if not waiting:
                    break
                chunk = self._serial.read(waiting)
                if not chunk:
                    break
                stale += chunk
        except serial.SerialException as exc:
            raise InstrumentError(f"reading from {self._port} failed: {exc}") from exc
        if stale:
            logger.warning("%s: discarded %d unread bytes: %r", self._port, len(stale), stale[:80])

    # -- common commands --------------------------------------------------------------------

    def identify(self) -> InstrumentIdentity:
        """Ask ``*IDN?`` and parse the reply.

        Raises
        ------
        InstrumentReplyError
            If the reply is not four non-empty comma-separated fields.
        """
        reply = self.query("*IDN?")
        fields = [f.strip() for f in reply.split(",")]
        if len(fields) != 4 or not all(fields):
            raise InstrumentReplyError(
                f"*IDN? reply from {self._port} is not 'manufacturer,model,serial,firmware': "
                f"{reply!r}"
            )
        return InstrumentIdentity(*fields)

    def write_checked(self, command: str) -> None:
        """Send one command, then :meth:`check_errors`, with no other exchange in between.

        Raises
        ------
        InstrumentError
            If the instrument queued errors (for this command or earlier ones).
        """
        with self._lock:
            self.write(command)
            self.check_errors(command)

    def reset(self) -> None:
        """Send ``*RST`` (the instrument's default settings) and check the error queue."""
        self.write_checked("*RST")

    def errors(self) -> list[ScpiError]:
        """Drain the error queue: ask ``SYST:ERR?`` until it answers ``0,"No error"``.

        Returns
        -------
        list of ScpiError
            The queued errors, oldest first (empty when there were none).

        Raises
        ------
        InstrumentReplyError
            If a reply is not ``<code>,"<message>"``, or the queue does not drain.
        """
        found: list[ScpiError] = []
        with self._lock:
            for _ in range(_MAX_ERROR_READS):
                reply = self.query("SYST:ERR?")
                match = _ERROR_REPLY.match(reply)
                if match is None:
                    raise InstrumentReplyError(
                        f'SYST:ERR? reply from {self._port} is not <code>,"<message>": {reply!r}'
                    )
                entry = ScpiError(int(match.group(1)), match.group(2))
                if entry.code == 0:
                    return found
                found.append(entry)
        raise InstrumentReplyError(
            f"the error queue of {self._port} did not drain after {_MAX_ERROR_READS} reads"
        )

    def check_errors(self, context: str | None = None) -> None:
        """Raise if the instrument has queued errors.

        Parameters
        ----------
        context : str, optional
            What was sent just before (named in the message).

        Raises
        ------
        InstrumentError
            With the instrument's messages in the text and the entries in ``errors``.
        """
        with self._lock:
            found = self.errors()
        if found:
            after = f" after {context!r}" if context else ""
            listing = "; ".join(str(e) for e in found)
            raise InstrumentError(f"instrument at {self._port} reported{after}: {listing}", found)
