"""Rate table with an ASCII controller, over TCP or a serial line through pyserial.

`url_or_host`: "host:port" or "socket://host:port" (TCP), or anything pyserial opens (a device
path, a pty).  One reply line per request line; stale input is flushed before each request so a
late reply cannot be taken for the next one.  Queries retry on a timeout or a malformed reply;
setting lines retry only when idempotent (enable, disable, stop, watchdog, heartbeat).
"""

from __future__ import annotations

import threading

import serial

from drivers.errors import DeviceError, LinkLostError, ProtocolError

from . import ascii_protocol as ap
from .base import DEFAULT_POLL_S, RateTable, TableLimits, TableStatus
from .heartbeat import Heartbeat
from .modbus_protocol import (
    ST_AT_RATE,
    ST_ENABLED,
    ST_ESTOP,
    ST_FAULT,
    ST_IN_POSITION,
    ST_INTERLOCK_OPEN,
    ST_WATCHDOG_EXPIRED,
)


def _to_url(url_or_host: str) -> str:
    if "://" in url_or_host or url_or_host.startswith("/"):
        return url_or_host
    return f"socket://{url_or_host}"


class AsciiRateTable(RateTable):
    """An ASCII-command rate-table controller (command set in ascii_protocol)."""

    def __init__(
        self,
        url_or_host: str,
        *,
        limits: TableLimits,
        clock,
        baudrate: int = 115200,
        timeout_s: float = 1.0,
        read_retries: int = 2,
        watchdog_s: float = 2.0,
        heartbeat_s: float | None = None,
        poll_s: float = DEFAULT_POLL_S,
    ) -> None:
        super().__init__(limits=limits, clock=clock, poll_s=poll_s)
        self.url = _to_url(url_or_host)
        self.baudrate, self.timeout_s = baudrate, float(timeout_s)
        self.read_retries = int(read_retries)
        self.watchdog_s = float(watchdog_s)
        self._ser: serial.SerialBase | None = None
        self._io_lock = threading.Lock()
        self.heartbeat = Heartbeat(self._beat, heartbeat_s if heartbeat_s else max(0.05, self.watchdog_s / 8))

    # --- link ----------------------------------------------------------------------------------
    def connect(self) -> None:
        try:
            self._ser = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=self.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkLostError(f"rate table: cannot open {self.url}: {exc}") from exc
        idn = self._query(ap.Q_IDN)
        if not idn:
            raise ProtocolError(f"rate table at {self.url}: empty *IDN? reply")
        self._send(f"{ap.CMD_WDT} {self.watchdog_s:g}", idempotent=True)
        self.heartbeat.start()

    def close(self) -> None:
        self.heartbeat.stop()
        if self._ser is not None:
            self._ser.close()
            self._ser = None

    def _beat(self) -> None:
        self._send(ap.CMD_HB, idempotent=True)

    def _transact(self, line: str) -> str:
        """One request line, one reply line (wall-clock timeout); LinkLostError if none."""
        if self._ser is None:
            raise LinkLostError("rate table: not connected")
        with self._io_lock:
            try:
                self._ser.reset_input_buffer()
                self._ser.write((line + ap.TERMINATOR).encode("ascii"))
                raw = self._ser.read_until(b"\n")
                extra = raw.endswith(b"\n") and self._ser.in_waiting > 0
                if extra:
                    self._ser.reset_input_buffer()
            except (serial.SerialException, OSError) as exc:
                raise LinkLostError(f"rate table at {self.url}: link error on {line!r}: {exc}") from exc
        if extra:
            # one request, one reply line: more input means a stray or stale line came first, and
            # the line read may answer another request
            raise ProtocolError(f"rate table at {self.url}: more than one reply line to {line!r} (got {raw!r} first)")
        if not raw.endswith(b"\n"):
            raise LinkLostError(f"rate table: no reply to {line!r} within {self.timeout_s} s (got {raw!r})")
        try:
            return raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ProtocolError(f"rate table: non-ASCII reply {raw!r} to {line!r}") from None

    def _checked(self, line: str, attempts: int) -> str:
        last: Exception | None = None
        for _ in range(max(1, attempts)):
            try:
                reply = self._transact(line)
            except (LinkLostError, ProtocolError) as exc:
                last = exc
                continue
            err = ap.parse_error(reply)
            if err is not None:
                raise DeviceError(f"rate table refused {line!r}: error {err[0]} {err[1]}")
            return reply
        raise last if last is not None else LinkLostError(line)

    def _send(self, line: str, *, idempotent: bool) -> None:
        reply = self._checked(line, 1 + (self.read_retries if idempotent else 0))
        if reply != "OK":
            raise ProtocolError(f"rate table: expected OK to {line!r}, got {reply!r}")
        self.heartbeat.note_write()

    def _query(self, line: str) -> str:
        return self._checked(line, 1 + self.read_retries)

    # --- commands ------------------------------------------------------------------------------
    def enable(self) -> None:
        self._send(f"{ap.CMD_ENA} 1", idempotent=True)

    def disable(self) -> None:
        self._send(f"{ap.CMD_ENA} 0", idempotent=True)

    def fault_reset(self) -> None:
        self._send(ap.CMD_FRST, idempotent=False)

    def _write_rate(self, rate_dps: float, accel_dps2: float) -> None:
        self._send(f"ACC {accel_dps2:.6g};RATE {rate_dps:.9g};MODE RATE", idempotent=False)

    def _write_move(self, angle_deg: float, rate_dps: float, accel_dps2: float) -> None:
        self._send(f"ACC {accel_dps2:.6g};SPD {rate_dps:.9g};POS {angle_deg:.9g};MODE POS", idempotent=False)

    def _write_stop(self, accel_dps2: float) -> None:
        self._send(f"ACC {accel_dps2:.6g};STOP", idempotent=True)

    # --- read-back -----------------------------------------------------------------------------
    def status(self) -> TableStatus:
        """One STAT? query: rate, angle, status bits, fault code."""
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            reply = self._query(ap.Q_STAT)
            try:
                rate, angle, bits, code = ap.parse_status(reply)
            except ValueError as exc:
                last = exc
                continue
            return TableStatus(
                rate_dps=rate,
                angle_deg=angle,
                enabled=bool(bits & ST_ENABLED),
                at_rate=bool(bits & ST_AT_RATE),
                in_position=bool(bits & ST_IN_POSITION),
                fault=bool(bits & ST_FAULT),
                estop=bool(bits & ST_ESTOP),
                interlock_open=bool(bits & ST_INTERLOCK_OPEN),
                watchdog_expired=bool(bits & ST_WATCHDOG_EXPIRED),
                fault_code=code,
            )
        raise ProtocolError(f"rate table: malformed STAT? reply ({last})")
