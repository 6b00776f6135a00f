"""An ACUTROL3000 on loopback TCP sockets, speaking the ACL subset of
drivers/rate_table/acutronic_protocol.py, serving axes 1-3 of which one carries the gyro (a
`TableMechanics` attached to the World; the others move on their own).

What it models (docs/rate_table_acutronic.md): the command tree with short forms and tree
position, Off / Position / Rate modes driven by the demands and the per-mode limits, the
interlock string (close = servo, open, a trip freezes "Fault" until :Interlock:Reset), the
master interlock (e-stop, all axes) told apart from an axis's door switch in its A(n)INTLK
register, the velocity trip (checked on every message), *ESR? bits in either table (IEEE 488.2,
or the ACT2000's with its "all axis profiles complete" event), :U:F and the axis scaling, the
lockout flags.  Two interfaces on one controller: the Ethernet port (every message answered,
error code and length first) and a stand-in for the GPIB bus (LF lines, queries only).  A query
that fails answers an empty field when the command is known and nothing when it is not (unknown
commands are ignored, TM-8004 table 1); CR alone ends no message; 32,768 characters execute,
longer messages are lost (TM-8004 2.5).
"""

from __future__ import annotations

import math
import time
from typing import Any

from drivers.rate_table import acutronic_protocol as ap
from drivers.rate_table import modbus_protocol as mp
from simulators.line_server import LineServer

from .ascii_server import _LinkFaults
from .fault_controls import TableFaultControls
from .mechanics import CommandRejected, TableMechanics

_MODE_LETTER = {mp.MODE_STOP: ap.MODE_OFF, mp.MODE_RATE: ap.MODE_RATE, mp.MODE_POSITION: ap.MODE_POSITION}
#: *ESR? bit of each error kind, per table (docs: "*ESR? bits"); 0: no bit (ignored silently)
_ESR_BIT = {
    "ieee488": {ap.ERR_UNKNOWN: ap.ESR_BIT5, ap.ERR_SYNTAX: ap.ESR_BIT5, ap.ERR_RANGE: ap.ESR_BIT4,
                ap.ERR_REFUSED: ap.ESR_BIT4, ap.ERR_INTERFACE: ap.ESR_BIT4, "servo": ap.ESR_BIT4},
    "act2000": {ap.ERR_UNKNOWN: 0, ap.ERR_SYNTAX: ap.ESR_BIT2, ap.ERR_RANGE: ap.ESR_BIT2,
                ap.ERR_REFUSED: ap.ESR_BIT5, ap.ERR_INTERFACE: ap.ESR_BIT2, "servo": ap.ESR_BIT0},
}  # fmt: skip
AXES = (1, 2, 3)


class _Err(Exception):
    def __init__(self, code: int, text: str, *, servo: bool = False) -> None:
        super().__init__(text)
        self.code, self.servo = code, servo


class AcutrolController:
    """The controller: parses a message, acts on the axes' mechanics, returns (error code, answer
    text or None when the message held no query)."""

    def __init__(
        self,
        world,
        mechanics: dict[int, TableMechanics],
        *,
        gyro_axis: int = 1,
        esr_table: str = "ieee488",
        idn: str = ap.IDN,
        units: str = "deg",
        full_scale_deg: float = 360.0,
        number_format: str = ap.FORMAT_FLOAT,
    ) -> None:
        if esr_table not in ap.ESR_TABLES:
            raise ValueError(f"esr_table {esr_table!r}: expected one of {ap.ESR_TABLES}")
        self.world, self.axes, self.gyro_axis = world, dict(mechanics), int(gyro_axis)
        self.mech = self.axes[self.gyro_axis]
        self.esr_table, self.idn = esr_table, idn
        self.units, self.full_scale_deg, self.number_format = units, float(full_scale_deg), number_format
        self.demand_rate_dps = {a: 0.0 for a in self.axes}
        self.demand_pos_deg = {a: 0.0 for a in self.axes}
        self.demand_acc_dps2 = {a: 0.0 for a in self.axes}
        self.limits: dict[str, dict[int, dict[str, float]]] = {"RATE": {}, "ACCELERATION": {}, "VTRIP": {}}
        for a, m in self.axes.items():
            self.limits["RATE"][a] = {mode: m.max_rate_dps for mode in ap.LIMIT_MODES} | {"O": 0.0}
            self.limits["ACCELERATION"][a] = {mode: min(100.0, m.max_accel_dps2) for mode in ap.LIMIT_MODES}
            self.limits["VTRIP"][a] = {mode: 1.1 * m.max_rate_dps for mode in ap.LIMIT_MODES}
        self.mode = {a: ap.MODE_OFF for a in self.axes}
        self.esr = 0
        self.lockout = False
        self.remote_lockout = False
        self.gpib_remote = False  # the GPIB interface in remote (any GPIB message), until :INT:IEEE488:LOC
        self._profiles_complete = True
        self._idle_sample = {a: world.sample_index for a in self.axes if a != self.gyro_axis}
        self._frames: dict[int, tuple[float, float, int, int]] = {}
        self.log: list[str] = []  # every message received (with its terminator), for the byte-exact tests

    # --- the limits of the gyro's axis, per mode letter ---------------------------------------------
    @property
    def limit_rate(self) -> dict[str, float]:
        return self.limits["RATE"][self.gyro_axis]

    @property
    def limit_acc(self) -> dict[str, float]:
        return self.limits["ACCELERATION"][self.gyro_axis]

    @property
    def limit_vtrip(self) -> dict[str, float]:
        return self.limits["VTRIP"][self.gyro_axis]

    # --- message -------------------------------------------------------------------------------
    def handle_line(self, line: str, interface: str = "tcp") -> tuple[int, str | None]:
        """One received line (with its terminator) from `interface` ("tcp" or "gpib")."""
        self.log.append(line)
        message = ap.message_text(line)
        if message is None:
            return ap.ERR_NONE, None  # lost (too long) or not a whole message
        commands = ap.split_message(message, strict=False)
        answers: list[str] = []
        error = ap.ERR_NONE
        with self.world.lock:
            self._catch_up_idle_axes()
            self._check_vtrip()
            self._profiles_event()
            if interface == "gpib":
                self.gpib_remote = True
            self._frames = {}  # the read-backs of one message come from one frame (TM-8004 4.10.3)
            for path, query, args in commands:
                try:
                    ans = self._one(path, query, args, interface)
                except CommandRejected as exc:
                    self._record(_Err(ap.ERR_REFUSED, str(exc)))
                    error = error or ap.ERR_REFUSED
                    ans = "" if query else None
                except _Err as exc:
                    self._record(exc)
                    error = error or exc.code
                    # a failed query of a known command answers empty; an unknown one nothing
                    ans = "" if query and exc.code != ap.ERR_UNKNOWN else None
                if ans is not None:
                    answers.append(ans)
        return error, (";".join(answers) if answers else None)

    def _record(self, err: _Err) -> None:
        bits = _ESR_BIT[self.esr_table]
        self.esr |= bits["servo"] if err.servo else bits[err.code]

    def _catch_up_idle_axes(self) -> None:
        """The axes without a gyro move up to the world's time (they are not World devices)."""
        now = self.world.sample_index
        for a, since in self._idle_sample.items():
            if now > since:
                self.axes[a].advance_alone(now - since, self.world.sample_period_s)
                self._idle_sample[a] = now

    def _profiles_event(self) -> None:
        """ACT2000 table bit 3: all axis profiles complete, set once per not-complete -> complete."""
        complete = all(m.settled() for m in self.axes.values())
        if complete and not self._profiles_complete and self.esr_table == "act2000":
            self.esr |= ap.ESR_BIT3
        self._profiles_complete = complete

    def _check_vtrip(self) -> None:
        """Velocity trip: an over-rate on the rate feedback shuts the axis down (TM-8004 4.6.9)."""
        for a, m in self.axes.items():
            if m.enabled and abs(m.rate_dps) > self.limits["VTRIP"][a][_MODE_LETTER[m.mode]]:
                m.inject("fault")

    # --- registers (TM-8004 appendix B) ------------------------------------------------------------
    def axis_interlock_register(self, axis: int) -> int:
        """A(n)INTLK: the master interlock (e-stop) and the door switch on INTLK1."""
        m = self.axes[axis]
        reg = ap.INTLK_MASTER if (m.estop_pressed or m.estop_latched) else 0
        return reg | (ap.INTLK_DOOR1 if m.interlock_open else 0)

    def system_interlocks(self) -> int:
        """SI: G1INTLK (axes 1-3 and the master interlock), A(n)INTLK and A(n)SWFLT per axis."""
        si = 0
        for a, m in self.axes.items():
            if self.axis_interlock_register(a):
                si |= ap.si_axis_interlock(a) | (ap.SI_G1INTLK if a <= 3 else ap.SI_G2INTLK)
            if m.fault_latched:
                si |= ap.si_axis_software_fault(a)
        return si

    # --- helpers ---------------------------------------------------------------------------------
    def _axis(self, args: list[str], n_args: int, where: str, *, first: int = 0) -> int:
        if len(args) != n_args:
            raise _Err(ap.ERR_SYNTAX, f"{where}: {len(args)} arguments, expected {n_args}")
        try:
            axis = int(args[first])
        except ValueError:
            raise _Err(ap.ERR_SYNTAX, f"{where}: axis {args[first]!r}") from None
        if axis not in self.axes:
            raise _Err(ap.ERR_RANGE, f"{where}: axis {axis} out of range")
        return axis

    @staticmethod
    def _num(text: str, where: str) -> float:
        try:
            v = float(text.replace(" ", ""))
        except ValueError:
            raise _Err(ap.ERR_SYNTAX, f"{where}: {text!r} is not a number") from None
        if not math.isfinite(v):
            raise _Err(ap.ERR_RANGE, f"{where}: {text!r} is not finite")
        return v

    def _frame(self, axis: int) -> tuple[float, float, int, int]:
        if axis not in self._frames:
            self._frames[axis] = self.axes[axis].status()
        return self._frames[axis]

    def _engage(self, a: int) -> None:
        """Re-issue axis a's mode with its demands and that mode's limits."""
        m, mode = self.axes[a], self.mode[a]
        rate_lim, acc_lim = self.limits["RATE"][a], self.limits["ACCELERATION"][a]
        if mode == ap.MODE_RATE:
            lim = rate_lim["R"]
            rate = max(-lim, min(lim, self.demand_rate_dps[a]))  # the Command Processor clamps to the limit
            m.command(mp.MODE_RATE, rate, 0.0, acc_lim["R"])
        elif mode == ap.MODE_POSITION:
            m.command(mp.MODE_POSITION, rate_lim["P"], self.demand_pos_deg[a] % 360.0, acc_lim["P"])
        else:
            m.command(mp.MODE_STOP, 0.0, 0.0, acc_lim["O"])

    # --- one command ------------------------------------------------------------------------------
    def _one(self, path: tuple[str, ...], query: bool, args: list[str], interface: str) -> str | None:
        head = path[0]
        if path == ap.BAD:
            raise _Err(ap.ERR_UNKNOWN, args[0])
        if head.startswith("*"):
            return self._common(head, query)
        sub = path[1] if len(path) > 1 else ""
        where = ":".join(path)
        if head == "READ":
            a = self._axis(args, 1, where)
            frame = self._frame(a)
            if sub == "RATE":
                return ap.format_float(frame[0])
            if sub == "POSITION":
                return ap.format_float(frame[1])
            if sub == "ACCELERATION":
                m = self.axes[a]
                return ap.format_float(m.accel_dps2 if m.ref_dps != m.rate_dps else 0.0)
            raise _Err(ap.ERR_UNKNOWN, where)
        if head == "MODE":
            return self._mode(sub, query, args, where)
        if head == "DEMAND":
            return self._demand(sub, query, args, where)
        if head == "LIMIT":
            return self._limit(sub, query, args, where)
        if head == "INTERLOCK":
            return self._interlock(sub, query, args, where)
        if head == "STATUS":
            return self._status(sub, query, args, where)
        if head == "UTILITY":
            return self._utility(sub, query, args, where, interface)
        if head == "CONFIGURE":
            a = self._axis(args, 1, where)
            if not query:
                raise _Err(ap.ERR_SYNTAX, f"{where}: only the query is simulated")
            fs = self.full_scale_deg
            return f"{ap.format_float(fs)},{ap.format_float(fs)},{ap.format_float(0.0)},{self.units}"
        if head == "QUERY":
            if not (query and len(args) == 1):
                raise _Err(ap.ERR_SYNTAX, f"{where}: takes one error code")
            code = int(self._num(args[0], where))
            return ap.ERROR_TEXT.get(code, "no error" if code == 0 else f"undefined error code {code}")
        if head == "INTERFACE":
            if sub == "IEEE488" and path[2:] == ("LOCAL",) and not query:
                self.gpib_remote = False
                return None
            raise _Err(ap.ERR_SYNTAX, f"{where}: only :Interface:IEEE488:Local is simulated")
        raise _Err(ap.ERR_UNKNOWN, where)

    def _mode(self, sub: str, query: bool, args: list[str], where: str) -> str | None:
        if query and not sub:
            a = self._axis(args, 1, where)
            return _MODE_LETTER[self.axes[a].mode]
        if not sub:  # :Mode <axis>,<mode>
            a = self._axis(args, 2, where)
            sub = ap.resolve(args[1], ("OFF", "POSITION", "RATE")) or ""
            if not sub:
                raise _Err(ap.ERR_RANGE, f"{where}: mode {args[1]!r}")
        else:
            a = self._axis(args, 1, where)
        new = {"OFF": ap.MODE_OFF, "POSITION": ap.MODE_POSITION, "RATE": ap.MODE_RATE}[sub]
        old, self.mode[a] = self.mode[a], new
        try:
            self._engage(a)
        except CommandRejected:
            self.mode[a] = old
            raise
        return None

    def _demand(self, sub: str, query: bool, args: list[str], where: str) -> str | None:
        if query:
            a = self._axis(args, 1, where)
            table = {"RATE": self.demand_rate_dps, "POSITION": self.demand_pos_deg}.get(sub, self.demand_acc_dps2)
            return ap.format_float(table[a])
        a = self._axis(args, 2, where)
        v = self._num(args[1], where)
        m = self.axes[a]
        if sub == "RATE":
            self.demand_rate_dps[a] = v
            if self.mode[a] == ap.MODE_RATE and m.mode == mp.MODE_RATE:
                self._engage(a)
        elif sub == "POSITION":
            if not 0.0 <= v < 360.0:
                raise _Err(ap.ERR_RANGE, f"{where}: {v} outside [0, 360)")
            self.demand_pos_deg[a] = v
            if self.mode[a] == ap.MODE_POSITION and m.mode == mp.MODE_POSITION:
                self._engage(a)
        else:
            self.demand_acc_dps2[a] = v  # used by the synthesis/track modes only: not modelled
        return None

    def _interlock(self, sub: str, query: bool, args: list[str], where: str) -> str | None:
        if query and not sub:
            m = self.axes[self._axis(args, 1, where)]
            if m.tripped:
                return "Fault"
            return "Close" if m.enabled else "Open"
        if sub == "RESET":
            for m in self.axes.values():  # all axes (TM-8004 4.5.6)
                m.fault_reset()
            return None
        a = self._axis(args, 1, where)
        if sub == "CLOSE":
            try:
                self.axes[a].set_enabled(True)
            except CommandRejected as exc:
                raise _Err(ap.ERR_REFUSED, str(exc), servo=True) from None
        elif sub == "OPEN":
            self.axes[a].set_enabled(False)
        else:
            raise _Err(ap.ERR_UNKNOWN, where)
        self.mode[a] = ap.MODE_OFF
        return None

    def _status(self, sub: str, query: bool, args: list[str], where: str) -> str:
        if not (query and sub == "CSR" and len(args) == 1):
            raise _Err(ap.ERR_SYNTAX, f"{where} {args}: only :Status:CSR? <register> is simulated")
        reg = args[0].upper()
        if reg == "SI":
            return str(self.system_interlocks())
        for a, m in self.axes.items():
            if reg == f"A{a}INTLK":
                return str(self.axis_interlock_register(a))
            if reg in (f"A{a}SWFLT", f"A{a}SWFAULT"):
                return str(2 if m.fault_latched else 0)  # bit 1: maximum rate fault (the velocity trip)
        raise _Err(ap.ERR_RANGE, f"{where}: register {args[0]!r} is not simulated")

    def _utility(self, sub: str, query: bool, args: list[str], where: str, interface: str) -> str | None:
        if sub == "FORMAT":
            if query:
                return self.number_format
            if interface != "gpib":  # "can only be issued by an IEEE-488 interface controller-in-charge" (4.14.1)
                raise _Err(ap.ERR_INTERFACE, f"{where}: only from the IEEE-488 controller in charge")
            fmt = ap.resolve(args[0], (ap.FORMAT_BINARY, ap.FORMAT_FLOAT)) if len(args) == 1 else None
            if fmt is None:
                raise _Err(ap.ERR_RANGE, f"{where}: expected BINary or FLOat")
            self.number_format = fmt
            return None
        attr = "lockout" if sub == "LOCKOUT" else "remote_lockout"
        if query:
            return "ON" if getattr(self, attr) else "OFF"
        if len(args) != 1 or args[0].upper() not in ("ON", "OFF"):
            raise _Err(ap.ERR_RANGE, f"{where}: expected ON or OFF")
        setattr(self, attr, args[0].upper() == "ON")
        return None

    def _limit(self, sub: str, query: bool, args: list[str], where: str) -> str | None:
        table = self.limits["VTRIP" if sub == "VELOCITYTRIP" else sub]
        n = 2 if query else 3
        a = self._axis(args, n, where, first=1)
        mode = args[0].upper()[:1]
        if mode not in ap.LIMIT_MODES:
            raise _Err(ap.ERR_RANGE, f"{where}: mode {args[0]!r}")
        if query:
            return ap.format_float(table[a][mode])
        v = self._num(args[2], where)
        m = self.axes[a]
        hi = m.max_accel_dps2 if sub == "ACCELERATION" else m.max_rate_dps if sub == "RATE" else 2.0 * m.max_rate_dps
        if not 0.0 < v <= hi:
            raise _Err(ap.ERR_RANGE, f"{where}: {v} outside (0, {hi}]")
        if sub == "RATE" and mode == "O":
            return None  # forced to zero in Off mode (TM-8004 4.6.8)
        table[a][mode] = v
        if mode == self.mode[a] and (m.enabled or mode == ap.MODE_OFF):
            self._engage(a)  # a live limit: the running profile takes it at once
        return None

    def _common(self, head: str, query: bool) -> str | None:
        if head == "*IDN" and query:
            return self.idn
        if head == "*ESR" and query:
            esr, self.esr = self.esr, 0
            return str(esr)
        if head == "*STB" and query:
            stb = (1 if any(m.tripped for m in self.axes.values()) else 0) | (32 if self.esr else 0)
            return str(stb | (64 if stb else 0))
        if head == "*CLS" and not query:
            self.esr = 0
            return None
        if head == "*OPC" and query:
            return "1"
        if head == "*RST" and not query:
            for a, m in self.axes.items():
                m.set_enabled(False)
                self.mode[a] = ap.MODE_OFF
            return None
        raise _Err(ap.ERR_UNKNOWN, head)


class AcutrolTableServer(TableFaultControls):
    """Handle of a running simulated Acutrol: `.host`, `.port` (the Ethernet port, tcp framing),
    `.resource_name` (the same port as a VISA socket), `.gpib_standin_resource` (a socket standing
    in for the GPIB bus: gpib framing, LF lines), `.controller`, `.mechanics` (the gyro's axis),
    `.inject(kind, axis=...)`, `.corrupt_replies(kind)`, `.stop()`."""

    def __init__(self, world, controller: AcutrolController, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.world, self.controller = world, controller
        self.mechanics = controller.mech
        self.link_faults = _LinkFaults()
        self._late_s = 0.0
        max_line = ap.MAX_MESSAGE_CHARS + 2  # the message, a CR and its LF (TM-8004 2.5)
        self._tcp = LineServer(lambda line: self._reply(line, "tcp"), host, port, name="acutrol-tcp",
                               max_line=max_line, drop_long_lines=True)  # fmt: skip
        self._gpib = LineServer(lambda line: self._reply(line, "gpib"), host, 0, name="acutrol-gpib-standin",
                                max_line=max_line, drop_long_lines=True)  # fmt: skip
        self.host, self.port = self._tcp.host, self._tcp.port
        self.gpib_port = self._gpib.port

    @property
    def resource_name(self) -> str:
        """The Ethernet port as a VISA socket resource (pyvisa-py): tcp framing."""
        return self._tcp.resource_name

    @property
    def gpib_standin_resource(self) -> str:
        """A VISA socket resource STANDING IN for the GPIB bus (pyvisa-py has no GPIB without
        gpib-ctypes or linux-gpib): the controller answers it in the gpib framing."""
        return self._gpib.resource_name

    def inject(self, kind: str, code: int | None = None, *, axis: int | None = None) -> None:
        """Kind "estop" (the master interlock: every axis), or "fault" / "interlock" (a door) on `axis`
        (default: the gyro's)."""
        with self.world.lock:
            targets = self.controller.axes.values() if kind == "estop" else [self._mech(axis)]
            for m in targets:
                m.inject(kind, code)

    def clear(self, kind: str, *, axis: int | None = None) -> None:
        with self.world.lock:
            targets = self.controller.axes.values() if kind == "estop" else [self._mech(axis)]
            for m in targets:
                m.clear(kind)

    def _mech(self, axis: int | None) -> TableMechanics:
        return self.controller.axes[self.controller.gyro_axis if axis is None else int(axis)]

    def delay_next_reply(self, wall_s: float) -> None:
        """The next answer goes out `wall_s` late (a late reply the driver must not mistake for
        the answer to its next request)."""
        self._late_s = float(wall_s)

    def _reply(self, line: str, interface: str) -> bytes | None:
        code, text = self.controller.handle_line(line, interface)
        if interface == "gpib":
            if text is None:
                return None  # IEEE-488: only a message with a query is answered
            data = ap.gpib_answer(text)
        elif ap.message_text(line) is None:
            return None  # a lost message is not answered
        else:
            data = ap.tcp_answer(code, text if text is not None else (ap.COMMAND_OK if code == ap.ERR_NONE else ""))
        late, self._late_s = self._late_s, 0.0
        if late > 0:
            time.sleep(late)
        return self._spoil(data)

    def _spoil(self, data: bytes) -> bytes | None:
        """The link faults a test asked for: "short" (half the bytes), "garbage", "drop"."""
        with self.link_faults.lock:
            if self.link_faults.count <= 0:
                return data
            self.link_faults.count -= 1
            kind = self.link_faults.kind
        if kind == "short":
            return data[: max(1, len(data) // 2)]
        if kind == "garbage":
            return b"\x7f#?" + data[::-1]
        return None

    def stop(self) -> None:
        self._tcp.stop()
        self._gpib.stop()
        with self.world.lock:
            self.world.detach(self.mechanics)

    def __enter__(self) -> AcutrolTableServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def serve_acutrol_table(
    world,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    mechanics: TableMechanics | None = None,
    gyro_axis: int = 1,
    esr_table: str = "ieee488",
    idn: str = ap.IDN,
    units: str = "deg",
    full_scale_deg: float = 360.0,
    number_format: str = ap.FORMAT_FLOAT,
    **mechanics_kw,
) -> AcutrolTableServer:
    """Axes 1-3: the gyro's a TableMechanics attached to the World (no host watchdog: ACL has
    none), the others alike but moving on their own; served on TCP and on the GPIB stand-in."""
    mechanics_kw.setdefault("watchdog_s", 0.0)
    axes: dict[int, TableMechanics] = {}
    for a in sorted({*AXES, gyro_axis}):
        if a == gyro_axis and mechanics is not None:
            axes[a] = mechanics
        else:
            seed = world.seed if a == gyro_axis else 1000 * int(world.seed or 0) + 100 + a
            axes[a] = TableMechanics(seed=seed, **mechanics_kw)
    with world.lock:
        world.attach(axes[gyro_axis])
    controller = AcutrolController(
        world, axes, gyro_axis=gyro_axis, esr_table=esr_table, idn=idn, units=units,
        full_scale_deg=full_scale_deg, number_format=number_format,
    )  # fmt: skip
    return AcutrolTableServer(world, controller, host=host, port=port)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[AcutrolTableServer, dict[str, Any]]:
    """A simulated station's `acutrol-table`: served from its station keys; (handle, driver address keys)."""
    handle = serve_acutrol_table(
        world, gyro_axis=cfg["axis"], max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"]
    )
    return handle, {"host": handle.host, "port": handle.port, "visa_resource": "", "framing": "auto"}
