"""The simulated Modbus table's own server, byte for byte: MBAP and RTU frames as the Modbus
application protocol gives them (a function the controller lacks, a quantity out of range, a bad
CRC), and a controller that goes away closes its client's connection."""

from __future__ import annotations

import socket
import struct

import pytest
from pymodbus.client import ModbusTcpClient

from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import preset
from simulators.rate_table import serve_modbus_table
from simulators.rate_table.modbus_server import crc16_modbus
from simulators.world import World


@pytest.fixture
def served(request):
    world = World(preset("hrg"), seed=3)
    server = serve_modbus_table(world, framer=request.param)
    sock = socket.create_connection((server.host, server.port), timeout=1.0)
    yield world, server, sock
    sock.close()
    server.stop()


def _recv(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        piece = sock.recv(n - len(data))
        if not piece:
            break
        data += piece
    return data


def _mbap(sock: socket.socket, tid: int, unit: int, pdu: bytes) -> tuple[int, int, bytes]:
    """Send one MBAP request; (transaction id, unit, reply PDU)."""
    sock.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu)
    tid_r, proto, length, unit_r = struct.unpack(">HHHB", _recv(sock, 7))
    assert proto == 0
    return tid_r, unit_r, _recv(sock, length - 1)


@pytest.mark.parametrize("served", ["tcp"], indirect=True)
def test_mbap_replies_carry_the_transaction_and_the_status(served):
    world, server, sock = served
    tid, unit, pdu = _mbap(sock, 0x1234, 1, struct.pack(">BHH", 4, 0, mp.IR_COUNT))
    assert (tid, unit) == (0x1234, 1)
    assert pdu[:2] == bytes((4, 2 * mp.IR_COUNT))
    rate_dps, angle_deg, bits, code = mp.decode_status(list(struct.unpack(f">{mp.IR_COUNT}H", pdu[2:])))
    assert rate_dps == pytest.approx(0.0, abs=0.02)  # at rest, within the rate sensor's noise
    assert 0.0 <= angle_deg < 360.0 and not bits & mp.ST_ENABLED and code == mp.FAULT_NONE


@pytest.mark.parametrize("served", ["tcp"], indirect=True)
@pytest.mark.parametrize(
    ("pdu", "code"),
    [
        (struct.pack(">BHH", 1, 0, 8), 1),  # read coils: the controller has none
        (struct.pack(">BHH", 43, 0, 0), 1),  # any other function
        (struct.pack(">BHH", 3, 0, 126), 3),  # quantity above 125
        (struct.pack(">BHH", 4, 0, 0), 3),  # quantity 0
        (struct.pack(">BHH", 4, 4, mp.IR_COUNT), 2),  # past the input registers
        (struct.pack(">BHH", 6, mp.HR_COUNT, 1), 2),  # a write past the holding registers
        (struct.pack(">BHHB", 16, 0, 2, 3) + b"\x00\x00\x00", 3),  # byte count not 2 x quantity
    ],
)
def test_refused_requests_get_the_protocols_exception(served, pdu, code):
    world, server, sock = served
    _, _, reply = _mbap(sock, 7, 1, pdu)
    assert reply == bytes((pdu[0] | 0x80, code))
    assert server.mechanics.mode == mp.MODE_STOP and not server.mechanics.enabled  # nothing acted


@pytest.mark.parametrize("served", ["rtu"], indirect=True)
def test_rtu_frames_with_a_bad_crc_get_silence_and_good_ones_a_checked_reply(served):
    world, server, sock = served
    request = struct.pack(">BBHH", 1, 4, 0, mp.IR_COUNT)
    bad = request + bytes(b ^ 0xFF for b in crc16_modbus(request))
    sock.sendall(bad)
    sock.settimeout(0.2)
    with pytest.raises(TimeoutError):
        sock.recv(64)
    sock.settimeout(1.0)
    sock.sendall(request + crc16_modbus(request))
    reply = _recv(sock, 3 + 2 * mp.IR_COUNT + 2)
    assert reply[:3] == bytes((1, 4, 2 * mp.IR_COUNT))
    assert crc16_modbus(reply[:-2]) == reply[-2:]


def test_crc16_modbus_check_value():
    """CRC-16/MODBUS of "123456789" is 0x4B37 (the catalogue's check value), sent low byte first."""
    assert crc16_modbus(b"123456789") == b"\x37\x4b"


def test_a_stopped_controller_closes_its_clients_link():
    world = World(preset("hrg"), seed=3)
    server = serve_modbus_table(world, framer="tcp")
    client = ModbusTcpClient(server.host, port=server.port, timeout=0.5, retries=0)
    try:
        assert client.connect()
        assert not client.read_input_registers(0, count=mp.IR_COUNT, device_id=1).isError()
        server.stop()
        sock = client.socket
        sock.settimeout(1.0)
        assert sock.recv(16) == b""  # the peer closed: the driver sees its link lost
    finally:
        client.close()
        server.stop()
