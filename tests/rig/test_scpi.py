"""Protocol tests of the SCPI layer against a scripted TCP peer (``socket://``).

:func:`expected_protocol` runs the instrument against a peer that expects an exact byte stream:
the test fails unless every scripted exchange happens, in order, with the exact terminations,
and nothing else is sent.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import pytest

from rig.instruments.scpi import (
    InstrumentError,
    InstrumentIdentity,
    InstrumentReplyError,
    InstrumentTimeout,
    ScpiError,
    ScpiInstrument,
)

PEER_TIMEOUT_S = 2.0

# One scripted exchange: (bytes the instrument must send, bytes the peer answers or None,
# seconds the peer waits before answering).
Step = tuple[bytes, bytes | None, float]


class ScriptedPeer:
    """A one-connection TCP server that checks the bytes it receives against a script."""

    def __init__(self, script: Sequence[Step]) -> None:
        self.script = list(script)
        self.failures: list[str] = []
        self.completed = 0
        self._server = socket.create_server(("127.0.0.1", 0))
        self._server.settimeout(PEER_TIMEOUT_S)
        self.port = self._server.getsockname()[1]
        self._thread = threading.Thread(target=self._run, name="scripted SCPI peer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            conn, _ = self._server.accept()
        except OSError as exc:
            self.failures.append(f"no connection: {exc}")
            return
        with conn:
            conn.settimeout(PEER_TIMEOUT_S)
            for i, (expected, reply, delay_s) in enumerate(self.script):
                received = self._receive(conn, len(expected))
                if received != expected:
                    self.failures.append(f"step {i}: expected {expected!r}, received {received!r}")
                    return
                if reply is not None:
                    time.sleep(delay_s)
                    conn.sendall(reply)
                self.completed += 1
            extra = self._receive(conn, 1 << 16, until_closed=True)
            if extra:
                self.failures.append(f"unexpected bytes after the script: {extra!r}")

    @staticmethod
    def _receive(conn: socket.socket, n: int, until_closed: bool = False) -> bytes:
        data = b""
        while len(data) < n:
            try:
                chunk = conn.recv(n - len(data))
            except OSError:
                break
            if not chunk:
                break
            data += chunk
            if until_closed:
                continue
        return data

    def finish(self) -> None:
        self._thread.join(PEER_TIMEOUT_S + 1.0)
        self._server.close()
        assert not self._thread.is_alive(), "the scripted peer did not finish"


@contextmanager
def expected_protocol(
    exchanges: Sequence[tuple[str, str | bytes | None] | tuple[str, str | bytes | None, float]],
    *,
    write_termination: str = "\n",
    read_termination: str = "\n",
    timeout_s: float = 1.0,
) -> Iterator[ScpiInstrument]:
    """Yield an instrument connected to a peer that accepts exactly ``exchanges``.

    Each exchange is ``(command, reply)`` or ``(command, reply, delay_s)``; ``reply`` is None for
    a command without reply, and bytes to be sent verbatim (no termination added). Terminations
    are added here, so they are checked byte for byte.
    """
    script: list[Step] = []
    for ex in exchanges:
        command, reply = ex[0], ex[1]
        delay_s = ex[2] if len(ex) == 3 else 0.0
        sent = (command + write_termination).encode("ascii")
        if reply is None or isinstance(reply, bytes):
            answer = reply
        else:
            answer = (reply + read_termination).encode("ascii")
        script.append((sent, answer, delay_s))
    peer = ScriptedPeer(script)
    failed = False
    try:
        with ScpiInstrument(
            f"socket://127.0.0.1:{peer.port}",
            timeout_s=timeout_s,
            write_termination=write_termination,
            read_termination=read_termination,
        ) as instrument:
            yield instrument
    except BaseException:
        failed = True
        raise
    finally:
        peer.finish()
        if not failed:
            assert not peer.failures, "; ".join(peer.failures)
            assert peer.completed == len(script), (
                f"only {peer.completed} of {len(script)} exchanges happened"
            )


# -- the helper itself fails when it should -------------------------------------------------


def test_expected_protocol_fails_on_a_missing_exchange() -> None:
    with pytest.raises(AssertionError, match="step 1: expected b'\\*CLS\\\\n', received b''"):
        with expected_protocol([("*RST", None), ("*CLS", None)]) as inst:
            inst.write("*RST")


def test_expected_protocol_fails_on_a_wrong_command() -> None:
    with pytest.raises(AssertionError, match="expected b'\\*RST\\\\n'"):
        with expected_protocol([("*RST", None)]) as inst:
            inst.write("*CLS")


def test_expected_protocol_fails_on_an_extra_command() -> None:
    with pytest.raises(AssertionError, match="unexpected bytes"):
        with expected_protocol([("*RST", None)]) as inst:
            inst.write("*RST")
            inst.write("*CLS")


# -- exchanges and terminations -------------------------------------------------------------


def test_write_and_query_exchange_exact_bytes() -> None:
    with expected_protocol([("GAIN 5", None), ("GAIN?", "5.0")]) as inst:
        inst.write("GAIN 5")
        assert inst.query("GAIN?") == "5.0"


@pytest.mark.parametrize(
    ("write_term", "read_term"), [("\r\n", "\r\n"), ("\r", "\n"), ("\n", "\r\n")]
)
def test_terminations_are_sent_and_stripped(write_term: str, read_term: str) -> None:
    with expected_protocol(
        [("*IDN?", "ACME,PA-1,42,2.1")], write_termination=write_term, read_termination=read_term
    ) as inst:
        assert inst.query("*IDN?") == "ACME,PA-1,42,2.1"


def test_reply_with_extra_carriage_return_is_stripped() -> None:
    with expected_protocol([("OUTP?", "1\r")]) as inst:
        assert inst.query("OUTP?") == "1"


def test_loop_url_echoes_through_serial_for_url() -> None:
    with ScpiInstrument("loop://", timeout_s=0.5, write_termination="\r\n") as inst:
        assert inst.query("*IDN?") == "*IDN?"
        assert inst.is_open
    assert not inst.is_open


@pytest.mark.parametrize("command", ["", "   ", "GAIN 1\nOUTP ON", "GAIN\r", "GAIN \u00b5"])
def test_bad_commands_are_refused_before_sending(command: str) -> None:
    with expected_protocol([]) as inst:
        with pytest.raises(ValueError, match="command"):
            inst.write(command)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"timeout_s": 0}, "timeout_s"),
        ({"timeout_s": float("nan")}, "timeout_s"),
        ({"baudrate": -1}, "baudrate"),
        ({"write_termination": ""}, "write_termination"),
        ({"read_termination": "\u00e9"}, "read_termination"),
    ],
)
def test_invalid_settings_name_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        ScpiInstrument("loop://", **kwargs)


def test_unopenable_port_raises_instrument_error() -> None:
    with pytest.raises(InstrumentError, match="/dev/does-not-exist"):
        ScpiInstrument("/dev/does-not-exist")


# -- identification and reset ---------------------------------------------------------------


def test_identify_parses_four_fields() -> None:
    with expected_protocol([("*IDN?", "ACME Audio, PA-200 ,SN123,fw 3.1")]) as inst:
        ident = inst.identify()
    assert ident == InstrumentIdentity("ACME Audio", "PA-200", "SN123", "fw 3.1")


def test_identify_rejects_a_malformed_reply() -> None:
    with expected_protocol([("*IDN?", "ACME,PA-200")]) as inst:
        with pytest.raises(InstrumentReplyError, match="'ACME,PA-200'"):
            inst.identify()


def test_reset_sends_rst_and_checks_the_queue() -> None:
    with expected_protocol([("*RST", None), ("SYST:ERR?", '0,"No error"')]) as inst:
        inst.reset()


# -- error queue ----------------------------------------------------------------------------


def test_errors_drains_the_queue_in_order() -> None:
    exchanges = [
        ("SYST:ERR?", '-113,"Undefined header"'),
        ("SYST:ERR?", '-222,"Data out of range;GAIN 99"'),
        ("SYST:ERR?", '+0,"No error"'),
    ]
    with expected_protocol(exchanges) as inst:
        found = inst.errors()
    assert found == [
        ScpiError(-113, "Undefined header"),
        ScpiError(-222, "Data out of range;GAIN 99"),
    ]


def test_check_errors_raises_with_the_instrument_messages() -> None:
    exchanges = [
        ("GAIN 99", None),
        ("SYST:ERR?", '-222,"Data out of range"'),
        ("SYST:ERR?", '0,"No error"'),
    ]
    with expected_protocol(exchanges) as inst:
        with pytest.raises(InstrumentError, match='GAIN 99.*-222,"Data out of range"') as info:
            inst.write_checked("GAIN 99")
    assert info.value.errors == (ScpiError(-222, "Data out of range"),)


def test_check_errors_is_quiet_on_an_empty_queue() -> None:
    with expected_protocol([("SYST:ERR?", '0,"No error"')]) as inst:
        inst.check_errors()


def test_malformed_error_reply_is_a_reply_error() -> None:
    with expected_protocol([("SYST:ERR?", "what?")]) as inst:
        with pytest.raises(InstrumentReplyError, match="what\\?"):
            inst.errors()


# -- timeouts -------------------------------------------------------------------------------


def test_timeout_names_command_and_port() -> None:
    with expected_protocol([("MEAS:CURR?", None)], timeout_s=0.2) as inst:
        start = time.monotonic()
        with pytest.raises(InstrumentTimeout) as info:
            inst.query("MEAS:CURR?")
        elapsed = time.monotonic() - start
    message = str(info.value)
    assert "'MEAS:CURR?'" in message
    assert inst.port in message
    assert "0.2 s" in message
    assert 0.15 < elapsed < 1.0
    assert isinstance(info.value, TimeoutError)


def test_unterminated_reply_times_out_and_shows_what_arrived() -> None:
    with expected_protocol([("GAIN?", b"5.0")], timeout_s=0.2) as inst:
        with pytest.raises(InstrumentTimeout, match=r"received only b'5.0'"):
            inst.query("GAIN?")


def test_late_reply_is_discarded_before_the_next_query() -> None:
    exchanges = [("GAIN?", "5.0", 0.2), ("OUTP?", "1")]
    with expected_protocol(exchanges, timeout_s=0.1) as inst:
        with pytest.raises(InstrumentTimeout):
            inst.query("GAIN?")
        time.sleep(0.6)  # the late "5.0" arrives meanwhile
        assert inst.query("OUTP?") == "1"


# -- lifetime ----------------------------------------------------------------------------


def test_closed_instrument_refuses_to_send() -> None:
    with expected_protocol([]) as inst:
        inst.close()
        inst.close()  # idempotent
        with pytest.raises(InstrumentError, match="closed"):
            inst.write("*RST")
