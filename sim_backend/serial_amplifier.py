"""The simulated amplifier's serial front panel, on a pseudo-terminal.

:class:`SimulatedAmplifierPort` opens a pty and answers the commands of
``docs/amplifier-protocol.md`` on it from a daemon thread, against an
:class:`~sim_backend.amplifier.AmplifierModel`. Its :attr:`~SimulatedAmplifierPort.port` is a
real tty path, so the rig's driver opens it exactly like a USB-serial adapter::

    with SimulatedAmplifierPort(model) as sim, PowerAmplifier(sim.port) as amp:
        amp.enable()

:class:`AmplifierProtocol` is the command interpreter alone (one line in, one reply or nothing
out), usable without a pty.
"""

from __future__ import annotations

import errno
import logging
import math
import os
import select
import threading
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Self

from sim_backend.amplifier import AmplifierModel, OverloadLatchedError

__all__ = ["DEFAULT_IDENTITY", "AmplifierProtocol", "SimulatedAmplifierPort"]

logger = logging.getLogger(__name__)

DEFAULT_IDENTITY = "SIMRIG,PA-SIM-100,SN0001,1.0.0"
MAX_LINE_CHARS = 256
ERROR_QUEUE_LENGTH = 16

_OVERFLOW = (-350, "Queue overflow")


class _CommandError(Exception):
    """A command failed; ``code`` and ``message`` become an error-queue entry."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(f'{code},"{message}"')
        self.code = code
        self.message = message


def _missing() -> _CommandError:
    return _CommandError(-109, "Missing parameter")


def _no_parameter(args: str) -> None:
    if args:
        raise _CommandError(-108, "Parameter not allowed")


def _boolean(args: str) -> bool:
    if not args:
        raise _missing()
    word = args.upper()
    if word in ("ON", "1"):
        return True
    if word in ("OFF", "0"):
        return False
    raise _CommandError(-224, f"Illegal parameter value;{args} is not ON|OFF|1|0")


def _nr1(flag: bool) -> str:
    return "1" if flag else "0"


def _nr3(value: float) -> str:
    return f"{value:.6E}"


def _short_form(mnemonic: str) -> str:
    return "".join(ch for ch in mnemonic if not ch.islower())


@dataclass(frozen=True)
class _Command:
    header: str  # mnemonics with the short form in capitals, e.g. "OUTPut:MUTE"
    query: bool
    handler: Callable[[str], str | None]

    def matches(self, nodes: list[str], query: bool) -> bool:
        if query != self.query:
            return False
        if self.header.startswith("*"):
            return len(nodes) == 1 and nodes[0].upper() == self.header
        mnemonics = self.header.split(":")
        if len(nodes) != len(mnemonics):
            return False
        return all(
            node.upper() in (m.upper(), _short_form(m))
            for node, m in zip(nodes, mnemonics, strict=True)
        )


class AmplifierProtocol:
    """Command interpreter of the amplifier protocol (``docs/amplifier-protocol.md``).

    Parameters
    ----------
    model : AmplifierModel
        The amplifier the commands act on.
    identity : str
        The ``*IDN?`` reply: ``maker,model,serial,firmware``.

    Notes
    -----
    Not thread-safe by itself: one reader thread calls :meth:`handle_line`. The model it acts on
    is thread-safe.
    """

    def __init__(self, model: AmplifierModel, identity: str = DEFAULT_IDENTITY) -> None:
        if not isinstance(model, AmplifierModel):
            raise TypeError(f"model: expected AmplifierModel, got {model!r}")
        fields = identity.split(",") if isinstance(identity, str) else []
        if len(fields) != 4 or not all(f.strip() for f in fields) or "\n" in identity:
            raise ValueError(f"identity: must be 'maker,model,serial,firmware', got {identity!r}")
        self.model = model
        self.identity = identity
        self.remote = False
        self._errors: deque[tuple[int, str]] = deque()
        self._commands = (
            _Command("*IDN", True, self._idn),
            _Command("*RST", False, self._rst),
            _Command("*CLS", False, self._cls),
            _Command("*OPC", True, self._opc),
            _Command("SYSTem:ERRor", True, self._next_error),
            _Command("SYSTem:REMote", False, self._set_remote),
            _Command("SYSTem:LOCal", False, self._set_local),
            _Command("OUTPut", False, self._set_output),
            _Command("OUTPut", True, self._get_output),
            _Command("OUTPut:MUTE", False, self._set_mute),
            _Command("OUTPut:MUTE", True, self._get_mute),
            _Command("GAIN", False, self._set_gain),
            _Command("GAIN", True, self._get_gain),
            _Command("STATus:OVLD", True, self._get_overload),
            _Command("STATus:OVLD:CLEar", False, self._clear_overload),
            _Command("MEASure:CURRent", True, self._measure_current),
            _Command("MEASure:TEMPerature", True, self._measure_temperature),
            _Command("STATus", True, self._summary),
        )

    # -- entry points -----------------------------------------------------------------------

    def handle_line(self, line: str) -> str | None:
        """Execute one command line; return the reply (without termination) or ``None``.

        A failing command queues its error and sends nothing, queries included.
        """
        text = line.strip()
        if not text:
            return None
        header, _, args = text.partition(" ")
        args = args.strip()
        query = header.endswith("?")
        nodes = header.removesuffix("?").removeprefix(":").split(":")
        command = next((c for c in self._commands if c.matches(nodes, query)), None)
        try:
            if command is None:
                raise _CommandError(-113, "Undefined header")
            return command.handler(args)
        except _CommandError as exc:
            logger.debug("amplifier protocol: %r -> %d,%s", text, exc.code, exc.message)
            self.push_error(exc.code, exc.message)
        except Exception:
            logger.exception("amplifier protocol: %r failed", text)
            self.push_error(-300, "Device-specific error")
        return None

    def push_error(self, code: int, message: str) -> None:
        """Queue an error; a full queue turns its newest entry into ``-350``."""
        if len(self._errors) >= ERROR_QUEUE_LENGTH:
            self._errors[-1] = _OVERFLOW
        else:
            self._errors.append((code, message))

    # -- common and system commands ---------------------------------------------------------

    def _idn(self, args: str) -> str:
        _no_parameter(args)
        return self.identity

    def _rst(self, args: str) -> None:
        _no_parameter(args)
        self.model.reset()

    def _cls(self, args: str) -> None:
        _no_parameter(args)
        self._errors.clear()

    def _opc(self, args: str) -> str:
        _no_parameter(args)
        return "1"

    def _next_error(self, args: str) -> str:
        _no_parameter(args)
        code, message = self._errors.popleft() if self._errors else (0, "No error")
        return f'{code},"{message}"'

    def _set_remote(self, args: str) -> None:
        _no_parameter(args)
        self.remote = True

    def _set_local(self, args: str) -> None:
        _no_parameter(args)
        self.remote = False

    # -- output, gain, protection, readings -------------------------------------------------

    def _set_output(self, args: str) -> None:
        if not _boolean(args):
            self.model.disable()
            return
        try:
            self.model.enable()
        except OverloadLatchedError as exc:
            raise _CommandError(-221, "Settings conflict;overload latched") from exc

    def _get_output(self, args: str) -> str:
        _no_parameter(args)
        return _nr1(self.model.state().enabled)

    def _set_mute(self, args: str) -> None:
        self.model.set_muted(_boolean(args))

    def _get_mute(self, args: str) -> str:
        _no_parameter(args)
        return _nr1(self.model.state().muted)

    def _set_gain(self, args: str) -> None:
        if not args:
            raise _missing()
        try:
            value = float(args)
        except ValueError as exc:
            raise _CommandError(-104, "Data type error") from exc
        c = self.model.constants
        if not (math.isfinite(value) and c.gain_min_v_per_v <= value <= c.gain_max_v_per_v):
            raise _CommandError(
                -222,
                f"Data out of range;GAIN {args} outside "
                f"[{c.gain_min_v_per_v:g}, {c.gain_max_v_per_v:g}]",
            )
        self.model.set_gain(value)

    def _get_gain(self, args: str) -> str:
        c = self.model.constants
        word = args.upper()
        if not word:
            return _nr3(self.model.state().gain_v_per_v)
        if word in ("MIN", "MINIMUM"):
            return _nr3(c.gain_min_v_per_v)
        if word in ("MAX", "MAXIMUM"):
            return _nr3(c.gain_max_v_per_v)
        raise _CommandError(-224, f"Illegal parameter value;{args} is not MIN|MAX")

    def _get_overload(self, args: str) -> str:
        _no_parameter(args)
        return _nr1(self.model.state().overload)

    def _clear_overload(self, args: str) -> None:
        _no_parameter(args)
        self.model.clear_overload()

    def _measure_current(self, args: str) -> str:
        _no_parameter(args)
        return _nr3(self.model.state().current_a)

    def _measure_temperature(self, args: str) -> str:
        _no_parameter(args)
        return _nr3(self.model.state().temperature_c)

    def _summary(self, args: str) -> str:
        _no_parameter(args)
        s = self.model.state()
        return (
            f"OUTP={_nr1(s.enabled)},MUTE={_nr1(s.muted)},OVLD={_nr1(s.overload)},"
            f"GAIN={_nr3(s.gain_v_per_v)},CURR={_nr3(s.current_a)},"
            f"TEMP={_nr3(s.temperature_c)},REM={_nr1(self.remote)}"
        )


class SimulatedAmplifierPort:
    """A pseudo-terminal whose far end behaves like the amplifier's serial port.

    Parameters
    ----------
    model : AmplifierModel, optional
        The amplifier behind the port; a default one when omitted.
    identity : str
        The ``*IDN?`` reply.

    Attributes
    ----------
    protocol : AmplifierProtocol
        The command interpreter (error queue, remote flag).
    """

    def __init__(
        self, model: AmplifierModel | None = None, *, identity: str = DEFAULT_IDENTITY
    ) -> None:
        self.protocol = AmplifierProtocol(
            model if model is not None else AmplifierModel(), identity
        )
        self._silent = threading.Event()
        self._closed = False
        self._close_lock = threading.Lock()
        self._master, self._slave = os.openpty()
        self._wake_r, self._wake_w = os.pipe()
        try:
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self._port = os.ttyname(self._slave)
        except OSError:
            self._close_fds()
            raise
        self._thread = threading.Thread(
            target=self._serve, name=f"simulated amplifier on {self._port}", daemon=True
        )
        self._thread.start()
        logger.debug("simulated amplifier listening on %s", self._port)

    @property
    def model(self) -> AmplifierModel:
        """The amplifier behind the port."""
        return self.protocol.model

    @property
    def port(self) -> str:
        """Path of the tty to open with ``serial.Serial(port)`` (e.g. ``/dev/pts/5``)."""
        return self._port

    @property
    def silent(self) -> bool:
        """Fault injection: while ``True`` the port reads and drops every command unanswered."""
        return self._silent.is_set()

    @silent.setter
    def silent(self, value: bool) -> None:
        if value:
            self._silent.set()
        else:
            self._silent.clear()

    @property
    def running(self) -> bool:
        """Whether the server thread is alive."""
        return self._thread.is_alive()

    # -- lifetime ---------------------------------------------------------------------------

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the server thread and close the pty (idempotent)."""
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
            os.write(self._wake_w, b"x")
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                logger.error("simulated amplifier thread on %s did not stop", self._port)
            else:
                self._close_fds()
            logger.debug("simulated amplifier on %s closed", self._port)

    def _close_fds(self) -> None:
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- server thread ----------------------------------------------------------------------

    def _serve(self) -> None:
        buffer = b""
        overrun = False
        while True:
            readable, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in readable:
                return
            try:
                data = os.read(self._master, 4096)
            except BlockingIOError:
                continue
            except OSError as exc:
                logger.error("simulated amplifier on %s: read failed: %s", self._port, exc)
                return
            if self._silent.is_set():
                buffer, overrun = b"", False
                continue
            buffer += data
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                if overrun:
                    overrun = False
                    self.protocol.push_error(-363, "Input buffer overrun")
                    continue
                self._execute(raw)
            if len(buffer) > MAX_LINE_CHARS:
                buffer, overrun = b"", True

    def _execute(self, raw: bytes) -> None:
        if len(raw.rstrip(b"\r")) > MAX_LINE_CHARS:
            self.protocol.push_error(-363, "Input buffer overrun")
            return
        try:
            line = raw.decode("ascii")
        except UnicodeDecodeError:
            self.protocol.push_error(-101, "Invalid character")
            return
        reply = self.protocol.handle_line(line)
        if reply is not None:
            self._send((reply + "\n").encode("ascii"))

    def _send(self, data: bytes) -> None:
        while data:
            try:
                written = os.write(self._master, data)
            except BlockingIOError:
                logger.warning(
                    "simulated amplifier on %s: reply dropped (nobody reads)", self._port
                )
                return
            except OSError as exc:
                if exc.errno != errno.EIO:
                    logger.error("simulated amplifier on %s: write failed: %s", self._port, exc)
                return
            data = data[written:]
