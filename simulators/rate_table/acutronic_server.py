"""An ACUTROL3000 on a loopback TCP socket, speaking the ACL subset of
drivers/rate_table/acutronic_protocol.py and backed by a `TableMechanics` attached to the World.

What it models (docs/rate_table_acutronic.md): the command tree with short forms and tree
position, Off / Position / Rate modes driven by the demands and the per-mode limits, the
interlock string (close = servo, open, a trip freezes "Fault" until :Interlock:Reset), the
velocity trip (checked on every message), *ESR? error bits, the lockout flag, and the answers
of one message joined by ';'.  A command message without a query gets no answer (GPIB style).
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


class _Err(Exception):
    def __init__(self, bit: int, text: str) -> None:
        super().__init__(text)
        self.bit = bit


class AcutrolController:
    """One axis of the controller: parses a message, acts on the mechanics, returns the answer line
    (None when the message had no query)."""

    def __init__(self, world, mech: TableMechanics, *, axes: int = 1) -> None:
        self.world, self.mech, self.axes = world, mech, axes
        self.demand_rate_dps = 0.0
        self.demand_pos_deg = 0.0
        self.demand_acc_dps2 = 0.0
        default_acc = min(100.0, mech.max_accel_dps2)
        self.limit_rate = {m: mech.max_rate_dps for m in ap.LIMIT_MODES}
        self.limit_rate["O"] = 0.0
        self.limit_acc = {m: default_acc for m in ap.LIMIT_MODES}
        self.limit_vtrip = {m: 1.1 * mech.max_rate_dps for m in ap.LIMIT_MODES}
        self.mode = ap.MODE_OFF
        self.esr = 0
        self.lockout = False
        self.remote_lockout = False
        self._frame: tuple[float, float, int, int] | None = None
        self.log: list[str] = []  # every message received, for the byte-exact tests

    # --- message -------------------------------------------------------------------------------
    def handle_line(self, line: str) -> str | None:
        self.log.append(line)
        commands = ap.split_message(line, strict=False)
        answers: list[str] = []
        with self.world.lock:
            self._check_vtrip()
            self._frame = None  # the read-backs of one message come from one frame (TM-8004 4.10.3)
            for path, query, args in commands:
                try:
                    ans = self._one(path, query, args)
                except _Err as exc:
                    self.esr |= exc.bit
                    ans = None
                    if query:  # a failed query still answers, so the host is not left waiting
                        ans = ""
                except CommandRejected:
                    self.esr |= ap.ESR_EXECUTION_ERROR
                    ans = "" if query else None
                if ans is not None:
                    answers.append(ans)
        return ";".join(answers) if answers else None

    def _check_vtrip(self) -> None:
        """Velocity trip: an over-rate on the rate feedback shuts the axis down (TM-8004 4.6.9)."""
        m = self.mech
        if m.enabled and abs(m.rate_dps) > self.limit_vtrip[_MODE_LETTER[m.mode]]:
            m.inject("fault")

    # --- helpers ---------------------------------------------------------------------------------
    def _axis(self, args: list[str], n_args: int, where: str, *, first: int = 0) -> int:
        if len(args) != n_args:
            raise _Err(ap.ESR_COMMAND_ERROR, f"{where}: {len(args)} arguments, expected {n_args}")
        try:
            axis = int(args[first])
        except ValueError:
            raise _Err(ap.ESR_COMMAND_ERROR, f"{where}: axis {args[first]!r}") from None
        if not 1 <= axis <= self.axes:
            raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: axis {axis} out of range")
        return axis

    @staticmethod
    def _num(text: str, where: str) -> float:
        try:
            v = float(text.replace(" ", ""))
        except ValueError:
            raise _Err(ap.ESR_COMMAND_ERROR, f"{where}: {text!r} is not a number") from None
        if not math.isfinite(v):
            raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: {text!r} is not finite")
        return v

    def _engage(self) -> None:
        """Re-issue the current mode with the current demands and that mode's limits."""
        m = self.mech
        if self.mode == ap.MODE_RATE:
            lim = self.limit_rate["R"]
            rate = max(-lim, min(lim, self.demand_rate_dps))  # the Command Processor clamps to the limit
            m.command(mp.MODE_RATE, rate, 0.0, self.limit_acc["R"])
        elif self.mode == ap.MODE_POSITION:
            m.command(mp.MODE_POSITION, self.limit_rate["P"], self.demand_pos_deg % 360.0, self.limit_acc["P"])
        else:
            m.command(mp.MODE_STOP, 0.0, 0.0, self.limit_acc["O"])

    # --- one command ------------------------------------------------------------------------------
    def _one(self, path: tuple[str, ...], query: bool, args: list[str]) -> str | None:
        m = self.mech
        head = path[0]
        if path == ap.BAD:
            raise _Err(ap.ESR_COMMAND_ERROR, args[0])
        if head.startswith("*"):
            return self._common(head, query)
        sub = path[1] if len(path) > 1 else ""
        where = ":".join(path)
        if head == "READ":
            self._axis(args, 1, where)
            if self._frame is None:
                self._frame = m.status()
            if sub == "RATE":
                return ap.format_float(self._frame[0])
            if sub == "POSITION":
                return ap.format_float(self._frame[1])
            if sub == "ACCELERATION":
                return ap.format_float(m.accel_dps2 if m.ref_dps != m.rate_dps else 0.0)
            raise _Err(ap.ESR_COMMAND_ERROR, where)
        if head == "MODE":
            if query and not sub:
                self._axis(args, 1, where)
                return _MODE_LETTER[m.mode]
            if not sub:  # :Mode <axis>,<mode>
                self._axis(args, 2, where)
                sub = ap.resolve(args[1], ("OFF", "POSITION", "RATE")) or ""
                if not sub:
                    raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: mode {args[1]!r}")
            else:
                self._axis(args, 1, where)
            new = {"OFF": ap.MODE_OFF, "POSITION": ap.MODE_POSITION, "RATE": ap.MODE_RATE}[sub]
            old, self.mode = self.mode, new
            try:
                self._engage()
            except CommandRejected:
                self.mode = old
                raise
            return None
        if head == "DEMAND":
            if query:
                self._axis(args, 1, where)
                v = {"RATE": self.demand_rate_dps, "POSITION": self.demand_pos_deg}.get(sub, self.demand_acc_dps2)
                return ap.format_float(v)
            self._axis(args, 2, where)
            v = self._num(args[1], where)
            if sub == "RATE":
                self.demand_rate_dps = v
                if self.mode == ap.MODE_RATE and m.mode == mp.MODE_RATE:
                    self._engage()
            elif sub == "POSITION":
                if not 0.0 <= v < 360.0:
                    raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: {v} outside [0, 360)")
                self.demand_pos_deg = v
                if self.mode == ap.MODE_POSITION and m.mode == mp.MODE_POSITION:
                    self._engage()
            else:
                self.demand_acc_dps2 = v  # used by the synthesis/track modes only: not modelled
            return None
        if head == "LIMIT":
            return self._limit(sub, query, args, where)
        if head == "INTERLOCK":
            if query and not sub:
                self._axis(args, 1, where)
                if m.tripped:
                    return "Fault"
                return "Close" if m.enabled else "Open"
            if sub == "RESET":
                m.fault_reset()
                return None
            self._axis(args, 1, where)
            if sub == "CLOSE":
                m.set_enabled(True)
                self.mode = ap.MODE_OFF
            elif sub == "OPEN":
                m.set_enabled(False)
                self.mode = ap.MODE_OFF
            else:
                raise _Err(ap.ESR_COMMAND_ERROR, where)
            return None
        if head == "STATUS":
            if not (query and sub == "CSR" and args and args[0].upper() == "SI"):
                raise _Err(ap.ESR_COMMAND_ERROR, f"{where} {args}: only :Status:CSR? SI is simulated")
            si = 0
            if m.estop_pressed or m.estop_latched:
                si |= ap.SI_GLOBAL1
            if m.interlock_open:
                si |= ap.SI_AXIS1_HW
            if m.fault_latched:
                si |= ap.SI_AXIS1_SW
            return str(si)
        if head == "UTILITY":
            attr = "lockout" if sub == "LOCKOUT" else "remote_lockout"
            if query:
                return "ON" if getattr(self, attr) else "OFF"
            if len(args) != 1 or args[0].upper() not in ("ON", "OFF"):
                raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: expected ON or OFF")
            setattr(self, attr, args[0].upper() == "ON")
            return None
        raise _Err(ap.ESR_COMMAND_ERROR, where)

    def _limit(self, sub: str, query: bool, args: list[str], where: str) -> str | None:
        table = {"RATE": self.limit_rate, "ACCELERATION": self.limit_acc}.get(sub, self.limit_vtrip)
        n = 2 if query else 3
        self._axis(args, n, where, first=1)
        mode = args[0].upper()[:1]
        if mode not in ap.LIMIT_MODES:
            raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: mode {args[0]!r}")
        if query:
            return ap.format_float(table[mode])
        v = self._num(args[2], where)
        m = self.mech
        hi = m.max_accel_dps2 if sub == "ACCELERATION" else 2.0 * m.max_rate_dps if sub != "RATE" else m.max_rate_dps
        if not 0.0 < v <= hi:
            raise _Err(ap.ESR_EXECUTION_ERROR, f"{where}: {v} outside (0, {hi}]")
        if sub == "RATE" and mode == "O":
            return None  # forced to zero in Off mode (TM-8004 4.6.8)
        table[mode] = v
        if mode == self.mode and (m.enabled or mode == ap.MODE_OFF):
            self._engage()  # a live limit: the running profile takes it at once
        return None

    def _common(self, head: str, query: bool) -> str | None:
        if head == "*IDN" and query:
            return ap.IDN
        if head == "*ESR" and query:
            esr, self.esr = self.esr, 0
            return str(esr)
        if head == "*STB" and query:
            m = self.mech
            stb = (1 if m.tripped else 0) | (32 if self.esr else 0)
            return str(stb | (64 if stb else 0))
        if head == "*CLS" and not query:
            self.esr = 0
            return None
        if head == "*OPC":
            if query:
                return "1"
            self.esr |= ap.ESR_OPC
            return None
        if head == "*RST" and not query:
            self.mech.set_enabled(False)
            self.mode = ap.MODE_OFF
            return None
        raise _Err(ap.ESR_COMMAND_ERROR, head)


class AcutrolTableServer(TableFaultControls):
    """Handle of a running simulated Acutrol: `.host`, `.port`, `.controller`, `.mechanics`,
    `.inject(kind)`, `.corrupt_replies(kind)`, `.stop()`."""

    def __init__(self, world, mechanics: TableMechanics, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.world, self.mechanics = world, mechanics
        self.controller = AcutrolController(world, mechanics)
        self.link_faults = _LinkFaults()
        self._late_s = 0.0
        self._server = LineServer(self._reply, host, port, name="acutrol-table")
        self.host, self.port = self._server.host, self._server.port

    @property
    def resource_name(self) -> str:
        """The same socket as a VISA resource (pyvisa-py), for the GPIB-style path."""
        return self._server.resource_name

    def delay_next_reply(self, wall_s: float) -> None:
        """The next answer goes out `wall_s` late (a late reply the driver must not mistake for
        the answer to its next request)."""
        self._late_s = float(wall_s)

    def _reply(self, line: str) -> bytes | None:
        answer = self.controller.handle_line(line)
        if answer is None:
            return None
        late, self._late_s = self._late_s, 0.0
        if late > 0:
            time.sleep(late)
        answer = self.link_faults.apply(answer)
        return None if answer is None else (answer + ap.TERMINATOR).encode("ascii", "replace")

    def stop(self) -> None:
        self._server.stop()
        with self.world.lock:
            self.world.detach(self.mechanics)

    def __enter__(self) -> AcutrolTableServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def serve_acutrol_table(
    world, *, host: str = "127.0.0.1", port: int = 0, mechanics: TableMechanics | None = None, **mechanics_kw
) -> AcutrolTableServer:
    """Attach a TableMechanics (no host watchdog: ACL has none) and serve the controller on TCP."""
    mechanics_kw.setdefault("watchdog_s", 0.0)
    mech = mechanics if mechanics is not None else TableMechanics(seed=world.seed, **mechanics_kw)
    with world.lock:
        world.attach(mech)
    return AcutrolTableServer(world, mech, host=host, port=port)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[AcutrolTableServer, dict[str, Any]]:
    """A simulated station's `acutrol-table`: served from its station keys; (handle, driver address keys)."""
    handle = serve_acutrol_table(world, max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    return handle, {"host": handle.host, "port": handle.port, "visa_resource": ""}
