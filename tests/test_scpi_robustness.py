"""The SCPI front-end driver against misbehaving devices: a wall-clock deadline per query (a device
that streams or drips bytes), and stray reply lines that must never be taken for another query's
reply (the link is cleared and confirmed instead)."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LinkLostError, ProtocolError
from drivers.frontend import ScpiFrontEnd
from simulators.frontend import serve_frontend
from simulators.physics.params import ResonatorParams
from simulators.world import World

pytestmark = pytest.mark.serial  # reply deadlines of 1 s checked to 0.3 s of wall time: run alone

IDN = "GYROBENCH,FE-2CH,TEST,1.0"


def answer(message: str) -> bytes:
    """What a well-behaved instrument replies to a program message (no terminator)."""
    tag, replies = 0, []
    for unit in message.strip().split(";"):
        head, _, arg = unit.strip().lstrip(":").partition(" ")
        head = head.upper()
        if head == "*ESE":
            tag = int(arg)
        elif head == "*ESE?":
            replies.append(str(tag))
        elif head == "*IDN?":
            replies.append(IDN)
        elif head == "*OPC?":
            replies.append("1")
        elif head == "SYST:ERR?":
            replies.append('0,"No error"')
        elif head.endswith("?"):
            replies.append("0")
    return ";".join(replies).encode()


class MisbehavingDevice:
    """A loopback SCPI socket whose reply to each line is sent by `behave(sock, reply)`."""

    def __init__(self, behave: Callable[[socket.socket, bytes], None]) -> None:
        self.behave = behave
        self.stop = threading.Event()
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen()
        self.srv.settimeout(0.05)
        self.port = self.srv.getsockname()[1]
        self.resource_name = f"TCPIP::127.0.0.1::{self.port}::SOCKET"
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.srv.accept()
            except OSError:
                continue
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        buf = b""
        conn.settimeout(0.05)
        with conn:
            while not self.stop.is_set():
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not data:
                    return
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    reply = answer(line.decode())
                    if reply:
                        try:
                            self.behave(conn, reply)
                        except OSError:
                            return

    def sleep(self, seconds: float) -> bool:
        """Wait, unless the device is being stopped (then False)."""
        return not self.stop.wait(seconds)

    def close(self) -> None:
        self.stop.set()
        self.srv.close()


def _connect_timed(device: MisbehavingDevice, timeout_s: float = 1.0) -> tuple[float, BaseException | None]:
    clock = SimClock(World(ResonatorParams(f0_hz=5500.0, tau_s=3000.0), seed=1))
    fe = ScpiFrontEnd(device.resource_name, clock=clock, timeout_s=timeout_s)
    t0 = time.monotonic()
    try:
        fe.connect()
        error = None
    except Exception as exc:  # noqa: BLE001 - the test looks at it
        error = exc
    elapsed = time.monotonic() - t0
    fe.close()
    clock.close()
    return elapsed, error


def test_a_device_streaming_bytes_without_a_terminator_meets_the_deadline():
    def stream(conn: socket.socket, reply: bytes) -> None:
        t_end = time.monotonic() + 5.0  # bounds the test without the deadline too
        while device.sleep(0.005) and time.monotonic() < t_end:
            conn.sendall(b"x")  # never a terminator

    device = MisbehavingDevice(stream)
    try:
        elapsed, error = _connect_timed(device)
    finally:
        device.close()
    assert isinstance(error, LinkLostError) and "within 1 s" in str(error)
    assert 1.0 <= elapsed < 1.3


def test_a_reply_dripped_slower_than_the_deadline_is_refused_in_time():
    def drip(conn: socket.socket, reply: bytes) -> None:
        for b in reply + b"\n":
            if not device.sleep(0.4):
                return
            conn.sendall(bytes([b]))

    device = MisbehavingDevice(drip)
    try:
        elapsed, error = _connect_timed(device)
    finally:
        device.close()
    assert isinstance(error, LinkLostError) and "bytes came, no complete reply" in str(error)
    assert 1.0 <= elapsed < 1.3


@pytest.mark.parametrize("how", ["late", "dripped"])
def test_a_slow_reply_within_the_deadline_is_accepted(how):
    """0.5 s late in one piece, or dripped at 10 ms a byte (~0.3 s): both inside 1 s."""

    def slow(conn: socket.socket, reply: bytes) -> None:
        if how == "late":
            device.sleep(0.5)
            conn.sendall(reply + b"\n")
            return
        for b in reply + b"\n":
            device.sleep(0.01)
            conn.sendall(bytes([b]))

    device = MisbehavingDevice(slow)
    try:
        elapsed, error = _connect_timed(device)
    finally:
        device.close()
    assert error is None
    assert elapsed < 1.0


@pytest.fixture
def bench():
    world = World(ResonatorParams(f0_hz=5500.0, tau_s=3000.0), seed=3)
    clock = SimClock(world)
    server = serve_frontend(world, seed=4)
    fe = ScpiFrontEnd(server.resource_name, clock=clock, timeout_s=1.0).connect()
    fe.ch1.amplitude_v = 0.5
    fe.ch2.amplitude_v = 0.0
    yield server, fe
    fe.close()
    server.stop()
    clock.close()


def _reads(fe: ScpiFrontEnd) -> list[tuple[Callable[[], object], object]]:
    """Queries with their true answers (ch1 0.5 V, ch2 0.0 V, the instrument's IDN)."""
    return [
        (lambda: fe.ch2.amplitude_v, 0.0),
        (lambda: fe.ch1.amplitude_v, 0.5),
        (lambda: fe.idn, "GYROBENCH,FE-2CH,SIM0001,1.0"),
        (lambda: fe.ch2.amplitude_v, 0.0),
        (fe.check_errors, []),
        (lambda: fe.ch1.output_on, False),
        (lambda: fe.ch1.amplitude_v, 0.5),
    ]


def _check_own_values(fe: ScpiFrontEnd) -> int:
    """Every query returns its own true value or raises ProtocolError; the number raised."""
    raised = 0
    for read, truth in _reads(fe):
        try:
            value = read()
        except ProtocolError:
            raised += 1
            continue
        assert value == truth
    return raised


@pytest.mark.parametrize("stray", [b"0.5", b"0.5;7", b'0,"No error"', b"\xff\xfe garbage"])
def test_a_stray_line_never_becomes_another_query_s_value(bench, stray):
    server, fe = bench
    server.send_unsolicited(stray)
    time.sleep(0.02)  # it is in the driver's input before the next query
    assert _check_own_values(fe) <= 1
    assert _check_own_values(fe) == 0  # and the link is back in step for good


def test_duplicated_replies_are_caught_and_the_link_recovers(bench):
    server, fe = bench
    server.inject("duplicate")
    with pytest.raises(ProtocolError):
        for read, truth in _reads(fe):
            assert read() == truth
    server.inject("none")
    assert _check_own_values(fe) <= 1
    assert _check_own_values(fe) == 0


def test_a_setting_after_a_stray_line_is_confirmed_not_misread(bench):
    """The stray arrives before a setting: the setting's error-queue reply is not mistaken."""
    server, fe = bench
    server.send_unsolicited(b'-222,"Data out of range"')
    time.sleep(0.02)
    try:
        fe.ch2.amplitude_v = 0.25
    except ProtocolError:
        fe.ch2.amplitude_v = 0.25
    assert fe.ch2.amplitude_v == 0.25 and server.model.channels[2].amplitude_v == 0.25


def test_a_refused_query_is_a_device_error_not_a_timeout(bench):
    """The tag comes back alone: the instrument answered nothing to the query itself."""
    server, fe = bench
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match=r"no reply to 'SOUR3:VOLT\?'.*-114"):
        fe._query("SOUR3:VOLT?")
    assert time.monotonic() - t0 < 0.5
    assert fe.ch1.amplitude_v == 0.5


@pytest.mark.parametrize("bad", [b"nan", b"inf", b"-inf"])
def test_a_non_finite_setting_value_is_a_protocol_error(bad):
    """An amplitude read back as NaN or inf is no amplitude: ProtocolError, never the value."""

    def non_finite(conn: socket.socket, reply: bytes) -> None:
        conn.sendall(reply.replace(b"0;", bad + b";", 1) + b"\n")

    device = MisbehavingDevice(non_finite)
    clock = SimClock(World(ResonatorParams(f0_hz=5500.0, tau_s=3000.0), seed=1))
    fe = ScpiFrontEnd(device.resource_name, clock=clock, timeout_s=1.0)
    try:
        fe.connect()
        with pytest.raises(ProtocolError, match="not a valid"):
            fe.ch2.amplitude_v  # noqa: B018
    finally:
        fe.close()
        clock.close()
        device.close()


def test_a_stray_line_before_a_capture_block_is_caught_and_the_block_read_again(bench):
    server, fe = bench
    first = fe.capture(1, 2000)
    np.testing.assert_array_equal(first, server.last_capture(1))
    server.send_unsolicited(b"0.5;3")
    time.sleep(0.02)
    try:
        again = fe.fetch_capture(1, expected_samples=2000)
    except ProtocolError:
        again = fe.fetch_capture(1, expected_samples=2000)
    np.testing.assert_array_equal(again, first)
    assert fe.ch1.amplitude_v == 0.5


def test_the_link_check_probe_reads_its_own_reply_on_the_socket_without_pyvisa(bench, monkeypatch):
    """The station's per-grid-point probe (a tagged *IDN? on pyvisa-py's socket) on a healthy link
    takes no pyvisa query; the link stays in step for the queries after it."""
    server, fe = bench

    def no_query(command: str) -> str:
        raise AssertionError(f"the probe took pyvisa's query path for {command!r}")

    monkeypatch.setattr(fe, "_query", no_query)
    for _ in range(50):
        fe.probe()
    monkeypatch.undo()
    assert _check_own_values(fe) == 0


@pytest.mark.parametrize("stray", [b"0.5", b"GYROBENCH,FE-2CH,SIM0001,1.0;123", b"\xff\xfe garbage"])
def test_a_stray_line_before_the_probe_sends_it_to_the_full_query_path(bench, stray):
    """A line that is not the probe's own reply (wrong tag, not an IDN) is never taken for a sign of
    life by itself: the probe clears the input and asks again through the confirmed path."""
    server, fe = bench
    server.send_unsolicited(stray)
    time.sleep(0.02)
    fe.probe()  # the full path's confirmation: no error, the link proven
    assert not fe._suspect
    assert _check_own_values(fe) == 0


@pytest.mark.parametrize("how", ["hang", "gone"])
def test_a_probe_of_a_silent_or_gone_device_is_a_lost_link_in_bounded_time(bench, how):
    server, fe = bench
    if how == "hang":
        server.inject("hang")
    else:
        server.stop()
    t0 = time.monotonic()
    with pytest.raises(LinkLostError):
        fe.probe()
    assert time.monotonic() - t0 < 2.0 * fe.timeout_s + 0.5  # the probe's wait, then the full query's
