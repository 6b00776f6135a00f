"""A line instrument served over VXI-11 (VISA `TCPIP::host::INSTR`), the way a lab's LAN
instruments speak it: ONC RPC (RFC 5531) over TCP with record marking, a portmapper answering
GETPORT (RFC 1833, program 100000 version 2) and the VXI-11 core channel (program 0x0607AF
version 1: create_link, device_write, device_read, device_readstb, device_clear, destroy_link
...).  Each complete message written (END flag) is handed to `execute(line)` under the world's
lock, as the socket simulators do; its answer waits for device_read.  docs/frontend_sr865.md.

pyvisa-py finds the core channel through the portmapper on port 111, or directly with the port
in the resource (`TCPIP::127.0.0.1,<port>::INSTR`), which is what the simulated stations hand
out; `PortMapper` serves GETPORT on any port (111 needs root)."""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable
from typing import Any, BinaryIO

from .tcp_server import LoopbackTcpServer

PMAP_PROG, PMAP_VERS, PMAP_GETPORT, PMAP_DUMP = 100000, 2, 3, 4
CORE_PROG, CORE_VERS = 0x0607AF, 1
IPPROTO_TCP = 6
# RPC message and reply kinds (RFC 5531)
CALL, REPLY, MSG_ACCEPTED = 0, 1, 0
SUCCESS, PROG_UNAVAIL, PROG_MISMATCH, PROC_UNAVAIL, GARBAGE_ARGS = 0, 1, 2, 3, 4
# VXI-11 core procedures
CREATE_LINK, DEVICE_WRITE, DEVICE_READ, DEVICE_READSTB = 10, 11, 12, 13
DEVICE_TRIGGER, DEVICE_CLEAR, DEVICE_REMOTE, DEVICE_LOCAL, DEVICE_LOCK, DEVICE_UNLOCK = 14, 15, 16, 17, 18, 19
DEVICE_ENABLE_SRQ, DEVICE_DOCMD, DESTROY_LINK, CREATE_INTR_CHAN, DESTROY_INTR_CHAN = 20, 22, 23, 25, 26
# VXI-11 error codes and flags
ERR_NONE, ERR_INVALID_LINK, ERR_NOT_SUPPORTED, ERR_IO_TIMEOUT, ERR_INVALID_ADDRESS = 0, 4, 8, 15, 21
FLAG_END, FLAG_TERMCHR = 0x08, 0x80
REASON_REQCNT, REASON_CHR, REASON_END = 1, 2, 4
MAX_RECV_SIZE = 1 << 20
LAST_FRAGMENT = 0x8000_0000


class Xdr:
    """Reads XDR items (RFC 4506) from a buffer: unsigned/signed ints and variable opaques."""

    def __init__(self, data: bytes) -> None:
        self.data, self.pos = data, 0

    def uint(self) -> int:
        (v,) = struct.unpack_from(">I", self.data, self.pos)
        self.pos += 4
        return v

    def int(self) -> int:
        (v,) = struct.unpack_from(">i", self.data, self.pos)
        self.pos += 4
        return v

    def opaque(self) -> bytes:
        n = self.uint()
        if self.pos + n > len(self.data):
            raise struct.error("opaque runs past the message")
        v = self.data[self.pos : self.pos + n]
        self.pos += (n + 3) & ~3
        return v


def xdr_uint(*values: int) -> bytes:
    return struct.pack(f">{len(values)}I", *(v & 0xFFFF_FFFF for v in values))


def xdr_opaque(data: bytes) -> bytes:
    return xdr_uint(len(data)) + data + b"\0" * (-len(data) % 4)


def read_record(rfile: Any) -> bytes | None:
    """One RPC record (its fragments joined); None at the end of the stream."""
    parts: list[bytes] = []
    while True:
        head = rfile.read(4)
        if len(head) < 4:
            return None
        (mark,) = struct.unpack(">I", head)
        body = rfile.read(mark & ~LAST_FRAGMENT)
        if len(body) < (mark & ~LAST_FRAGMENT):
            return None
        parts.append(body)
        if mark & LAST_FRAGMENT:
            return b"".join(parts)


def record(data: bytes) -> bytes:
    """`data` as one last fragment."""
    return xdr_uint(LAST_FRAGMENT | len(data)) + data


class RpcServer(LoopbackTcpServer):
    """ONC RPC over TCP on a loopback port: `dispatch(prog, vers, proc, args, conn) -> (accept_stat,
    results)` for each call; `stop()` ends it and its connections."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, name: str = "rpc-sim") -> None:
        self._lock = threading.Lock()  # the subclasses' own state (a VXI-11 server's links)
        super().__init__(host, port, name)

    def serve_connection(self, conn: Any, rfile: BinaryIO, wfile: BinaryIO) -> None:
        """Answer each call record until the peer closes or `stop()`; then the connection's links end."""
        conn_state: dict[str, Any] = {}
        try:
            while not self.stopping:
                call = read_record(rfile)
                if call is None:
                    return
                reply = self._reply(call, conn_state)
                if reply is not None:
                    wfile.write(record(reply))
        finally:
            self.connection_closed(conn_state)

    def _reply(self, call: bytes, conn_state: dict[str, Any]) -> bytes | None:
        x = Xdr(call)
        try:
            xid, kind = x.uint(), x.uint()
            if kind != CALL:
                return None
            _rpcvers, prog, vers, proc = x.uint(), x.uint(), x.uint(), x.uint()
            x.uint(), x.opaque()  # credentials (AUTH_NONE from pyvisa-py)
            x.uint(), x.opaque()  # verifier
        except struct.error:
            return None  # not even a call header: nothing to answer
        try:
            stat, results = self.dispatch(prog, vers, proc, x, conn_state)
        except struct.error:
            stat, results = GARBAGE_ARGS, b""
        return xdr_uint(xid, REPLY, MSG_ACCEPTED, 0, 0, stat) + results

    def dispatch(self, prog: int, vers: int, proc: int, args: Xdr, conn_state: dict[str, Any]) -> tuple[int, bytes]:
        return PROG_UNAVAIL, b""

    def connection_closed(self, conn_state: dict[str, Any]) -> None:
        """A client went away (its links end)."""


class PortMapper(RpcServer):
    """The portmapper's GETPORT and DUMP for the programs given: {(prog, vers): tcp port}."""

    def __init__(self, programs: dict[tuple[int, int], int], host: str = "127.0.0.1", port: int = 0) -> None:
        self.programs = dict(programs)
        super().__init__(host, port, name="portmapper-sim")

    def dispatch(self, prog: int, vers: int, proc: int, args: Xdr, conn_state: dict[str, Any]) -> tuple[int, bytes]:
        if prog != PMAP_PROG:
            return PROG_UNAVAIL, b""
        if vers != PMAP_VERS:
            return PROG_MISMATCH, xdr_uint(PMAP_VERS, PMAP_VERS)
        if proc == 0:
            return SUCCESS, b""
        if proc == PMAP_GETPORT:
            want_prog, want_vers, prot, _port = args.uint(), args.uint(), args.uint(), args.uint()
            port = self.programs.get((want_prog, want_vers), 0) if prot == IPPROTO_TCP else 0
            return SUCCESS, xdr_uint(port)
        if proc == PMAP_DUMP:
            out = b"".join(xdr_uint(1, p, v, IPPROTO_TCP, port) for (p, v), port in self.programs.items())
            return SUCCESS, out + xdr_uint(0)
        return PROC_UNAVAIL, b""


class Vxi11Server(RpcServer):
    """One instrument's VXI-11 core channel: `execute(line) -> answer | None` under `world.lock`;
    `status_byte()` answers device_readstb; `hang` leaves reads unanswered until their
    io_timeout, `garble` spoils answers (the socket simulators' faults)."""

    def __init__(self, world: Any, execute: Callable[[str], str | None], *, host: str = "127.0.0.1",
                 port: int = 0, device: str = "inst0", status_byte: Callable[[], int] | None = None) -> None:
        self.world, self.execute, self.device = world, execute, device
        self.status_byte = status_byte or (lambda: 0)
        self.hang = self.garble = False
        self._links: dict[int, dict[str, Any]] = {}
        self._next_link = 1
        super().__init__(host, port, name="vxi11-sim")

    @property
    def resource_name(self) -> str:
        """The VISA resource of this core channel, its port given (no portmapper needed)."""
        return f"TCPIP::{self.host},{self.port}::{self.device}::INSTR"

    def connection_closed(self, conn_state: dict[str, Any]) -> None:
        with self._lock:
            for lid in conn_state.get("links", ()):
                self._links.pop(lid, None)

    def _answer(self, text: str) -> bytes:
        """The answers to a written message's lines, each LF-terminated (what a read returns)."""
        out = b""
        for line in text.replace("\r", "").split("\n"):
            if not line.strip():
                continue
            with self.world.lock:
                answer = self.execute(line)
            if answer is None or self.hang:
                continue
            if self.garble:
                answer = "\x7f#" + answer[: len(answer) // 2]
            out += (answer + "\n").encode("ascii", "replace")
        return out

    def dispatch(self, prog: int, vers: int, proc: int, args: Xdr, conn_state: dict[str, Any]) -> tuple[int, bytes]:
        if prog != CORE_PROG:
            return PROG_UNAVAIL, b""
        if vers != CORE_VERS:
            return PROG_MISMATCH, xdr_uint(CORE_VERS, CORE_VERS)
        if proc == 0:
            return SUCCESS, b""
        if proc == CREATE_LINK:
            _client, _lock, _lock_timeout = args.int(), args.uint(), args.uint()
            device = args.opaque().decode("ascii", "replace")
            if device.lower() != self.device.lower():
                return SUCCESS, xdr_uint(ERR_INVALID_ADDRESS, 0, 0, 0)
            with self._lock:
                lid, self._next_link = self._next_link, self._next_link + 1
                self._links[lid] = {"in": b"", "out": b""}
            conn_state.setdefault("links", set()).add(lid)
            return SUCCESS, xdr_uint(ERR_NONE, lid, 0, MAX_RECV_SIZE)
        lid = args.int()
        link = self._links.get(lid)
        if link is None:
            return SUCCESS, xdr_uint(ERR_INVALID_LINK) + (
                xdr_uint(0) if proc in (DEVICE_WRITE, DEVICE_READSTB) else
                xdr_uint(0) + xdr_opaque(b"") if proc == DEVICE_READ else b"")
        if proc == DEVICE_WRITE:
            _io_timeout, _lock_timeout, flags = args.uint(), args.uint(), args.int()
            data = args.opaque()
            link["in"] += data
            if flags & FLAG_END:  # the message is complete: the instrument parses it now
                text, link["in"] = link["in"].decode("ascii", "replace"), b""
                link["out"] += self._answer(text)
            return SUCCESS, xdr_uint(ERR_NONE, len(data))
        if proc == DEVICE_READ:
            size, io_timeout_ms, _lock_timeout = args.uint(), args.uint(), args.uint()
            flags, term_char = args.int(), args.int()
            if not link["out"]:  # nothing to say: the client waits out its io_timeout
                time.sleep(min(io_timeout_ms, 60_000) / 1000.0)
                return SUCCESS, xdr_uint(ERR_IO_TIMEOUT, 0) + xdr_opaque(b"")
            out = link["out"]
            end = out.find(b"\n") + 1 or len(out)  # one answer (a line) per read, as an instrument
            chunk = out[: min(end, size)]
            link["out"] = out[len(chunk) :]
            reason = REASON_END if len(chunk) == end else REASON_REQCNT
            if flags & FLAG_TERMCHR and chunk.endswith(bytes([term_char & 0xFF])):
                reason |= REASON_CHR
            return SUCCESS, xdr_uint(ERR_NONE, reason) + xdr_opaque(chunk)
        if proc == DEVICE_READSTB:
            with self.world.lock:
                stb = self.status_byte() | (0x10 if link["out"] else 0)
            return SUCCESS, xdr_uint(ERR_NONE, stb)
        if proc == DEVICE_CLEAR:
            link["in"] = link["out"] = b""
            return SUCCESS, xdr_uint(ERR_NONE)
        if proc in (DEVICE_TRIGGER, DEVICE_REMOTE, DEVICE_LOCAL, DEVICE_LOCK, DEVICE_UNLOCK):
            return SUCCESS, xdr_uint(ERR_NONE)
        if proc == DESTROY_LINK:
            with self._lock:
                self._links.pop(lid, None)
            conn_state.get("links", set()).discard(lid)
            return SUCCESS, xdr_uint(ERR_NONE)
        if proc in (DEVICE_ENABLE_SRQ, DEVICE_DOCMD, CREATE_INTR_CHAN, DESTROY_INTR_CHAN):
            return SUCCESS, xdr_uint(ERR_NOT_SUPPORTED) + (xdr_opaque(b"") if proc == DEVICE_DOCMD else b"")
        return PROC_UNAVAIL, b""
