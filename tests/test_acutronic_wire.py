"""The Acutrol simulator's bytes on the wire, pinned to the manuals, and the driver surviving
malformed traffic (docs/rate_table_acutronic.md, "Answers: two framings", "Malformed traffic").

Expected bytes: the texts are TM-8004's own examples (3.3 `*ESR?` -> 0, 3.4 the *IDN? string,
4.14.1 `:U:F?` -> FLOAT, 4.14.2 `:U:L?` -> OFF); the TCP header is TM-9374A 3.4.2's two 32-bit
words (error code, length) in the Intel order of TM-8004 5.1.1; `OK` for a command is what
Acutronic's own client expects after the 8 header bytes."""

from __future__ import annotations

import socket
import time

import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LinkLostError, ProtocolError
from drivers.rate_table import acutronic_protocol as ap
from drivers.rate_table.acutronic_driver import AcutrolRateTable
from simulators.physics.params import preset
from simulators.rate_table.acutronic_server import serve_acutrol_table
from simulators.world import World
from tests.test_rate_table import LIMITS

MANUAL_IDN = "Acutronic R&D USA,Acutrol3000,0,A8800-001-01.000-a"  # TM-8004 3.4's example


@pytest.fixture
def server():
    world = World(preset("hrg"), seed=3)
    srv = serve_acutrol_table(world, idn=MANUAL_IDN)
    yield srv
    srv.stop()


class Wire:
    """A raw socket client: bytes out, whatever comes back within a short wall time."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def read(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                break
            out += chunk
        return out

    def silent(self, wall_s: float = 0.3) -> bool:
        """True when nothing arrives within wall_s."""
        self.sock.settimeout(wall_s)
        try:
            return self.sock.recv(1) == b""
        except TimeoutError:
            return True
        finally:
            self.sock.settimeout(2.0)

    def ask(self, data: bytes, n: int) -> bytes:
        self.send(data)
        return self.read(n)

    def close(self) -> None:
        self.sock.close()


# --- the two framings, byte for byte --------------------------------------------------------------
TCP_EXCHANGES = [
    (b"*IDN?\n", b"\x00\x00\x00\x00\x32\x00\x00\x00" + MANUAL_IDN.encode()),  # 50 characters
    (b":MODE:OFF 1\n", b"\x00\x00\x00\x00\x02\x00\x00\x00OK"),  # a command: answered OK
    (b"*ESR?\n", b"\x00\x00\x00\x00\x01\x00\x00\x000"),
    (b":U:F?\n", b"\x00\x00\x00\x00\x05\x00\x00\x00FLOAT"),
    (b":U:L?\n", b"\x00\x00\x00\x00\x03\x00\x00\x00OFF"),
    (b":U:L ON\r\n", b"\x00\x00\x00\x00\x02\x00\x00\x00OK"),  # CR LF ends a message as LF does (2.4)
]


@pytest.mark.parametrize("sent, answer", TCP_EXCHANGES)
def test_tcp_framing_error_code_and_length_before_the_data(server, sent, answer):
    wire = Wire(server.port)
    try:
        assert wire.ask(sent, len(answer)) == answer
        assert wire.silent(0.1)
    finally:
        wire.close()


def test_tcp_framing_a_refused_command_carries_its_error_code(server):
    wire = Wire(server.port)
    try:
        assert wire.ask(b":DEM:POS 1,400\n", 8) == b"\x03\x00\x00\x00\x00\x00\x00\x00"  # range, no text
        assert wire.ask(b":FLY 1\n", 8) == b"\x01\x00\x00\x00\x00\x00\x00\x00"  # unknown
        assert wire.ask(b":U:F F\n", 8) == b"\x05\x00\x00\x00\x00\x00\x00\x00"  # 4.14.1: GPIB controller only
    finally:
        wire.close()


def test_gpib_framing_lines_for_queries_and_nothing_for_commands(server):
    wire = Wire(server.gpib_port)
    try:
        idn = MANUAL_IDN.encode() + b"\n"
        assert wire.ask(b"*IDN?\n", len(idn)) == idn
        wire.send(b":MODE:OFF 1\n")
        assert wire.silent()  # IEEE-488: a command message is not answered
        assert wire.ask(b"*ESR?\n", 2) == b"0\n"
        assert wire.ask(b":U:F?\n", 6) == b"FLOAT\n"
        assert wire.ask(b":U:F F;*ESR?\n", 2) == b"0\n"  # the controller in charge may set it
    finally:
        wire.close()


@pytest.mark.parametrize(
    "resource, framing, expected",
    [("GPIB0::1::INSTR", "auto", "gpib"), ("gpib1::7::instr", "auto", "gpib"), ("", "auto", "tcp"),
     ("TCPIP::192.168.53.1::9878::SOCKET", "auto", "tcp"), ("TCPIP::127.0.0.1::5000::SOCKET", "gpib", "gpib")],
)  # fmt: skip
def test_the_transport_chooses_the_framing(resource, framing, expected):
    assert ap.framing_for(resource, framing) == expected


def test_a_bad_framing_name_is_refused():
    with pytest.raises(ValueError, match="expected 'auto', 'tcp' or 'gpib'"):
        ap.framing_for("", "rs232")


# --- malformed traffic: the simulator as the manual says ------------------------------------------
def test_a_failed_known_query_answers_empty_an_unknown_one_nothing(server):
    """Axis 9 does not exist: its known query answers an empty field; `:FOO?` is unknown and is
    ignored, so the fields after it shift (TM-8004 table 1: unknown commands are ignored)."""
    wire = Wire(server.gpib_port)
    try:
        wire.send(b":MODE? 9;:MODE? 1\n")
        assert wire.read(3) == b";O\n"
        wire.send(b":FOO?;:MODE? 1;:U:L?\n")
        assert wire.read(6) == b"O;OFF\n"
        wire.send(b":FOO?\n")
        assert wire.silent()  # nothing known asked: no answer at all on GPIB
    finally:
        wire.close()
    wire = Wire(server.port)
    try:  # on TCP every message is answered: the code says what went wrong
        assert wire.ask(b":FOO?;:MODE? 1\n", 9) == b"\x01\x00\x00\x00\x01\x00\x00\x00O"
        assert wire.ask(b":MODE? 9\n", 8) == b"\x03\x00\x00\x00\x00\x00\x00\x00"
    finally:
        wire.close()


@pytest.mark.parametrize("port_name", ["port", "gpib_port"])
def test_cr_alone_does_not_end_a_message(server, port_name):
    wire = Wire(getattr(server, port_name))
    try:
        wire.send(b"*ESR?\r")
        assert wire.silent()
        wire.send(b"\n")  # now CR LF: one message
        expected = b"\x00\x00\x00\x00\x01\x00\x00\x000" if port_name == "port" else b"0\n"
        assert wire.read(len(expected)) == expected
    finally:
        wire.close()


def _message_of(chars: int) -> bytes:
    """A vtrip setting padded with leading zeros to exactly `chars` characters."""
    head, tail = ":LIM:VTR R,1,", "400.0"
    return (head + "0" * (chars - len(head) - len(tail)) + tail).encode()


@pytest.mark.parametrize("port_name", ["port", "gpib_port"])
def test_32k_messages_execute_and_longer_ones_are_lost(server, port_name):
    """TM-8004 2.5: up to 32,768 characters in one message; more overflow and the message is lost."""
    c = server.controller
    wire = Wire(getattr(server, port_name))
    try:
        wire.send(_message_of(ap.MAX_MESSAGE_CHARS + 1) + b"\n")
        assert wire.silent() and c.limit_vtrip["R"] != 400.0
        msg = _message_of(ap.MAX_MESSAGE_CHARS)
        if port_name == "port":
            assert wire.ask(msg + b"\r\n", 10) == b"\x00\x00\x00\x00\x02\x00\x00\x00OK"
        else:
            wire.send(msg + b"\n")
            assert wire.ask(b":LIM:VTR? R,1\n", 11) == b"400.000000\n"
        assert c.limit_vtrip["R"] == 400.0
    finally:
        wire.close()


# --- malformed traffic: the driver survives ---------------------------------------------------------
@pytest.fixture(params=["tcp", "gpib"])
def table(request, server):
    clock = SimClock(server.world)
    if request.param == "gpib":
        t = AcutrolRateTable(resource=server.gpib_standin_resource, framing="gpib", limits=LIMITS, clock=clock,
                             timeout_s=0.3)  # fmt: skip
    else:
        t = AcutrolRateTable(server.host, server.port, limits=LIMITS, clock=clock, timeout_s=0.3)
    t.connect()
    yield t
    t.close()
    clock.close()


def test_the_driver_refuses_a_shifted_status_and_carries_on(table, monkeypatch):
    """A status query the controller does not fully know: one field short; then one refused
    (axis 9): an empty field.  GPIB: a ProtocolError naming the fields; TCP: the error code's
    refusal; never a misread status, and the next status is read."""
    from drivers.rate_table import acutronic_driver

    good = ap.status_query
    shifted = good(1).replace(";CSR? A1INTLK", ";:FOO? 1;:STAT:CSR? A1INTLK").replace(":INT? 1;", "")
    monkeypatch.setattr(acutronic_driver.ap, "status_query", lambda axis: shifted)
    with pytest.raises(DeviceError, match="5 fields, expected 6|error code 1: unknown command"):
        table.status()
    monkeypatch.setattr(acutronic_driver.ap, "status_query", lambda axis: good(1).replace(":INT? 1", ":INT? 9"))
    with pytest.raises(DeviceError, match="empty field|error code 3: axis or value out of range"):
        table.status()
    monkeypatch.setattr(acutronic_driver.ap, "status_query", good)
    assert not table.status().tripped


def test_the_driver_does_not_send_a_message_the_controller_would_lose(table):
    with pytest.raises(ProtocolError, match="32768 at most"):
        table._send(":DEM:RATE 1," + "0" * 40000 + "1", idempotent=False)
    assert not table.status().tripped


def test_a_lost_message_from_another_client_leaves_the_driver_working(server, table):
    wire = Wire(server.port)
    try:
        wire.send(_message_of(ap.MAX_MESSAGE_CHARS + 10) + b"\n")
        time.sleep(0.1)
    finally:
        wire.close()
    assert table._query("*IDN?") == MANUAL_IDN


def test_an_answer_header_with_an_absurd_length_is_a_protocol_error():
    with pytest.raises(ValueError, match="above the controller's 32768"):
        ap.parse_tcp_header(b"\x00\x00\x00\x00\xff\xff\x00\x00")
    assert ap.parse_tcp_header(b"\x00\x00\x00\x00\x02\x00\x00\x00") == (0, 2)


def test_a_garbled_answer_is_retried_then_a_link_error(server, table):
    server.corrupt_replies("garbage", 1)
    assert not table.status().tripped
    server.corrupt_replies("drop", 50)
    with pytest.raises((LinkLostError, ProtocolError)):
        table.status()
    server.corrupt_replies("drop", 0)


def test_the_manual_transcript_passes_against_the_simulator_gpib_standin(server):
    """tests/acutrol_gpib_transcript.yaml, written from TM-8004 for pyvisa-sim, replayed against
    the simulator: every exchange that does not depend on the table's motion answers the same."""
    from pathlib import Path

    import yaml

    spec = yaml.safe_load(Path(__file__).with_name("acutrol_gpib_transcript.yaml").read_text())
    dialogues = spec["devices"]["acutrol"]["dialogues"]
    motion = (":READ:", ":MODE:OFF")  # the table's state: angle, noise, profile events
    wire = Wire(server.gpib_port)
    try:
        checked = 0
        for d in dialogues:
            if any(m in d["q"] for m in motion):
                continue
            expected = d["r"].encode() + b"\n"
            assert wire.ask(d["q"].encode() + b"\n", len(expected)) == expected, d["q"]
            checked += 1
        assert checked == len(dialogues) - 2
    finally:
        wire.close()
