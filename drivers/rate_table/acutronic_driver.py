"""Acutronic ACUTROL3000/3000e table controller, one axis, speaking ACL (TM-8004) over Ethernet
TCP (port 9878) or over GPIB through a VISA resource (docs/rate_table_acutronic.md).

The answers come in the framing of the link (acutronic_protocol, "answer framing"): on TCP every message is answered
with an error code and a length before the text, commands with `OK`; on GPIB only queries answer,
so a command message ends in `*ESR?`, whose error bits (2, 4, 5 only) turn a refusal into a
DeviceError.  At connect the driver sets and checks ASCII numbers (`:U:F F`) and the axis's units
(degrees only); on close it releases the lockout (and, on GPIB, the interface) to local.  Queries
retry on a timeout or a malformed reply; commands retry only when idempotent.  The controller has
no host watchdog in ACL: a bench that dies leaves the table at its last demand (see the doc).
"""

from __future__ import annotations

import threading

from drivers.errors import DeviceError, LinkLostError, ProtocolError

from . import acutronic_protocol as ap
from .acutronic_links import AclLink, SocketBytes, VisaBytes
from .base import DEFAULT_POLL_S, RateTable, TableLimits, TableStatus

#: |rate - demand| within which the driver reports `at_rate` (deg/s)
AT_RATE_TOL_DPS = 0.05
#: |angle - target| within which the driver reports `in_position` once at rest (deg)
IN_POSITION_TOL_DEG = 0.005


class AcutrolRateTable(RateTable):
    """One axis of an ACUTROL3000 over TCP (`host`, `port`) or a VISA `resource` (through
    `visa_library` when given); `framing` is "auto" (GPIB resources speak lines, sockets the TCP
    header), "tcp" or "gpib"."""

    def __init__(
        self,
        host: str = "",
        port: int = ap.TCP_PORT,
        *,
        resource: str = "",
        framing: str = "auto",
        visa_library: str = "",
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
        self.resource = resource
        self.where = resource or f"{host}:{port}"
        self.framing = ap.framing_for(resource, framing)
        self.vtrip_dps = float(vtrip_dps) if vtrip_dps else 1.1 * limits.max_rate_dps
        self.lockout = bool(lockout)
        self.timeout_s = float(timeout_s)
        self.read_retries = int(read_retries)
        lines = self.framing == "gpib"
        if resource:
            io: VisaBytes | SocketBytes = VisaBytes(resource, timeout_s, lines=lines, visa_library=visa_library)
        else:
            io = SocketBytes(host, port, timeout_s)
        self._link = AclLink(io, self.framing, timeout_s)
        self._io_lock = threading.Lock()
        self._connected = False
        self.idn = ""
        self.units = ""

    # --- link ------------------------------------------------------------------------------------
    def connect(self) -> None:
        try:
            self._link.open()
        except Exception as exc:  # OSError, ValueError, and pyvisa's own errors for a bad resource name
            raise LinkLostError(f"rate table: cannot open {self.where}: {exc}") from exc
        self._connected = True
        try:
            self.idn = self._query("*IDN?")
            if "ACUTROL" not in self.idn.upper():
                raise ProtocolError(f"rate table at {self.where}: *IDN? answered {self.idn!r}, not an Acutrol")
            self._send("*CLS", idempotent=True)
            self._set_ascii_numbers()
            self._check_units()
            if self.lockout:
                self._send(ap.lockout(True), idempotent=True)
            self.write_limits()
        except Exception:
            self._connected = False
            self._link.close()
            raise

    def _set_ascii_numbers(self) -> None:
        """`:U:F F` and read it back: every number the driver parses is ASCII (TM-8004 4.14.1).  The
        manual lets only the IEEE-488 controller in charge set the format, so on TCP a refusal is
        accepted as long as the format already reads FLOAT."""
        try:
            self._send(ap.SET_FORMAT_FLOAT, idempotent=True)
        except DeviceError:
            if self.framing == "gpib":
                raise
        answer = self._query(ap.FORMAT_QUERY).strip().upper()
        if answer != ap.FORMAT_FLOAT:
            raise DeviceError(
                f"rate table at {self.where}: numbers are in {answer or '?'} format (:U:F? answered {answer!r}) "
                f"and gyrobench reads ASCII (FLOAT) only; set ':U:F F' from the GPIB controller or the "
                f"Acutrol GUI (TM-8004 4.14.1)"
            )

    def _check_units(self) -> None:
        """The axis's engineering unit and full scale (:Configure:Scaling?, TM-8004 4.2.26): the
        driver's numbers are degrees over a 360 deg turn, anything else is refused."""
        answer = self._query(ap.scaling_query(self.axis))
        try:
            full_scale, units = ap.parse_scaling(answer)
        except ValueError as exc:
            raise ProtocolError(f"rate table at {self.where}: {exc}") from None
        self.units = units
        if units.upper() not in ap.DEGREE_UNITS or abs(full_scale - 360.0) > 1e-6:
            raise DeviceError(
                f"rate table at {self.where}: axis {self.axis} is scaled in {units!r} over a full scale of "
                f"{full_scale:g} (:Configure:Scaling? answered {answer!r}); gyrobench commands and reads "
                f"degrees over 360 deg: set the axis's scaling to 360,...,deg in the controller's set-up"
            )

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
        """Release the controller to local: the lockout off, and on GPIB the interface to local
        (TM-8004 4.4.2, and the bus's go-to-local, 5.2.3), then close the link."""
        if self._connected:
            release = [ap.lockout(False)] if self.lockout else []
            if self.framing == "gpib":
                release.append(ap.IEEE488_LOCAL)
            for command in release:
                try:
                    self._send(command, idempotent=True)
                except (DeviceError, LinkLostError):
                    pass
            self._go_to_local()
        self._connected = False
        self._link.close()

    def _go_to_local(self) -> None:
        """The GPIB bus's go-to-local for this device (a VISA GPIB resource only)."""
        if not self.resource.upper().startswith("GPIB"):
            return
        try:
            import pyvisa

            inst = self._link.io.instrument
            if inst is not None:
                inst.control_ren(pyvisa.constants.RENLineOperation.address_gtl)
        except Exception:  # a VISA without the call: the ACL command above did the same
            pass

    def _transact(self, line: str) -> tuple[int, str]:
        """One message, its answer (error code, text); LinkLostError if none, ProtocolError if not an answer."""
        if not self._connected:
            raise LinkLostError("rate table: not connected")
        try:
            ap.message_bytes(line)
        except ValueError as exc:
            raise ProtocolError(f"rate table: not sent, the controller would lose it: {exc}") from None
        with self._io_lock:
            try:
                return self._link.transact(line)
            except OSError as exc:
                raise LinkLostError(f"rate table: no answer to {line!r} within {self.timeout_s} s: {exc}") from exc
            except (ValueError, UnicodeDecodeError) as exc:
                raise ProtocolError(f"rate table: bad answer to {line!r}: {exc}") from None

    def _query(self, line: str) -> str:
        """A query's text; retried on a lost or malformed answer; DeviceError when the controller
        refuses it (tcp: a non-zero error code)."""
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            try:
                code, text = self._transact(line)
            except (LinkLostError, ProtocolError) as exc:
                last = exc
                continue
            if code != ap.ERR_NONE:
                raise DeviceError(f"rate table refused {line!r}: {self._error_text(code)}")
            return text
        raise last if last is not None else LinkLostError(line)

    def _send(self, command: str, *, idempotent: bool) -> None:
        """A command message; DeviceError when the controller refused it.  tcp: the answer's error
        code (and `OK`); gpib: `*ESR?` appended, its error bits."""
        line = ap.with_esr(command) if self.framing == "gpib" else command
        last: Exception | None = None
        for _ in range(1 + (self.read_retries if idempotent else 0)):
            try:
                code, text = self._transact(line)
            except (LinkLostError, ProtocolError) as exc:
                last = exc
                continue
            if self.framing == "tcp":
                if code != ap.ERR_NONE:
                    raise DeviceError(f"rate table refused {command!r}: {self._error_text(code)}")
                if text != ap.COMMAND_OK:
                    last = ProtocolError(f"rate table: {command!r} answered {text!r}, not {ap.COMMAND_OK!r}")
                    continue
                return
            try:
                esr = ap.parse_esr(text)
            except ValueError as exc:
                last = ProtocolError(f"rate table: bad *ESR? answer to {command!r}: {exc}")
                continue
            if esr & ap.ESR_ERRORS:
                raise DeviceError(f"rate table refused {command!r}: {ap.esr_text(esr)}")
            return
        raise last if last is not None else LinkLostError(command)

    def _error_text(self, code: int) -> str:
        """`error code N: <the controller's words>` (:Query:Error?, TM-8004 4.9.1), or just the code."""
        try:
            words_code, words = self._transact(ap.query_error(code))
        except (LinkLostError, ProtocolError):
            return f"error code {code}"
        return f"error code {code}: {words}" if words_code == ap.ERR_NONE and words else f"error code {code}"

    # --- commands --------------------------------------------------------------------------------
    def enable(self) -> None:
        """Close the interlock and check it reads Close: a failed servo attempt is a *ESR? bit only
        in the ACT2000 table (bit 0), which the driver does not raise on."""
        self._send(ap.interlock_close(self.axis), idempotent=True)
        state = ap.parse_interlock(self._query(f":INT? {self.axis}"))
        if state != "Close":
            raise DeviceError(f"rate table refused {ap.interlock_close(self.axis)!r}: the interlock reads {state}")

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
        try:
            return float(self._query(ap.read_acceleration(self.axis)))
        except ValueError:
            raise ProtocolError(f"rate table: {ap.read_acceleration(self.axis)!r} answered no number") from None

    def status(self) -> TableStatus:
        """Rate, position, interlock, mode and the interlock registers from one message."""
        last: Exception | None = None
        for _ in range(1 + self.read_retries):
            reply = self._query(ap.status_query(self.axis))
            try:
                rate, angle, intlk, mode, si, axis_intlk = ap.parse_status(reply)
            except ValueError as exc:
                last = exc
                continue
            return self._to_status(rate, angle, intlk, mode, si, axis_intlk)
        raise ProtocolError(f"rate table: malformed status reply ({last})")

    def _to_status(self, rate: float, angle: float, intlk: str, mode: str, si: int, axis_intlk: int) -> TableStatus:
        angle %= 360.0
        estop, door, fault = ap.axis_conditions(self.axis, si, axis_intlk)
        fault = fault or (intlk == "Fault" and not (estop or door))
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
