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
