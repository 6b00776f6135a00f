"""The Modbus rate-table controller on loopback: a small threaded Modbus server (TCP, MBAP
framing, or RTU framing over a TCP socket that a `socket://` serial URL reaches), backed by a
`TableMechanics` attached to the World.  Register map: drivers/rate_table/modbus_protocol.py.

It answers the functions the controller has (FC3, FC4, FC6, FC16; any other: exception 1) as
the Modbus application protocol specifies them, so any stock client talks to it; one blocking
thread per connection answers a request in a few tens of microseconds (an asyncio server took
several times that, which the lockstep link checks pay thousands of times a run)."""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from drivers.rate_table import modbus_protocol as mp

from ..tcp_server import LoopbackTcpServer
from .fault_controls import REPLY_FAULTS, TableFaultControls
from .mechanics import CommandRejected, TableMechanics
from .pty_bridge import PtyBridge

EXC_ILLEGAL_FUNCTION = 0x01
EXC_GATEWAY_NO_RESPONSE = 0x0B
_MAX_READ_REGS = 125  # Modbus application protocol: FC3/FC4 quantity 1..125
_MAX_WRITE_REGS = 123  # FC16 quantity 1..123


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CRC_TABLE = _crc_table()


def crc16_modbus(data: bytes) -> bytes:
    """The RTU frame check (CRC-16/MODBUS), low byte first as sent."""
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return struct.pack("<H", crc)


@dataclass
class _LinkFaults:
    """Reply corruption the tests ask for: kind in "short", "garbage", "drop", "late" (the whole
    reply after late_s of wall time, as from a controller or a line that stalled); count replies."""

    kind: str = ""
    count: int = 0
    late_s: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def apply(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            return data
        with self.lock:
            if self.count <= 0:
                return data
            self.count -= 1
            kind = self.kind
        if kind == "short":
            return data[: max(1, len(data) // 2)]
        if kind == "garbage":
            return bytes((b ^ 0x5A) for b in data)
        if kind == "late":  # this connection's thread: the next request waits behind it, as on a line
            time.sleep(self.late_s)
            return data
        return b""  # drop


def _exception(fc: int, code: int) -> bytes:
    return bytes((fc | 0x80, code))


class _TableRegisters:
    """Answers one request PDU: reads fill registers from the mechanics, writes command it."""

    def __init__(self, world, mech: TableMechanics) -> None:
        self.world, self.mech = world, mech

    def answer(self, pdu: bytes) -> bytes:
        """The reply PDU to a request PDU (an exception PDU for what the controller refuses)."""
        fc = pdu[0]
        if fc in (3, 4):
            if len(pdu) != 5:
                return _exception(fc, mp.EXC_ILLEGAL_VALUE)
            address, count = struct.unpack_from(">HH", pdu, 1)
            if not 1 <= count <= _MAX_READ_REGS:
                return _exception(fc, mp.EXC_ILLEGAL_VALUE)
            if address + count > (mp.HR_COUNT if fc == 3 else mp.IR_COUNT):
                return _exception(fc, mp.EXC_ILLEGAL_ADDRESS)
            with self.world.lock:
                regs = self._holding() if fc == 3 else mp.encode_status(*self.mech.status())
            values = regs[address : address + count]
            return struct.pack(f">BB{count}H", fc, 2 * count, *values)
        if fc == 6:
            if len(pdu) != 5:
                return _exception(fc, mp.EXC_ILLEGAL_VALUE)
            address, value = struct.unpack_from(">HH", pdu, 1)
            values = [value]
        elif fc == 16:
            if len(pdu) < 6:
                return _exception(fc, mp.EXC_ILLEGAL_VALUE)
            address, count, n_bytes = struct.unpack_from(">HHB", pdu, 1)
            if not 1 <= count <= _MAX_WRITE_REGS or n_bytes != 2 * count or len(pdu) != 6 + n_bytes:
                return _exception(fc, mp.EXC_ILLEGAL_VALUE)
            values = list(struct.unpack_from(f">{count}H", pdu, 6))
        else:
            return _exception(fc, EXC_ILLEGAL_FUNCTION)
        if address + len(values) > mp.HR_COUNT:
            return _exception(fc, mp.EXC_ILLEGAL_ADDRESS)
        self.mech.feed()  # every write feeds the watchdog, without waiting for the world
        if not (address == mp.HR_HEARTBEAT and len(values) == 1):
            with self.world.lock:
                code = self._write(address, values)
            if code is not None:
                return _exception(fc, code)
        # FC6 answers with the echo of its request; FC16 with the address and the quantity
        return pdu if fc == 6 else struct.pack(">BHH", fc, address, len(values))

    def _holding(self) -> list[int]:
        m = self.mech
        rate = m.traverse_dps if m.mode == mp.MODE_POSITION else m.target_rate_dps
        return [
            m.mode,
            *mp.float_to_regs(rate),
            *mp.float_to_regs(m.target_angle_deg),
            *mp.float_to_regs(m.accel_dps2),
            int(m.enabled),
            0,
            0,
            min(65535, int(round(m.watchdog_s * 1000))),
        ]

    def _write(self, address: int, values: list[int]) -> int | None:
        m = self.mech
        regs = self._holding()
        regs[address : address + len(values)] = values
        touched = set(range(address, address + len(values)))
        try:
            if mp.HR_WATCHDOG_MS in touched:
                m.set_watchdog_s(regs[mp.HR_WATCHDOG_MS] / 1000.0)
            if mp.HR_FAULT_RESET in touched:
                if regs[mp.HR_FAULT_RESET] not in (0, 1):
                    return mp.EXC_ILLEGAL_VALUE
                if regs[mp.HR_FAULT_RESET] == 1:
                    m.fault_reset()
            if mp.HR_ENABLE in touched:
                if regs[mp.HR_ENABLE] not in (0, 1):
                    return mp.EXC_ILLEGAL_VALUE
                m.set_enabled(bool(regs[mp.HR_ENABLE]))
            if touched & set(range(mp.CMD_BLOCK_START, mp.CMD_BLOCK_START + mp.CMD_BLOCK_COUNT)):
                rate = mp.regs_to_float(regs[mp.HR_RATE_CMD : mp.HR_RATE_CMD + 2])
                angle = mp.regs_to_float(regs[mp.HR_ANGLE_CMD : mp.HR_ANGLE_CMD + 2])
                accel = mp.regs_to_float(regs[mp.HR_ACCEL : mp.HR_ACCEL + 2])
                m.command(regs[mp.HR_MODE], rate, angle, accel)
        except CommandRejected as exc:
            return mp.EXC_ILLEGAL_VALUE if exc.bad_value else mp.EXC_DEVICE_FAILURE
        return None


def _read_exact(sock: socket.socket, n: int) -> bytes | None:
    """n bytes from the socket, or None when the peer closed it."""
    data = b""
    while len(data) < n:
        piece = sock.recv(n - len(data))
        if not piece:
            return None
        data += piece
    return data


def _rtu_request_length(head: bytes) -> int | None:
    """Bytes of a whole RTU request from its first 7 bytes (unit, fc, ...), CRC included; None
    for a function whose request length this controller does not know."""
    fc = head[1]
    if fc in (1, 2, 3, 4, 5, 6):
        return 8
    if fc in (15, 16):
        return 9 + head[6]
    return None


class ModbusTableServer(TableFaultControls, LoopbackTcpServer):
    """Handle of a running Modbus table: `.host`, `.port`, `.url`, `.mechanics`, `.stop()`.

    TCP: it answers its unit id and 255 (the id the Modbus TCP guide reserves for "this
    server"); another unit id gets exception 0x0B, as a gateway to one unit answers.  RTU: only
    its own address is answered; a request for another, or with a bad CRC, gets silence, as on a
    serial line (docs/rate_table_modbus.md)."""

    reply_faults = (*REPLY_FAULTS, "late")

    def __init__(
        self, world, mechanics: TableMechanics, *, host: str, port: int, framer: str, device_id: int, use_pty=False,
        registers: Any = None,
    ):
        if framer not in ("tcp", "rtu"):
            raise ValueError(f"framer={framer!r}: expected 'tcp' or 'rtu'")
        self.world, self.mechanics, self.framer, self.device_id = world, mechanics, framer, device_id
        self.link_faults = _LinkFaults()
        # another controller on the same framing (simulators/chamber) brings its own register map
        self._registers = registers if registers is not None else _TableRegisters(world, mechanics)
        self._units = {device_id, 255} if framer == "tcp" else {device_id}
        LoopbackTcpServer.__init__(self, host, port, "modbus-table")
        self._bridge = PtyBridge(self.host, self.port) if use_pty else None

    # --- one connection -------------------------------------------------------------------------
    def serve_connection(self, conn: socket.socket, rfile: Any, wfile: Any) -> None:
        """Answer each request frame read from the socket until the peer goes or `stop()`."""
        while not self.stopping:
            reply = self._serve_tcp(conn) if self.framer == "tcp" else self._serve_rtu(conn)
            if reply is None:
                return
            out = self.link_faults.apply(True, reply)
            if out:
                conn.sendall(out)

    def _serve_tcp(self, sock: socket.socket) -> bytes | None:
        """One MBAP request in, its reply frame out (b"": none); None when the peer has gone."""
        head = _read_exact(sock, 7)
        if head is None:
            return None
        tid, protocol, length, unit = struct.unpack(">HHHB", head)
        if length < 2 or length > 254:
            return None  # not Modbus TCP: drop the connection as a server does
        pdu = _read_exact(sock, length - 1)
        if pdu is None:
            return None
        if protocol != 0:
            return b""
        if unit not in self._units:
            answer = _exception(pdu[0], EXC_GATEWAY_NO_RESPONSE)
        else:
            answer = self._registers.answer(pdu)
        return struct.pack(">HHHB", tid, 0, len(answer) + 1, unit) + answer

    def _serve_rtu(self, sock: socket.socket) -> bytes | None:
        """One RTU request in, its reply frame out (b"": silence); None when the peer has gone."""
        head = _read_exact(sock, 2)
        if head is None:
            return None
        if head[1] in (15, 16):
            rest = _read_exact(sock, 5)
            if rest is None:
                return None
            head += rest
        n = _rtu_request_length(head)
        if n is None:
            # a function this controller does not have: its length is unknown, so take what came
            # with it and answer (if addressed to us) exception 1 as a slave does
            sock.settimeout(0.01)
            try:
                head += sock.recv(256)
            except TimeoutError:
                pass
            finally:
                sock.settimeout(None)
            if head[0] != self.device_id:
                return b""
            frame = bytes((head[0],)) + _exception(head[1], EXC_ILLEGAL_FUNCTION)
            return frame + crc16_modbus(frame)
        rest = _read_exact(sock, n - len(head))
        if rest is None:
            return None
        frame = head + rest
        if crc16_modbus(frame[:-2]) != frame[-2:] or frame[0] not in self._units:
            return b""
        answer = bytes((frame[0],)) + self._registers.answer(frame[1:-2])
        return answer + crc16_modbus(answer)

    @property
    def url(self) -> str:
        """What a serial (RTU) client opens through pyserial: the pty path, or `socket://host:port`."""
        return self._bridge.path if self._bridge is not None else f"socket://{self.host}:{self.port}"

    def stop(self) -> None:
        if self._bridge is not None:
            self._bridge.close()
            self._bridge = None
        if not self.stopping:
            LoopbackTcpServer.stop(self)  # the clients see the link close, as when a controller goes away
            with self.world.lock:
                self.world.detach(self.mechanics)

    def __enter__(self) -> ModbusTableServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def serve_modbus_table(
    world,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    framer: str = "tcp",
    device_id: int = 1,
    use_pty: bool = False,
    mechanics: TableMechanics | None = None,
    **mechanics_kw,
) -> ModbusTableServer:
    """Attach a TableMechanics to the world and serve it over Modbus on loopback (port 0: any);
    use_pty (RTU): also open a pty wired to the server, its path in `.url`."""
    mech = mechanics if mechanics is not None else TableMechanics(seed=world.seed, **mechanics_kw)
    with world.lock:
        world.attach(mech)
    return ModbusTableServer(world, mech, host=host, port=port, framer=framer, device_id=device_id, use_pty=use_pty)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[ModbusTableServer, dict[str, Any]]:
    """A simulated station's `modbus-table`: served from its station keys; (handle, driver address keys)."""
    handle = serve_modbus_table(
        world,
        max_rate_dps=cfg["max_rate_dps"],
        max_accel_dps2=cfg["max_accel_dps2"],
        watchdog_s=cfg["watchdog_s"],
        device_id=cfg["device_id"],
    )
    return handle, {"host": handle.host, "port": handle.port, "serial_port": ""}
