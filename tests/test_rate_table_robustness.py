"""The Modbus rate table as a stock client sees it (pymodbus's own client: FC3, FC6, FC16), a
request for another unit id, and a peer that resets the link while the driver connects."""

from __future__ import annotations

import socket
import struct
import threading

import pytest
from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ModbusIOException

from bench.clock import SimClock
from drivers.errors import DeviceError, LinkLostError
from drivers.rate_table import ModbusRateTable, TableLimits
from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import preset
from simulators.rate_table import serve_modbus_table
from simulators.world import World

LIMITS = TableLimits(max_rate_dps=500.0, max_accel_dps2=300.0)


@pytest.fixture
def tcp_table():
    world = World(preset("hrg"), seed=3)
    server = serve_modbus_table(world, framer="tcp")
    client = ModbusTcpClient(server.host, port=server.port, timeout=0.5, retries=0)
    assert client.connect()
    yield world, server, client
    client.close()
    server.stop()


def test_fc6_single_register_writes_are_answered_with_their_echo_and_act(tcp_table):
    """Every holding register a stock client may write one at a time: the reply is the echo of
    the request (Modbus FC6), never an exception, and the controller acted on it."""
    world, server, client = tcp_table
    mech = server.mechanics
    for address, value in [
        (mp.HR_WATCHDOG_MS, 0),
        (mp.HR_ENABLE, 1),
        (mp.HR_HEARTBEAT, 7),
        (mp.HR_FAULT_RESET, 1),
        (mp.HR_MODE, mp.MODE_STOP),
        (mp.HR_WATCHDOG_MS, 1500),
        (mp.HR_ENABLE, 0),
    ]:
        rr = client.write_register(address, value, device_id=1)
        assert not rr.isError(), f"FC6 {value} -> register {address}: {rr}"
        assert (rr.address, rr.registers) == (address, [value])
        if address == mp.HR_ENABLE:
            assert mech.enabled is bool(value)
        if address == mp.HR_WATCHDOG_MS:
            assert mech.watchdog_s == value / 1000.0
    assert mech.mode == mp.MODE_STOP
    # a refused single write still answers with the exception the register map gives
    rr = client.write_register(mp.HR_ENABLE, 2, device_id=1)
    assert rr.isError() and rr.exception_code == mp.EXC_ILLEGAL_VALUE


def test_fc16_command_block_and_fc3_read_back(tcp_table):
    """A stock client spins the table with one FC16 block and reads it back with FC3."""
    world, server, client = tcp_table
    assert not client.write_register(mp.HR_ENABLE, 1, device_id=1).isError()
    block = mp.encode_command(mp.MODE_RATE, 12.5, 0.0, 100.0)
    rr = client.write_registers(mp.CMD_BLOCK_START, block, device_id=1)
    assert not rr.isError()
    assert server.mechanics.mode == mp.MODE_RATE and server.mechanics.target_rate_dps == 12.5
    rr = client.read_holding_registers(0, count=mp.HR_COUNT, device_id=1)
    assert not rr.isError()
    assert rr.registers[: mp.CMD_BLOCK_COUNT] == block
    assert rr.registers[mp.HR_ENABLE] == 1 and rr.registers[mp.HR_FAULT_RESET] == 0
    # and FC6 MODE=0 stops it: the reply says so
    rr = client.write_register(mp.HR_MODE, mp.MODE_STOP, device_id=1)
    assert not rr.isError() and server.mechanics.mode == mp.MODE_STOP


@pytest.mark.parametrize("unit", [0, 2, 247])
def test_another_unit_id_over_tcp_is_answered_gateway_no_response(tcp_table, unit):
    """A TCP server asked for a unit it is not answers exception 0x0B, for reads and writes;
    unit 255 is this server itself (the Modbus TCP convention)."""
    world, server, client = tcp_table
    for rr in (
        client.read_input_registers(0, count=mp.IR_COUNT, device_id=unit),
        client.read_holding_registers(0, count=2, device_id=unit),
        client.write_register(mp.HR_ENABLE, 1, device_id=unit),
    ):
        assert rr.isError() and rr.exception_code == 0x0B
    assert server.mechanics.enabled is False
    rr = client.read_input_registers(0, count=mp.IR_COUNT, device_id=255)
    assert not rr.isError() and len(rr.registers) == mp.IR_COUNT


def test_another_unit_id_on_a_serial_line_gets_no_answer():
    """A slave on an RTU line answers only its own address; the right one still answers after."""
    world = World(preset("hrg"), seed=3)
    server = serve_modbus_table(world, framer="rtu", use_pty=True)
    client = ModbusSerialClient(server.url, framer=FramerType.RTU, baudrate=921600, timeout=0.3, retries=0)
    try:
        assert client.connect()
        with pytest.raises(ModbusIOException):
            client.read_input_registers(0, count=mp.IR_COUNT, device_id=2)
        rr = client.read_input_registers(0, count=mp.IR_COUNT, device_id=1)
        assert not rr.isError() and len(rr.registers) == mp.IR_COUNT
    finally:
        client.close()
        server.stop()


def test_driver_with_a_wrong_unit_id_names_it():
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    server = serve_modbus_table(world, framer="tcp")
    table = ModbusRateTable(server.host, server.port, limits=LIMITS, clock=clock, device_id=5, timeout_s=0.3)
    try:
        with pytest.raises(DeviceError, match=r"unit 5\).*exception 11 \(gateway target"):
            table.connect()
    finally:
        table.close()
        server.stop()
        clock.close()


def _resetting_server(reset_after_bytes: bool) -> tuple[socket.socket, threading.Event]:
    """A listener whose every connection is reset (RST): at once, or after the first request."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    stop = threading.Event()

    def serve() -> None:
        srv.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            if reset_after_bytes:
                conn.settimeout(2.0)
                try:
                    conn.recv(256)
                except OSError:
                    pass
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    return srv, stop


@pytest.mark.parametrize("reset_after_bytes", [False, True])
def test_connection_reset_during_connect_is_a_named_link_error(reset_after_bytes):
    srv, stop = _resetting_server(reset_after_bytes)
    port = srv.getsockname()[1]
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    table = ModbusRateTable("127.0.0.1", port, limits=LIMITS, clock=clock, timeout_s=0.3, read_retries=1)
    try:
        with pytest.raises(LinkLostError, match=rf"rate table at 127\.0\.0\.1:{port}"):
            table.connect()
    finally:
        stop.set()
        table.close()
        srv.close()
        clock.close()


# --- replies that parse but may answer another request ------------------------------------------
STATUS_REGS = mp.encode_status(12.5, 30.0, mp.ST_ENABLED, 0)
STALE_REGS = mp.encode_status(-99.0, 271.0, 0, 0)


def _crc(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def _fc4_pdu(regs: list[int], fc: int = 4) -> bytes:
    return bytes([fc, 2 * len(regs)]) + b"".join(struct.pack(">H", r) for r in regs)


class FakeDevice:
    """A loopback TCP device: `reply(request bytes) -> bytes to send` for each request that
    `split(buffer)` cuts off (None while incomplete)."""

    def __init__(self, split, reply) -> None:
        self.split, self.reply = split, reply
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen()
        self.port = self.srv.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        try:
            conn, _ = self.srv.accept()
        except OSError:
            return
        buf = b""
        with conn:
            while True:
                try:
                    data = conn.recv(4096)
                except OSError:
                    return
                if not data:
                    return
                buf += data
                while (cut := self.split(buf)) is not None:
                    req, buf = cut
                    conn.sendall(self.reply(req))

    def close(self) -> None:
        self.srv.close()


def _tcp_split(buf: bytes):
    n = 6 + struct.unpack(">H", buf[4:6])[0] if len(buf) >= 7 else 1 << 30
    return (buf[:n], buf[n:]) if len(buf) >= n else None


def _rtu_split(buf: bytes):
    n = (9 + buf[6] if buf[1] == 16 else 8) if len(buf) >= 8 else 1 << 30
    return (buf[:n], buf[n:]) if len(buf) >= n else None


def _table(dev: FakeDevice, rtu: bool) -> ModbusRateTable:
    clock = SimClock(World(preset("hrg"), seed=3))
    kw = dict(limits=LIMITS, clock=clock, timeout_s=0.3, read_retries=2, heartbeat_s=1e6)
    if rtu:
        return ModbusRateTable.rtu(f"socket://127.0.0.1:{dev.port}", **kw)
    return ModbusRateTable("127.0.0.1", dev.port, **kw)


def test_a_reply_of_another_function_code_is_not_taken_for_the_status():
    """An FC3 reply (another request's registers) to the FC4 status read: retried, then refused."""

    def reply(req: bytes) -> bytes:
        pdu = req[7:12] if req[7] == 16 else _fc4_pdu(STALE_REGS, fc=3)
        return req[:4] + struct.pack(">H", len(pdu) + 1) + req[6:7] + pdu

    dev = FakeDevice(_tcp_split, reply)
    table = _table(dev, rtu=False)
    try:
        table.connect()
        with pytest.raises(LinkLostError, match="reply of function 3, not 4"):
            table.status()
    finally:
        table.close()
        table.clock.close()
        dev.close()


@pytest.mark.parametrize("stale_every_time", [False, True])
def test_an_rtu_reply_with_a_stale_frame_before_it_is_never_returned(stale_every_time):
    """RTU has no transaction id: a stale status frame arriving with the real one makes both
    suspect; the read is retried (the true status) or fails, never returns the stale values."""
    sent = {"stale": 0}

    def reply(req: bytes) -> bytes:
        if req[1] == 16:
            body = req[:6]
        else:
            body = req[:1] + _fc4_pdu(STATUS_REGS)
            if stale_every_time or sent["stale"] == 0:
                sent["stale"] += 1
                stale = req[:1] + _fc4_pdu(STALE_REGS)
                return stale + _crc(stale) + body + _crc(body)
        return body + _crc(body)

    dev = FakeDevice(_rtu_split, reply)
    table = _table(dev, rtu=True)
    try:
        table.connect()
        if stale_every_time:
            with pytest.raises(LinkLostError, match="bytes came for a 17-byte reply"):
                table.status()
        else:
            st = table.status()
            assert (st.rate_dps, st.angle_deg, st.enabled) == (12.5, 30.0, True)
    finally:
        table.close()
        table.clock.close()
        dev.close()


def test_ascii_stale_line_before_the_reply_is_never_returned():
    """A stale STAT? line arrives ahead of the real one: the reply is refused and retried."""
    from drivers.rate_table import AsciiRateTable
    from drivers.rate_table import ascii_protocol as ap

    count = {"stat": 0}

    def reply(req: bytes) -> bytes:
        text = req.decode().strip()
        if text == ap.Q_IDN:
            return (ap.IDN + "\n").encode()
        if text == ap.Q_STAT:
            count["stat"] += 1
            good = (ap.format_status(12.5, 30.0, mp.ST_ENABLED, 0) + "\n").encode()
            stale = (ap.format_status(-99.0, 271.0, 0, 0) + "\n").encode()
            return stale + good if count["stat"] == 1 else good
        return b"OK\n"

    def split(buf: bytes):
        i = buf.find(b"\n")
        return (buf[: i + 1], buf[i + 1 :]) if i >= 0 else None

    dev = FakeDevice(split, reply)
    clock = SimClock(World(preset("hrg"), seed=3))
    table = AsciiRateTable(f"127.0.0.1:{dev.port}", limits=LIMITS, clock=clock, timeout_s=0.3, heartbeat_s=1e6)
    try:
        table.connect()
        st = table.status()
        assert (st.rate_dps, st.angle_deg, st.enabled) == (12.5, 30.0, True)
        assert count["stat"] == 2  # the first reply was refused, the retry read the true one
    finally:
        table.close()
        table.clock.close()
        dev.close()
        clock.close()
