"""Acutronic ACUTROL3000/3000e table controller, one axis, speaking ACL (TM-8004) over Ethernet
TCP (port 9878) or over GPIB through a VISA resource (docs/rate_table_acutronic.md).

Every message the driver sends answers with exactly one line: queries answer themselves and a
command message ends in `*ESR?`, whose error bits turn a refused command into a DeviceError.
Stale input is flushed before each request; queries retry on a timeout or a malformed reply;
commands retry only when idempotent (interlock close/open, the stop).  The controller has no
host watchdog in ACL: a bench that dies leaves the table at its last demand (see the doc).
"""

from __future__ import annotations

import socket
import threading
import time

from drivers.errors import DeviceError, LinkLostError, ProtocolError

from . import acutronic_protocol as ap
from .base import DEFAULT_POLL_S, RateTable, TableLimits, TableStatus

#: |rate - demand| within which the driver reports `at_rate` (deg/s)
AT_RATE_TOL_DPS = 0.05
#: |angle - target| within which the driver reports `in_position` once at rest (deg)
IN_POSITION_TOL_DEG = 0.005


class _TcpLink:
    """One TCP connection, LF-terminated lines."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        self.host, self.port, self.timeout_s = host, int(port), float(timeout_s)
        self._sock: socket.socket | None = None
        self._buf = b""

    def open(self) -> None:
        self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _flush(self) -> None:
        self._buf = b""
        assert self._sock is not None
        self._sock.setblocking(False)
        try:
            while self._sock.recv(65536):
                pass
        except (BlockingIOError, InterruptedError):
            pass
        finally:
            self._sock.settimeout(self.timeout_s)

    def transact(self, line: str) -> bytes:
        if self._sock is None:
            raise OSError("not connected")
        self._flush()
        self._sock.sendall((line + ap.TERMINATOR).encode("ascii"))
        deadline = time.monotonic() + self.timeout_s
        while b"\n" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                return self._buf
            self._sock.settimeout(left)
            try:
                chunk = self._sock.recv(65536)
            except TimeoutError:
                return self._buf
            if not chunk:
                raise OSError("connection closed by the controller")
            self._buf += chunk
        raw, _, self._buf = self._buf.partition(b"\n")
        return raw + b"\n"


class _VisaLink:
    """A VISA resource (GPIB0::1::INSTR, or TCPIP::host::9878::SOCKET) through pyvisa."""

    def __init__(self, resource: str, timeout_s: float) -> None:
        self.resource, self.timeout_s = resource, float(timeout_s)
        self._inst = None
        self._stale = False  # a reply timed out: it may still arrive, drain it before the next request

    def open(self) -> None:
        import pyvisa

        rm = pyvisa.ResourceManager("@py") if "::SOCKET" in self.resource.upper() else pyvisa.ResourceManager()
        inst = rm.open_resource(self.resource)
        inst.timeout = int(self.timeout_s * 1000)
        inst.read_termination = ap.TERMINATOR
        inst.write_termination = ap.TERMINATOR
        self._inst = inst

    def close(self) -> None:
        if self._inst is not None:
            self._inst.close()
            self._inst = None

    def transact(self, line: str) -> bytes:
        import pyvisa

        if self._inst is None:
            raise OSError("not connected")
        try:
            if self._stale:
                self._drain()
            self._inst.write(line)
            return self._inst.read_raw()
        except pyvisa.errors.VisaIOError as exc:
            if exc.error_code == pyvisa.constants.StatusCode.error_timeout:
                self._stale = True
                return b""
            raise OSError(str(exc)) from exc

    def _drain(self) -> None:
        """Read and drop whatever a late reply left, with a short timeout, so it is not taken for
        the answer to the next request."""
        import pyvisa

        inst, keep = self._inst, self._inst.timeout
        inst.timeout = 50
        try:
            while True:
                inst.read_raw()
        except pyvisa.errors.VisaIOError:
            pass
        finally:
            inst.timeout = keep
            self._stale = False


class AcutrolRateTable(RateTable):
    """One axis of an ACUTROL3000 over TCP (`host`, `port`) or a VISA `resource`."""

    def __init__(
        self,
        host: str = "",
        port: int = ap.TCP_PORT,
        *,
        resource: str = "",
        axis: int = 1,
        limits: TableLimits,
        clock,
        vtrip_dps: float | None = None,
        lockout: bool = True,
        timeout_s: float = 1.0,
        read_retries: int = 2,
        poll_s: float = DEFAULT_POLL_S,
    ) -> None:
        super().__init__(limits=limits, clock=clock, poll_s=poll_s)
        if not (host or resource):
            raise ValueError("AcutrolRateTable needs a host (TCP) or a VISA resource")
        self.axis = int(axis)
        self.where = resource or f"{host}:{port}"
        self.vtrip_dps = float(vtrip_dps) if vtrip_dps else 1.1 * limits.max_rate_dps
        self.lockout = bool(lockout)
        self.timeout_s = float(timeout_s)
        self.read_retries = int(read_retries)
        self._link = _VisaLink(resource, timeout_s) if resource else _TcpLink(host, port, timeout_s)
        self._io_lock = threading.Lock()
        self._connected = False
        self.idn = ""

    # --- link ------------------------------------------------------------------------------------
    def connect(self) -> None:
        try:
            self._link.open()
        except (OSError, ValueError) as exc:
            raise LinkLostError(f"rate table: cannot open {self.where}: {exc}") from exc
        except Exception as exc:  # pyvisa raises its own errors for a bad resource name
            raise LinkLostError(f"rate table: cannot open {self.where}: {exc}") from exc
        self._connected = True
        try:
            self.idn = self._query("*IDN?")
            if "ACUTROL" not in self.idn.upper():
                raise ProtocolError(f"rate table at {self.where}: *IDN? answered {self.idn!r}, not an Acutrol")
            self._send("*CLS", idempotent=True)
            if self.lockout:
                self._send(ap.lockout(True), idempotent=True)
            self.write_limits()
        except Exception:
            self._connected = False
            self._link.close()
            raise

    def write_limits(self) -> None:
        """The station's rate and acceleration limits into every mode the driver uses, and the
        velocity trip above the rate limit: the controller then enforces them too."""
        a, lim = self.axis, self.limits
        cmds = []
        for mode in ap.LIMIT_MODES:
            if mode != "O":  # the Off mode's rate limit is forced to zero (TM-8004 4.6.8)
                cmds.append(ap.limit_rate(mode, a, lim.max_rate_dps))
            cmds.append(ap.limit_acceleration(mode, a, lim.max_accel_dps2))
            cmds.append(ap.limit_vtrip(mode, a, self.vtrip_dps))
        self._send(";".join(cmds), idempotent=True)

    def close(self) -> None:
        if self._connected and self.lockout:
            try:
                self._send(ap.lockout(False), idempotent=True)
            except (DeviceError, LinkLostError):
                pass
        self._connected = False
        self._link.close()

    def _transact(self, line: str) -> str:
        """One message, one reply line (wall-clock timeout); LinkLostError if none."""
        if not self._connected:
            raise LinkLostError("rate table: not connected")
        with self._io_lock:
            try:
                raw = self._link.transact(line)
            except OSError as exc:
                raise LinkLostError(f"rate table: link error on {line!r}: {exc}") from exc
        if not raw.endswith(b"\n"):
            raise LinkLostError(f"rate table: no reply to {line!r} within {self.timeout_s} s (got {raw!r})")
        try:
            return raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise ProtocolError(f"rate table: non-ASCII reply {raw!r} to {line!r}") from None

    def _query(self, line: str) -> str:
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            try:
                return self._transact(line)
            except (LinkLostError, ProtocolError) as exc:
                last = exc
        raise last if last is not None else LinkLostError(line)

    def _send(self, command: str, *, idempotent: bool) -> None:
        """A command message with `*ESR?` appended; DeviceError when an error bit comes back."""
        line = ap.with_esr(command)
        last: Exception | None = None
        for _ in range(1 + (self.read_retries if idempotent else 0)):
            try:
                esr = ap.parse_esr(self._transact(line))
            except (LinkLostError, ProtocolError) as exc:
                last = exc
                continue
            except ValueError as exc:
                last = ProtocolError(f"rate table: bad *ESR? answer to {command!r}: {exc}")
                continue
            if esr & ap.ESR_ERRORS:
                raise DeviceError(f"rate table refused {command!r}: {ap.esr_text(esr)}")
            return
        raise last if last is not None else LinkLostError(command)

    # --- commands --------------------------------------------------------------------------------
    def enable(self) -> None:
        self._send(ap.interlock_close(self.axis), idempotent=True)

    def disable(self) -> None:
        self._send(ap.interlock_open(self.axis), idempotent=True)

    def fault_reset(self) -> None:
        self._send(ap.INTERLOCK_RESET, idempotent=False)

    def _write_rate(self, rate_dps: float, accel_dps2: float) -> None:
        a = self.axis
        self._send(
            f"{ap.limit_acceleration('R', a, accel_dps2)};{ap.demand_rate(a, rate_dps)};{ap.mode_rate(a)}",
            idempotent=False,
        )

    def _write_move(self, angle_deg: float, rate_dps: float, accel_dps2: float) -> None:
        a = self.axis
        self._send(
            f"{ap.limit_rate('P', a, rate_dps)};{ap.limit_acceleration('P', a, accel_dps2)};"
            f"{ap.demand_position(a, angle_deg)};{ap.mode_position(a)}",
            idempotent=False,
        )

    def _write_stop(self, accel_dps2: float) -> None:
        a = self.axis
        self._send(f"{ap.limit_acceleration('O', a, accel_dps2)};{ap.mode_off(a)}", idempotent=True)

    # --- read-back -------------------------------------------------------------------------------
    def read_acceleration(self) -> float:
        """Acceleration feedback (deg/s^2)."""
        return float(self._query(ap.read_acceleration(self.axis)))

    def status(self) -> TableStatus:
        """Rate, position, interlock, mode and the interlock register from one message."""
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            reply = self._query(ap.status_query(self.axis))
            try:
                rate, angle, intlk, mode, si = ap.parse_status(reply)
            except ValueError as exc:
                last = exc
                continue
            return self._to_status(rate, angle, intlk, mode, si)
        raise ProtocolError(f"rate table: malformed status reply ({last})")

    def _to_status(self, rate: float, angle: float, intlk: str, mode: str, si: int) -> TableStatus:
        angle %= 360.0
        estop = bool(si & ap.SI_GLOBAL1)
        door = bool(si & ap.SI_AXIS1_HW)
        fault = bool(si & ap.SI_AXIS1_SW) or (intlk == "Fault" and not (estop or door))
        enabled = intlk == "Close"
        code = 1 if estop else 3 if door else 2 if fault else 0  # the fault codes of modbus_protocol
        at_rate = enabled and mode == ap.MODE_RATE and abs(rate - self.commanded_rate_dps) <= AT_RATE_TOL_DPS
        target = self.commanded_angle_deg
        in_position = (
            enabled
            and mode == ap.MODE_POSITION
            and target is not None
            and abs((angle - target + 180.0) % 360.0 - 180.0) <= IN_POSITION_TOL_DEG
            and abs(rate) <= AT_RATE_TOL_DPS
        )
        return TableStatus(
            rate_dps=rate,
            angle_deg=angle,
            enabled=enabled,
            at_rate=at_rate,
            in_position=in_position,
            fault=fault,
            estop=estop,
            interlock_open=door,
            watchdog_expired=False,
            fault_code=code,
        )
