"""Rate table over Modbus (TCP, or RTU on a serial line) with pymodbus's sync client.

Reads retry on timeout or a bad reply; writes are retried only when idempotent (enable,
disable, stop, watchdog settings, heartbeat), never a motion command or a fault reset.
Modbus exception responses become DeviceError naming the exception; a lost, reset or silent
link becomes LinkLostError naming the table's address.
"""

from __future__ import annotations

import select
import struct
import threading
import time

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusIOException

from drivers.errors import DeviceError, LinkLostError, ProtocolError

from . import modbus_protocol as mp
from .base import DEFAULT_POLL_S, RateTable, TableLimits, TableStatus
from .heartbeat import Heartbeat


class ModbusRateTable(RateTable):
    """A Modbus rate-table controller (register map in modbus_protocol)."""

    def __init__(
        self,
        host: str | None = None,
        port: int = 502,
        *,
        limits: TableLimits,
        clock,
        device_id: int = 1,
        timeout_s: float = 1.0,
        read_retries: int = 2,
        watchdog_s: float = 2.0,
        heartbeat_s: float | None = None,
        poll_s: float = DEFAULT_POLL_S,
        client=None,
    ) -> None:
        super().__init__(limits=limits, clock=clock, poll_s=poll_s)
        if client is None:
            if host is None:
                raise ValueError("ModbusRateTable needs host= (TCP) or use ModbusRateTable.rtu(port)")
            client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0)
        self.client = client
        self.address = _address_of(client)
        self.device_id = device_id
        self.read_retries = int(read_retries)
        self.watchdog_s = float(watchdog_s)
        self._io_lock = threading.Lock()
        self.heartbeat = Heartbeat(self._beat, heartbeat_s if heartbeat_s else max(0.05, self.watchdog_s / 8))
        self._beat_count = 0
        self._rx: _ReceivedBytes | None = None  # RTU: what a transaction received, to spot extra frames
        self._line_dirty = False  # RTU: the last transaction failed, a late reply may still come
        self.timeout_s = float(timeout_s)
        self._probe_tid = 0  # transaction id of probe_status's own requests (TCP)

    @classmethod
    def rtu(
        cls,
        port: str,
        *,
        limits: TableLimits,
        clock,
        device_id: int = 1,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        **kw,
    ) -> ModbusRateTable:
        """RTU framing on a serial port: a device path, a pty, or a pyserial URL (`socket://h:p`)."""
        rx = _ReceivedBytes()
        client = ModbusSerialClient(
            port, framer=FramerType.RTU, baudrate=baudrate, timeout=timeout_s, retries=0, trace_packet=rx
        )
        table = cls(limits=limits, clock=clock, device_id=device_id, client=client, **kw)
        table._rx = rx
        return table

    # --- link ----------------------------------------------------------------------------------
    def connect(self) -> None:
        try:
            connected = self.client.connect()
        except OSError as exc:
            raise LinkLostError(f"rate table at {self.address}: cannot connect ({exc!r})") from exc
        if not connected:
            raise LinkLostError(f"rate table at {self.address}: cannot connect")
        try:
            self._write(mp.HR_WATCHDOG_MS, [int(round(self.watchdog_s * 1000))], idempotent=True)
        except Exception:
            self.client.close()
            raise
        self.heartbeat.start()

    def close(self) -> None:
        self.heartbeat.stop()
        self.client.close()

    def _beat(self) -> None:
        self._beat_count = (self._beat_count + 1) & 0xFFFF
        self._write(mp.HR_HEARTBEAT, [self._beat_count], idempotent=True)

    def _call(self, what: str, fn, *, attempts: int, fc: int):
        """One transaction of function `fc` (with the I/O lock), retried `attempts - 1` times on a
        lost reply, a reply of another function, or (RTU) one that came with extra bytes."""
        last: Exception | None = None
        for _ in range(max(1, attempts)):
            try:
                with self._io_lock:
                    if self._rx is not None:
                        self._rx.n_bytes = 0
                        if self._line_dirty:  # a reply that missed its timeout may still be coming
                            _drain_until_quiet(self.client, quiet_s=self.timeout_s, most_s=3.0 * self.timeout_s)
                        else:
                            _flush_input(self.client)  # what is left of an earlier, spoiled reply
                        self._line_dirty = True  # until this transaction gives a valid reply
                    rr = fn()
                    received = self._rx.n_bytes + _waiting(self.client) if self._rx is not None else 0
            except (ModbusIOException, ConnectionException, OSError) as exc:
                # OSError: the peer reset or closed the connection mid-transaction
                last = exc
                continue
            if (rr.function_code & 0x7F) != fc:
                last = ProtocolError(f"reply of function {rr.function_code & 0x7F}, not {fc}")
                continue
            if self._rx is not None and received > _rtu_reply_bytes(rr):
                # no transaction id on a serial line: a frame that came with another may be a
                # stale reply to an earlier request, so neither can be trusted
                last = ProtocolError(f"{received} bytes came for a {_rtu_reply_bytes(rr)}-byte reply")
                continue
            self._line_dirty = False
            if rr.isError():
                code = getattr(rr, "exception_code", None)
                name = mp.EXCEPTION_NAMES.get(code, "unknown")
                raise DeviceError(
                    f"rate table at {self.address} (unit {self.device_id}) refused {what}: "
                    f"Modbus exception {code} ({name})"
                )
            return rr
        raise LinkLostError(
            f"rate table at {self.address} (unit {self.device_id}): no valid reply to {what} ({last!r})"
        )

    def _write(self, address: int, values: list[int], *, idempotent: bool) -> None:
        self._call(
            f"write of {values} at register {address}",
            lambda: self.client.write_registers(address, values, device_id=self.device_id),
            attempts=1 + (self.read_retries if idempotent else 0),
            fc=16,
        )
        self.heartbeat.note_write()

    # --- commands ------------------------------------------------------------------------------
    def enable(self) -> None:
        self._write(mp.HR_ENABLE, [1], idempotent=True)

    def disable(self) -> None:
        self._write(mp.HR_ENABLE, [0], idempotent=True)

    def fault_reset(self) -> None:
        self._write(mp.HR_FAULT_RESET, [1], idempotent=False)

    def _write_rate(self, rate_dps: float, accel_dps2: float) -> None:
        self._write(mp.HR_MODE, mp.encode_command(mp.MODE_RATE, rate_dps, 0.0, accel_dps2), idempotent=False)

    def _write_move(self, angle_deg: float, rate_dps: float, accel_dps2: float) -> None:
        block = mp.encode_command(mp.MODE_POSITION, rate_dps, angle_deg, accel_dps2)
        self._write(mp.HR_MODE, block, idempotent=False)

    def _write_stop(self, accel_dps2: float) -> None:
        self._write(mp.HR_MODE, mp.encode_command(mp.MODE_STOP, 0.0, 0.0, accel_dps2), idempotent=True)

    # --- read-back -----------------------------------------------------------------------------
    def status(self) -> TableStatus:
        """One FC4 read of 6 input registers: rate, angle, status bits, fault code."""
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            rr = self._call(
                "status read",
                lambda: self.client.read_input_registers(mp.IR_RATE_ACT, count=mp.IR_COUNT, device_id=self.device_id),
                attempts=1 + self.read_retries,
                fc=4,
            )
            try:
                return self._status_from(rr.registers)
            except ValueError as exc:
                last = exc
        raise ProtocolError(f"rate table at {self.address}: malformed status reply ({last})")

    def probe_status(self) -> TableStatus:
        """status() for the station's link check at every lockstep grid point and the waits'
        polls (`poll_status`), without pymodbus's per-call bookkeeping: the same MBAP frame and
        FC4 read on the client's own socket, its reply checked field by field (transaction id,
        unit, function, byte count).  Anything else (no reply within timeout_s, a short, foreign
        or late reply, RTU) goes to status(), with its retries and errors, on a fresh connection
        so a late reply is never taken for the next one."""
        sock = getattr(self.client, "socket", None)
        if self._rx is not None or sock is None or not isinstance(self.client, ModbusTcpClient):
            return self.status()
        with self._io_lock:
            self._probe_tid = self._probe_tid % 0xFFFF + 1
            tid = self._probe_tid
            try:
                sock.sendall(_FC4_REQUEST.pack(tid, 0, 6, self.device_id, 4, mp.IR_RATE_ACT, mp.IR_COUNT))
                reply = _read_reply(sock, time.monotonic() + self.timeout_s)
            except OSError:
                reply = None
            if reply is not None and _MBAP.unpack_from(reply)[:4] == (tid, 0, len(reply) - 6, self.device_id):
                fc, n_bytes = reply[7], reply[8]
                if fc == 4 and n_bytes == 2 * mp.IR_COUNT:
                    try:
                        return self._status_from(_STATUS_REGS.unpack_from(reply, 9))
                    except ValueError:
                        pass  # status() reads again and names what is malformed
                elif fc == 0x84:
                    raise DeviceError(
                        f"rate table at {self.address} (unit {self.device_id}) refused status read: "
                        f"Modbus exception {n_bytes} ({mp.EXCEPTION_NAMES.get(n_bytes, 'unknown')})"
                    )
            self.client.close()  # pymodbus connects again at the next transaction
        return self.status()

    poll_status = probe_status

    def _status_from(self, registers) -> TableStatus:
        rate, angle, bits, code = mp.decode_status(registers)
        return TableStatus(
            rate_dps=rate,
            angle_deg=angle,
            enabled=bool(bits & mp.ST_ENABLED),
            at_rate=bool(bits & mp.ST_AT_RATE),
            in_position=bool(bits & mp.ST_IN_POSITION),
            fault=bool(bits & mp.ST_FAULT),
            estop=bool(bits & mp.ST_ESTOP),
            interlock_open=bool(bits & mp.ST_INTERLOCK_OPEN),
            watchdog_expired=bool(bits & mp.ST_WATCHDOG_EXPIRED),
            fault_code=code,
        )


#: MBAP header (transaction id, protocol 0, length, unit) + FC4 request (address, count)
_FC4_REQUEST = struct.Struct(">HHHBBHH")
_MBAP = struct.Struct(">HHHBB")  # + function code
_STATUS_REPLY_BYTES = _MBAP.size + 1 + 2 * mp.IR_COUNT  # MBAP, fc, byte count, 6 registers
_STATUS_REGS = struct.Struct(f">{mp.IR_COUNT}H")


def _read_reply(sock, deadline: float) -> bytes | None:
    """One Modbus TCP reply to the FC4 status read (or an exception reply) from a socket, None
    when the deadline passes first or the peer closed the connection."""
    data = b""
    want = _STATUS_REPLY_BYTES
    while len(data) < want:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([sock], [], [], left)[0]:
            return None
        piece = sock.recv(want - len(data))
        if not piece:
            return None
        data += piece
        if len(data) >= 8 and data[7] & 0x80:
            want = 9  # an exception reply: MBAP, fc | 0x80, exception code
    return data


class _ReceivedBytes:
    """pymodbus trace_packet hook: the size of the receive buffer a transaction decoded from."""

    def __init__(self) -> None:
        self.n_bytes = 0

    def __call__(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self.n_bytes = len(data)
        return data


def _flush_input(client) -> None:
    """Discard whatever a serial client's input holds (pymodbus reads only what in_waiting says,
    and pyserial's socket:// says at most 1)."""
    try:
        client.socket.reset_input_buffer()
    except (AttributeError, OSError):
        pass


def _drain_until_quiet(client, *, quiet_s: float, most_s: float) -> None:
    """Discard a serial client's input until it has been silent for quiet_s (at most most_s in
    all): on RTU, with no transaction id, a reply that missed its timeout must be gone before
    the retry goes out, or it is taken for (or spoils) the retry's reply."""
    start = last_byte = time.monotonic()
    while (now := time.monotonic()) - last_byte < quiet_s and now - start < most_s:
        n = _waiting(client)
        if n > 0:
            try:
                client.socket.read(n)
            except (AttributeError, OSError):
                return
            last_byte = time.monotonic()
        else:
            time.sleep(min(0.002, quiet_s))


def _waiting(client) -> int:
    """Bytes (pyserial's socket:// says 0 or 1) already in a serial client's input, 0 if unknown."""
    try:
        return int(client.socket.in_waiting)
    except (AttributeError, OSError, ValueError, TypeError):
        return 0


def _rtu_reply_bytes(rr) -> int:
    """RTU frame size of a decoded reply: address, PDU, CRC."""
    if rr.isError():
        return 5
    if rr.function_code in (3, 4):
        return 5 + 2 * len(rr.registers)
    return 8  # FC6 / FC16 echo


def _address_of(client) -> str:
    """host:port of a TCP client, the port (device path or URL) of a serial one."""
    params = getattr(client, "comm_params", None)
    host = getattr(params, "host", None)
    port = getattr(params, "port", None)
    if host and port:  # a serial client's port is 0
        return f"{host}:{port}"
    return str(host or port or client)
