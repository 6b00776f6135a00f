"""The ASCII rate-table controller on loopback (TCP, or a pty for the serial path), backed by a
`TableMechanics` attached to the World.  Command set: drivers/rate_table/ascii_protocol.py."""

from __future__ import annotations

import math
import os
import pty
import select
import threading
import tty
from typing import Any

from drivers.rate_table import ascii_protocol as ap
from drivers.rate_table import modbus_protocol as mp
from simulators.line_server import LineServer

from .fault_controls import TableFaultControls
from .mechanics import CommandRejected, TableMechanics


class _Reject(Exception):
    def __init__(self, code: int, text: str) -> None:
        super().__init__(text)
        self.code, self.text = code, text


class AsciiController:
    """Parses one line and executes it on the mechanics; returns the reply line (no LF)."""

    def __init__(self, world, mech: TableMechanics) -> None:
        self.world, self.mech = world, mech
        self.rate_dps = 0.0
        self.pos_deg = 0.0
        self.spd_dps = 10.0
        self.acc_dps2 = mech.accel_dps2

    def handle_line(self, line: str) -> str:
        cmds = [c.strip() for c in line.strip().split(";") if c.strip()]
        if not cmds:
            return f'ERR {ap.ERR_COMMAND},"empty line"'
        if cmds == [ap.CMD_HB]:
            self.mech.feed()  # the heartbeat does not wait for the world
            return "OK"
        answers: list[str] = []
        with self.world.lock:
            for cmd in cmds:
                try:
                    ans = self._one(cmd)
                except _Reject as exc:
                    return f'ERR {exc.code},"{exc.text}"'
                except CommandRejected as exc:
                    code = ap.ERR_OUT_OF_RANGE if exc.bad_value else ap.ERR_SETTINGS_CONFLICT
                    return f'ERR {code},"{exc}"'
                if ans is not None:
                    answers.append(ans)
        return ";".join(answers) if answers else "OK"

    @staticmethod
    def _number(mnemonic: str, arg: str) -> float:
        try:
            v = float(arg)
        except ValueError:
            raise _Reject(ap.ERR_DATA_TYPE, f"{mnemonic} needs a number, got {arg!r}") from None
        if not math.isfinite(v):
            raise _Reject(ap.ERR_OUT_OF_RANGE, f"{mnemonic} {arg} is not finite")
        return v

    def _engage(self, mode: int) -> None:
        rate = self.spd_dps if mode == mp.MODE_POSITION else self.rate_dps
        self.mech.command(mode, rate, self.pos_deg, self.acc_dps2)

    def _one(self, cmd: str) -> str | None:
        m = self.mech
        head, _, arg = cmd.partition(" ")
        head, arg = head.upper(), arg.strip()
        if head.endswith("?"):
            if head == ap.Q_STAT:
                return ap.format_status(*m.status())
            if head == ap.Q_IDN:
                return ap.IDN
            if head == ap.Q_MODE:
                return ap.MODE_BY_NUMBER[m.mode]
            if head == ap.Q_WDT:
                return f"{m.watchdog_s:g}"
            raise _Reject(ap.ERR_COMMAND, f"unknown query {head}")
        m.feed()
        if head == "*RST":
            m.set_enabled(False)
        elif head == ap.CMD_HB:
            pass
        elif head == ap.CMD_STOP:
            m.command(mp.MODE_STOP, 0.0, 0.0, self.acc_dps2)
        elif head == ap.CMD_FRST:
            m.fault_reset()
        elif head == ap.CMD_ENA:
            if arg not in ("0", "1"):
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"ENA {arg!r}: expected 0 or 1")
            m.set_enabled(arg == "1")
        elif head == ap.CMD_MODE:
            if arg.upper() not in ap.MODE_NAMES:
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"MODE {arg!r}: expected RATE, POS or STOP")
            self._engage(ap.MODE_NAMES[arg.upper()])
        elif head == ap.CMD_RATE:
            v = self._number(head, arg)
            if abs(v) > m.max_rate_dps:
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"RATE {v} beyond +/-{m.max_rate_dps}")
            self.rate_dps = v
            if m.mode == mp.MODE_RATE:
                self._engage(mp.MODE_RATE)
        elif head == ap.CMD_POS:
            v = self._number(head, arg)
            if not 0.0 <= v < 360.0:
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"POS {v} outside [0, 360)")
            self.pos_deg = v
        elif head == ap.CMD_SPD:
            v = self._number(head, arg)
            if not 0.0 < v <= m.max_rate_dps:
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"SPD {v} outside (0, {m.max_rate_dps}]")
            self.spd_dps = v
        elif head == ap.CMD_ACC:
            v = self._number(head, arg)
            if not 0.0 < v <= m.max_accel_dps2:
                raise _Reject(ap.ERR_OUT_OF_RANGE, f"ACC {v} outside (0, {m.max_accel_dps2}]")
            self.acc_dps2 = v
            if m.mode == mp.MODE_RATE:
                self._engage(mp.MODE_RATE)
        elif head == ap.CMD_WDT:
            m.set_watchdog_s(self._number(head, arg))
        else:
            raise _Reject(ap.ERR_COMMAND, f"unknown command {head}")
        return None


class _LinkFaults:
    """Reply corruption for the tests: "short" (half a line), "garbage", "drop"."""

    def __init__(self) -> None:
        self.kind, self.count, self.lock = "", 0, threading.Lock()

    def apply(self, reply: str) -> str | None:
        with self.lock:
            if self.count <= 0:
                return reply
            self.count -= 1
            kind = self.kind
        if kind == "short":
            return reply[: max(1, len(reply) // 2)]
        if kind == "garbage":
            return "\x7f#?" + reply[::-1]
        return None


class AsciiTableServer(TableFaultControls):
    """Handle of a running ASCII table: `.host`, `.port` (TCP) or `.url` (pty path or socket://),
    `.mechanics`, `.inject(kind)`, `.stop()`."""

    def __init__(self, world, mechanics: TableMechanics, *, host: str = "127.0.0.1", port: int = 0, use_pty=False):
        self.world, self.mechanics = world, mechanics
        self.controller = AsciiController(world, mechanics)
        self.link_faults = _LinkFaults()
        self._stop = threading.Event()
        self.host: str | None = None
        self.port: int | None = None
        if use_pty:
            self._master, slave = pty.openpty()
            tty.setraw(slave)
            self.pty_path = os.ttyname(slave)
            self._slave = slave
            self._thread = threading.Thread(target=self._serve_pty, name="ascii-table-pty", daemon=True)
            self._tcp = None
            self._thread.start()
        else:
            self._tcp = LineServer(self._reply, host, port, name="ascii-table", max_line=4096)
            self.host, self.port = self._tcp.host, self._tcp.port

    @property
    def url(self) -> str:
        return self.pty_path if self._tcp is None else f"socket://{self.host}:{self.port}"

    def _reply(self, line: str) -> bytes | None:
        reply = self.link_faults.apply(self.controller.handle_line(line))
        return None if reply is None else (reply + ap.TERMINATOR).encode("ascii", "replace")

    def _serve_pty(self) -> None:
        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.05)
            if not ready:
                continue
            try:
                buf += os.read(self._master, 4096)
            except OSError:
                return
            while b"\n" in buf:
                raw, _, buf = buf.partition(b"\n")
                out = self._reply(raw.decode("ascii", "replace"))
                if out is not None:
                    os.write(self._master, out)

    def stop(self) -> None:
        self._stop.set()
        if self._tcp is not None:
            self._tcp.stop()
        else:
            self._thread.join(timeout=5.0)
            for fd in (self._master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
        with self.world.lock:
            self.world.detach(self.mechanics)

    def __enter__(self) -> AsciiTableServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def serve_ascii_table(
    world,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    use_pty: bool = False,
    mechanics: TableMechanics | None = None,
    **mechanics_kw,
) -> AsciiTableServer:
    """Attach a TableMechanics to the world and serve the ASCII controller (TCP port 0: any)."""
    mech = mechanics if mechanics is not None else TableMechanics(seed=world.seed, **mechanics_kw)
    with world.lock:
        world.attach(mech)
    return AsciiTableServer(world, mech, host=host, port=port, use_pty=use_pty)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[AsciiTableServer, dict[str, Any]]:
    """A simulated station's `ascii-table`: served from its station keys; (handle, driver address keys)."""
    handle = serve_ascii_table(
        world, max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"], watchdog_s=cfg["watchdog_s"]
    )
    return handle, {"url": handle.url}
