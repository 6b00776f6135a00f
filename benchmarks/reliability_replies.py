"""Malformed device replies against every driver: the audit count of issue 13 ("95 malformed
device replies").  Each case is a scripted loopback device (Modbus TCP, Modbus RTU over a
`socket://` serial URL, the ASCII table, the SCPI front end, the FPGA link) that answers like the
real one except for the replies to one request kind, which it mangles once (the driver may retry
and recover) or every time.  A case is clean when the driver either returns the true value or
raises a named driver error (drivers.errors), within its deadline, and a follow-up read (good
replies again) returns its true value or a named error, never a value of another request.
Usage: python benchmarks/reliability_replies.py [-v]   (prints one line per case with -v)"""

from __future__ import annotations

import math
import random
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench.clock import SimClock
from drivers.errors import DeviceError, LinkLostError, ProtocolError
from drivers.fpga import protocol as fp
from drivers.fpga.link import FpgaLink
from drivers.frontend import ScpiFrontEnd
from drivers.rate_table import AsciiRateTable, ModbusRateTable, TableLimits
from drivers.rate_table import ascii_protocol as ap
from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import ResonatorParams
from simulators.world import World

NAMED = (DeviceError, LinkLostError, ProtocolError)
TIMEOUT_S = 0.3  # every driver's wall-clock timeout here (the SCPI front end's deadline: 0.5 s)
LIMITS = TableLimits(max_rate_dps=500.0, max_accel_dps2=300.0)
RATE, ANGLE, BITS = 12.5, 30.0, mp.ST_ENABLED | mp.ST_AT_RATE
RNG = random.Random(13)

# --- a scripted loopback device -----------------------------------------------------------------
# an action: ("send", bytes) | ("drip", bytes, seconds a byte) | ("sleep", s) | ("close",) | ("reset",)
Actions = list[tuple]


class ScriptedDevice:
    """A TCP device: `split(buf)` cuts one request off the input (or None), `good(req)` is the
    true reply, and the replies to requests where `target(req)` holds are `mangle(req, good)`
    (the first `count` of them)."""

    def __init__(self, split, good, target, mangle, count: int) -> None:
        self.split, self.good, self.target, self.mangle, self.count = split, good, target, mangle, count
        self.stop = threading.Event()
        self.srv = socket.socket()
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen()
        self.srv.settimeout(0.05)
        self.port = self.srv.getsockname()[1]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.srv.accept()
            except OSError:
                continue
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(0.05)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = b""
        try:
            while not self.stop.is_set():
                try:
                    data = conn.recv(65536)
                except TimeoutError:
                    continue
                if not data:
                    return
                buf += data
                while (cut := self.split(buf)) is not None:
                    req, buf = cut
                    good = self.good(req)
                    actions: Actions = [("send", good)] if good else []
                    if self.target(req) and self.count > 0:
                        self.count -= 1
                        actions = self.mangle(req, good)
                    if not self._perform(conn, actions):
                        return
        except OSError:
            return
        finally:
            conn.close()

    def _perform(self, conn: socket.socket, actions: Actions) -> bool:
        for act in actions:
            if act[0] == "send":
                conn.sendall(act[1])
            elif act[0] == "drip":
                for b in act[1]:
                    if self.stop.wait(act[2]):
                        return False
                    conn.sendall(bytes([b]))
            elif act[0] == "sleep":
                if self.stop.wait(act[1]):
                    return False
            elif act[0] == "reset":
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                return False
            elif act[0] == "close":
                return False
        return True

    def close(self) -> None:
        self.stop.set()
        self.srv.close()


# --- generic mangles --------------------------------------------------------------------------------
def send(b: bytes) -> Actions:
    return [("send", b)]


def garbage(n: int) -> bytes:
    return bytes(RNG.randrange(256) for _ in range(n))


COMMON: dict[str, Callable[[bytes, bytes], Actions]] = {
    "truncated": lambda r, g: send(g[: len(g) // 2]),
    "truncated-1": lambda r, g: send(g[:-1]),
    "garbage": lambda r, g: send(garbage(len(g))),
    "garbage-prefix": lambda r, g: send(garbage(7) + g),
    "silence": lambda r, g: [],
    "dripped": lambda r, g: [("drip", g, TIMEOUT_S * 0.8)],
    "dripped-0.4s": lambda r, g: [("drip", g, 0.4)],
    "oversize": lambda r, g: send(g + garbage(4096)),
    "duplicate": lambda r, g: send(g + g),
    "close": lambda r, g: [("close",)],
    "reset": lambda r, g: [("reset",)],
    "late": lambda r, g: [("sleep", TIMEOUT_S * 1.5), ("send", g)],
    "bit-flip": lambda r, g: send(g[:-3] + bytes([g[-3] ^ 0x10]) + g[-2:]),
}


# --- Modbus ------------------------------------------------------------------------------------------
def _regs(values: list[int]) -> bytes:
    return b"".join(struct.pack(">H", v & 0xFFFF) for v in values)


STATUS_REGS = mp.encode_status(RATE, ANGLE, BITS, 0)


def modbus_pdu_reply(pdu: bytes) -> bytes:
    fc = pdu[0]
    if fc == 4:
        return bytes([4, 2 * len(STATUS_REGS)]) + _regs(STATUS_REGS)
    if fc == 3:
        count = struct.unpack(">H", pdu[3:5])[0]
        return bytes([3, 2 * count]) + b"\0\0" * count
    if fc in (6, 16):
        return pdu[:5]
    return bytes([fc | 0x80, 1])


def crc_modbus(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def tcp_split(buf: bytes):
    if len(buf) < 7:
        return None
    n = 6 + struct.unpack(">H", buf[4:6])[0]
    return (buf[:n], buf[n:]) if len(buf) >= n else None


def tcp_good(req: bytes) -> bytes:
    pdu = modbus_pdu_reply(req[7:])
    return req[:4] + struct.pack(">H", len(pdu) + 1) + req[6:7] + pdu


def rtu_split(buf: bytes):
    if len(buf) < 8:
        return None
    n = 9 + buf[6] if buf[1] == 16 else 8
    return (buf[:n], buf[n:]) if len(buf) >= n else None


def rtu_good(req: bytes) -> bytes:
    body = req[:1] + modbus_pdu_reply(req[1:-2])
    return body + crc_modbus(body)


def _tcp_pdu(req: bytes, pdu: bytes, *, tid=None, pid=0, unit=None, length=None) -> bytes:
    tid_b = req[:2] if tid is None else struct.pack(">H", tid)
    n = len(pdu) + 1 if length is None else length
    return tid_b + struct.pack(">HH", pid, n) + bytes([req[6] if unit is None else unit]) + pdu


def _status_pdu(regs: list[int] | None = None, *, fc: int = 4, byte_count: int | None = None) -> bytes:
    regs = STATUS_REGS if regs is None else regs
    return bytes([fc, 2 * len(regs) if byte_count is None else byte_count]) + _regs(regs)


NAN_RATE = mp.encode_status(float("nan"), ANGLE, BITS, 0)
INF_ANGLE = mp.encode_status(RATE, float("inf"), BITS, 0)
# replies that are the right shape but another request's: a stale status with other values
STALE = mp.encode_status(-99.0, 271.0, 0, 0)


def modbus_tcp_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    m = dict(COMMON)
    m.pop("bit-flip")  # TCP has no checksum: a flipped bit is a valid other value (not a malformed reply)
    m.update(
        {
            "wrong-transaction-id": lambda r, g: send(_tcp_pdu(r, _status_pdu(STALE), tid=(r[0] << 8 | r[1]) ^ 0x55)),
            "wrong-protocol-id": lambda r, g: send(_tcp_pdu(r, _status_pdu(STALE), pid=7)),
            "length-too-long": lambda r, g: send(_tcp_pdu(r, _status_pdu(), length=40)),
            "length-too-short": lambda r, g: send(_tcp_pdu(r, _status_pdu(), length=5)),
            "wrong-unit-id": lambda r, g: send(_tcp_pdu(r, _status_pdu(STALE), unit=9)),
            "wrong-function-code": lambda r, g: send(_tcp_pdu(r, _status_pdu(STALE, fc=3))),
            "byte-count-wrong": lambda r, g: send(_tcp_pdu(r, _status_pdu(byte_count=10))),
            "5-registers": lambda r, g: send(_tcp_pdu(r, _status_pdu(STATUS_REGS[:5]))),
            "7-registers": lambda r, g: send(_tcp_pdu(r, _status_pdu(STATUS_REGS + [0]))),
            "nan-rate": lambda r, g: send(_tcp_pdu(r, _status_pdu(NAN_RATE))),
            "inf-angle": lambda r, g: send(_tcp_pdu(r, _status_pdu(INF_ANGLE))),
            "stray-frame-first": lambda r, g: send(_tcp_pdu(r, _status_pdu(STALE), tid=0x7777) + g),
            "exception-no-code": lambda r, g: send(_tcp_pdu(r, bytes([0x84]))),
        }
    )
    for code in (1, 2, 3, 4, 6, 0x0A, 0x0B):
        m[f"exception-{code:02x}"] = lambda r, g, code=code: send(_tcp_pdu(r, bytes([0x84, code])))
    return m


def _rtu(addr: int, pdu: bytes, *, good_crc: bool = True) -> bytes:
    body = bytes([addr]) + pdu
    crc = crc_modbus(body)
    return body + (crc if good_crc else bytes([crc[0] ^ 0xFF, crc[1]]))


def modbus_rtu_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    m = dict(COMMON)
    m.update(
        {
            "bad-crc": lambda r, g: send(_rtu(r[0], _status_pdu(STALE), good_crc=False)),
            "wrong-slave-address": lambda r, g: send(_rtu(9, _status_pdu(STALE))),
            "wrong-function-code": lambda r, g: send(_rtu(r[0], _status_pdu(STALE, fc=3))),
            "byte-count-wrong": lambda r, g: send(_rtu(r[0], _status_pdu(byte_count=10))),
            "5-registers": lambda r, g: send(_rtu(r[0], _status_pdu(STATUS_REGS[:5]))),
            "nan-rate": lambda r, g: send(_rtu(r[0], _status_pdu(NAN_RATE))),
            "stray-frame-first": lambda r, g: send(_rtu(r[0], _status_pdu(STALE)) + g),
        }
    )
    for code in (2, 4, 0x0B):
        m[f"exception-{code:02x}"] = lambda r, g, code=code: send(_rtu(r[0], bytes([0x84, code])))
    return m


# --- ASCII table ---------------------------------------------------------------------------------------
def line_split(buf: bytes):
    i = buf.find(b"\n")
    return (buf[: i + 1], buf[i + 1 :]) if i >= 0 else None


STAT_LINE = ap.format_status(RATE, ANGLE, BITS, 0)


def ascii_good(req: bytes) -> bytes:
    text = req.decode().strip()
    if text == ap.Q_IDN:
        return (ap.IDN + "\n").encode()
    if text == ap.Q_STAT:
        return (STAT_LINE + "\n").encode()
    return b"OK\n"


def ascii_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    m = dict(COMMON)
    stale = ap.format_status(-99.0, 271.0, 0, 0)
    m.update(
        {
            "no-terminator": lambda r, g: send(g[:-1]),
            "cr-terminator": lambda r, g: send(g[:-1] + b"\r"),
            "non-ascii": lambda r, g: send(b"\xff\xfe" + g),
            "empty-line": lambda r, g: send(b"\n"),
            "3-fields": lambda r, g: send(b"+12.5,30.0,3\n"),
            "nan-rate": lambda r, g: send(b"nan,30.0,3,0\n"),
            "bits-out-of-range": lambda r, g: send(b"+12.5,30.0,99999,0\n"),
            "error-reply": lambda r, g: send(b"ERR -222,out of range\n"),
            "bad-error-reply": lambda r, g: send(b"ERR x\n"),
            "stray-line-first": lambda r, g: send(b"OK\n" + g),
            "stale-line-first": lambda r, g: send((stale + "\n").encode() + g),
            "oversize-line": lambda r, g: send(b"1" * 100_000 + b"\n"),
        }
    )
    return m


# --- SCPI front end ----------------------------------------------------------------------------------
SCPI_VALUES = {"SOUR1:VOLT?": "0.5", "SOUR2:VOLT?": "0.25", "*IDN?": "GYROBENCH,FE-2CH,SCRIPT,1.0", "*OPC?": "1"}
BLOCK = np.frombuffer(struct.pack("<fffI", 1.0, 2.0, -3.5, 0x00020A0A), dtype="<f4")  # two 0x0A bytes in the data


def scpi_reply(message: str) -> tuple[bytes, int]:
    """(reply of a program message without terminator, its tag)."""
    tag, parts = 0, []
    for unit in message.strip().split(";"):
        head, _, arg = unit.strip().lstrip(":").partition(" ")
        head = head.upper()
        if head == "*ESE":
            tag = int(arg)
        elif head == "*ESE?":
            parts.append(str(tag).encode())
        elif head == "SYST:ERR?":
            parts.append(b'0,"No error"')
        elif head == "FETC:CAPT1?":
            payload = BLOCK.tobytes()
            parts.append(b"#2%02d" % len(payload) + payload)
        elif head == "FETC:LOCK:ALL?":
            parts.append(b"0.1,0.2,0.3,0.4")
        elif head.endswith("?"):
            parts.append(SCPI_VALUES.get(head, "0").encode())
    return b";".join(parts), tag


def scpi_good(req: bytes) -> bytes:
    reply, _ = scpi_reply(req.decode())
    return reply + b"\n" if reply else b""


def _retag(g: bytes, new: bytes) -> bytes:
    body, _, _ = g[:-1].rpartition(b";")
    return body + new + b"\n"


def scpi_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    m = dict(COMMON)
    m.update(
        {
            "no-terminator": lambda r, g: send(g[:-1]),
            "cr-terminator": lambda r, g: send(g[:-1] + b"\r"),
            "non-ascii": lambda r, g: send(b"\xff\xfe" + g),
            "empty-line": lambda r, g: send(b"\n"),
            "stray-value-first": lambda r, g: send(b"0.5\n" + g),
            "stray-value-after": lambda r, g: send(g + b"0.5\n"),
            "stray-tagged-first": lambda r, g: send(b"0.5;3\n" + g),
            "missing-tag": lambda r, g: send(_retag(g, b"")),
            "wrong-tag": lambda r, g: send(_retag(g, b";200")),
            "value-only": lambda r, g: send(b"0.25\n"),
            "nan-value": lambda r, g: send(g.replace(b"0.25", b"nan")),
            "inf-value": lambda r, g: send(g.replace(b"0.25", b"inf")),
            "two-values": lambda r, g: send(g.replace(b"0.25", b"0.25,0.5")),
            "oversize-line": lambda r, g: send(b"1" * 100_000 + b"\n"),
            "drip-no-terminator": lambda r, g: [("drip", b"x" * 200, 0.004)],
        }
    )
    return m


def scpi_block_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    head = 4  # "#216"
    return {
        "block-bad-header": lambda r, g: send(b"$2" + g[2:]),
        "block-digits-zero": lambda r, g: send(b"#0" + g[2:]),
        "block-length-not-digits": lambda r, g: send(b"#2x6" + g[head:]),
        "block-short-payload": lambda r, g: send(g[: head + 8]),
        "block-length-oversize": lambda r, g: send(b"#9999999999" + g[head:]),
        "block-no-trailer": lambda r, g: send(g[: g.rfind(b";")]),
        "block-wrong-trailer": lambda r, g: send(_retag(g, b";201")),
        "block-stray-line-first": lambda r, g: send(b"0.5;9\n" + g),
        "block-dripped": lambda r, g: [("drip", g, TIMEOUT_S * 0.8)],
        "block-garbage": lambda r, g: send(garbage(len(g))),
    }


# --- FPGA link -----------------------------------------------------------------------------------------
PLL = fp.register("PLL_FREQ_HZ")
FPGA_VALUES = {fp.register("ID").addr: fp.FPGA_ID, fp.register("SAMPLE_PERIOD_S").addr: 1e-4, PLL.addr: 5432.25}


def fpga_split(buf: bytes):
    i = buf.find(fp.SYNC)
    if i < 0 or len(buf) - i < fp.HEADER_SIZE:
        return None
    n = fp.HEADER_SIZE + buf[i + 3] + fp.CRC_SIZE
    return (buf[i : i + n], buf[i + n :]) if len(buf) - i >= n else None


def fpga_good(req: bytes) -> bytes:
    _, ftype, _, seq, addr = fp.HEADER.unpack_from(req, 0)
    if ftype == fp.WRITE:
        return fp.encode_frame(fp.ACK, seq, addr, req[fp.HEADER_SIZE : -fp.CRC_SIZE])
    reg = fp.BY_ADDR.get(addr)
    if reg is None:
        return fp.encode_frame(fp.NACK, seq, addr, struct.pack("<Q", fp.ERR_UNKNOWN_ADDRESS))
    return fp.encode_frame(fp.ACK, seq, addr, fp.encode_value(reg, FPGA_VALUES.get(addr, 0)))


def _seq(req: bytes) -> int:
    return fp.HEADER.unpack_from(req, 0)[3]


def fpga_mangles() -> dict[str, Callable[[bytes, bytes], Actions]]:
    m = dict(COMMON)
    other = fp.encode_value(PLL, -1.0)
    m.update(
        {
            "bad-crc": lambda r, g: send(g[:-2] + bytes([g[-2] ^ 0xFF, g[-1]])),
            "wrong-seq": lambda r, g: send(fp.encode_frame(fp.ACK, _seq(r) + 5, PLL.addr, other)),
            "wrong-addr": lambda r, g: send(fp.encode_frame(fp.ACK, _seq(r), PLL.addr + 1, other)),
            "short-payload": lambda r, g: send(fp.encode_frame(fp.ACK, _seq(r), PLL.addr, b"\0" * 4)),
            "long-payload": lambda r, g: send(fp.encode_frame(fp.ACK, _seq(r), PLL.addr, b"\0" * 200)),
            "wrong-type": lambda r, g: send(fp.encode_frame(fp.WRITE, _seq(r), PLL.addr, other)),
            "bad-type-byte": lambda r, g: send(g[:2] + b"\x09" + g[3:]),
            "nack-unknown-code": lambda r, g: send(fp.encode_frame(fp.NACK, _seq(r), PLL.addr, struct.pack("<Q", 77))),
            "nack-empty": lambda r, g: send(fp.encode_frame(fp.NACK, _seq(r), PLL.addr, b"")),
            "stale-reply-first": lambda r, g: send(fp.encode_frame(fp.ACK, _seq(r) - 1, PLL.addr, other) + g),
            "stream-frame-first": lambda r, g: send(
                fp.encode_stream(0, np.array([0]), np.array([0.0]), np.zeros((1, 8), np.float32)) + g
            ),
        }
    )
    for code in (1, 3, 4):
        m[f"nack-{code}"] = lambda r, g, code=code: send(
            fp.encode_frame(fp.NACK, _seq(r), PLL.addr, struct.pack("<Q", code))
        )
    return m


# --- families: the device, the driver, the read under test and its truth --------------------------------
@dataclass
class Family:
    name: str
    split: Callable
    good: Callable
    target: Callable[[bytes], bool]
    mangles: dict
    open: Callable  # (port, clock) -> driver
    read: Callable  # driver -> value
    truth: object
    follow: Callable  # driver -> value (a different read)
    follow_truth: object
    bound_s: float  # the driver's own worst case for one read (all retries)
    deadline: bool = False  # bound_s is a deadline from the start of the read (link checks included)


def _status_tuple(table) -> tuple:
    st = table.status()
    return (round(st.rate_dps, 6), round(st.angle_deg, 6), st.enabled, st.at_rate)


STATUS_TRUTH = (RATE, ANGLE, True, True)
TABLE_KW = dict(limits=LIMITS, timeout_s=TIMEOUT_S, read_retries=2, heartbeat_s=1e6)


def _fpga_open(port: int, clock) -> FpgaLink:
    return FpgaLink(f"socket://127.0.0.1:{port}", timeout_s=TIMEOUT_S, retries=2).connect()


def _scpi_open(port: int, clock) -> ScpiFrontEnd:
    return ScpiFrontEnd(f"TCPIP::127.0.0.1::{port}::SOCKET", clock=clock, timeout_s=0.5).connect()


def _modbus_tcp_open(port: int, clock) -> ModbusRateTable:
    t = ModbusRateTable("127.0.0.1", port, clock=clock, **TABLE_KW)
    t.connect()
    return t


def _modbus_rtu_open(port: int, clock) -> ModbusRateTable:
    t = ModbusRateTable.rtu(f"socket://127.0.0.1:{port}", clock=clock, **TABLE_KW)
    t.connect()
    return t


def _ascii_open(port: int, clock) -> AsciiRateTable:
    t = AsciiRateTable(f"127.0.0.1:{port}", clock=clock, **TABLE_KW)
    t.connect()
    return t


def families() -> list[Family]:
    def is_modbus_tcp_status(r: bytes) -> bool:
        return len(r) > 7 and r[7] == 4

    def scpi_target(text: bytes) -> Callable[[bytes], bool]:
        return lambda r: text in r

    return [
        Family("modbus-tcp", tcp_split, tcp_good, is_modbus_tcp_status, modbus_tcp_mangles(), _modbus_tcp_open,
               _status_tuple, STATUS_TRUTH, _status_tuple, STATUS_TRUTH, 9 * TIMEOUT_S),
        Family("modbus-rtu", rtu_split, rtu_good, lambda r: r[1] == 4, modbus_rtu_mangles(), _modbus_rtu_open,
               _status_tuple, STATUS_TRUTH, _status_tuple, STATUS_TRUTH, 9 * TIMEOUT_S),
        Family("ascii", line_split, ascii_good, lambda r: r.strip() == b"STAT?", ascii_mangles(), _ascii_open,
               _status_tuple, STATUS_TRUTH, _status_tuple, STATUS_TRUTH, 9 * TIMEOUT_S),
        Family("scpi", line_split, scpi_good, scpi_target(b"SOUR2:VOLT?"), scpi_mangles(), _scpi_open,
               lambda fe: fe.ch2.amplitude_v, 0.25, lambda fe: fe.ch1.amplitude_v, 0.5, 0.5, deadline=True),
        Family("scpi-block", line_split, scpi_good, scpi_target(b"FETC:CAPT1?"), scpi_block_mangles(), _scpi_open,
               lambda fe: list(fe.fetch_capture(1, expected_samples=4)), [float(v) for v in BLOCK],
               lambda fe: fe.ch1.amplitude_v, 0.5, 0.5 + 16 / 10e6, deadline=True),
        Family("fpga", fpga_split, fpga_good, lambda r: r[2] == fp.READ and r[8] == PLL.addr, fpga_mangles(),
               _fpga_open, lambda link: link.read_register("PLL_FREQ_HZ"), 5432.25,
               lambda link: link.read_register("SAMPLE_PERIOD_S"), 1e-4, 3 * TIMEOUT_S),
    ]


# --- running a case --------------------------------------------------------------------------------------
SLACK_S = 0.25  # scheduling on a loaded machine


def _timed(fn: Callable[[], object], limit_s: float) -> tuple[str, object, float]:
    """("value", v) | ("named", exc) | ("foreign", exc) | ("hang", None), and the wall time."""
    box: list = []

    def run() -> None:
        try:
            box.append(("value", fn()))
        except NAMED as exc:
            box.append(("named", exc))
        except Exception as exc:  # noqa: BLE001 - what the audit counts as a traceback
            box.append(("foreign", exc))

    t0 = time.monotonic()
    th = threading.Thread(target=run, daemon=True)
    th.start()
    th.join(limit_s + 5.0)
    elapsed = time.monotonic() - t0
    if not box:
        return "hang", None, elapsed
    return box[0][0], box[0][1], elapsed


def _same(value: object, truth: object) -> bool:
    if isinstance(truth, (list, tuple)):
        return isinstance(value, (list, tuple)) and len(value) == len(truth) and all(map(_same, value, truth))
    if isinstance(truth, float) and isinstance(value, (int, float)):
        return math.isclose(value, truth, rel_tol=1e-9, abs_tol=1e-12)
    return value == truth


def run_case(fam: Family, name: str, count: int, clock) -> tuple[bool, str]:
    dev = ScriptedDevice(fam.split, fam.good, fam.target, fam.mangles[name], count)
    driver = None
    try:
        kind, value, _ = _timed(lambda: fam.open(dev.port, clock), 5.0)
        if kind != "value":
            return False, f"open: {kind} {value!r}"
        driver = value
        verdicts = []
        for read, truth, bound in ((fam.read, fam.truth, fam.bound_s), (fam.follow, fam.follow_truth, fam.bound_s)):
            # a deadline holds from the start of the read, plus one low-level read (SCPI: 10 ms
            # slices, 16-byte pieces); otherwise a stale line may sit in the input and the driver
            # may clear it first: the bound of one read plus one more
            limit = bound + 0.1 + SLACK_S if fam.deadline else bound * 2 + SLACK_S
            kind, value, elapsed = _timed(lambda read=read: read(driver), limit)
            if kind == "hang" or elapsed > limit:
                return False, f"{kind} after {elapsed:.2f} s (limit {limit:.2f} s)"
            if kind == "foreign":
                return False, f"traceback-worthy {type(value).__name__}: {value}"
            if kind == "value" and not _same(value, truth):
                return False, f"WRONG VALUE {value!r} (true {truth!r})"
            verdicts.append("value" if kind == "value" else f"{type(value).__name__}")
            if count > 1:
                break  # a persistent fault: the follow-up would meet it again
        return True, ", ".join(verdicts)
    finally:
        if driver is not None:
            try:
                driver.close()
            except Exception:  # noqa: BLE001
                pass
        dev.close()


def main(argv: list[str]) -> int:
    verbose = "-v" in argv
    clock = SimClock(World(ResonatorParams(f0_hz=5500.0, tau_s=3000.0), seed=1))
    tried = clean = 0
    per_family: dict[str, list[int]] = {}
    failures: list[str] = []
    t0 = time.monotonic()
    try:
        for fam in families():
            for name in fam.mangles:
                for count, label in ((1, "once"), (10**9, "always")):
                    ok, what = run_case(fam, name, count, clock)
                    tried += 1
                    clean += ok
                    per_family.setdefault(fam.name, [0, 0])
                    per_family[fam.name][0] += 1
                    per_family[fam.name][1] += ok
                    line = f"{fam.name:11s} {name:24s} {label:6s} {'clean' if ok else 'NOT CLEAN'}: {what}"
                    if not ok:
                        failures.append(line)
                    if verbose:
                        print(line, flush=True)
    finally:
        clock.close()
    for fam_name, (n, ok) in per_family.items():
        print(f"  {fam_name:11s} tried {n:3d}, clean {ok:3d}")
    for line in failures:
        print("  " + line)
    print(f"  ({time.monotonic() - t0:.0f} s)")
    print(f"malformed device replies: tried {tried}, clean {clean}")
    return 0 if clean == tried else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
