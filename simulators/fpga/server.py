"""Serve the simulated FPGA over a loopback socket (`socket://127.0.0.1:PORT`) or a pty, with
fault injection (corrupted bytes, dropped frames, stall, link drop).

Stream frames are written from the World's thread inside `after_block`, with blocking writes:
in lockstep a block's frames are all in the link before the next block begins (backpressure),
and a wall timeout (`write_timeout_s`) drops a client that stopped reading instead of hanging
the world.  Register commands are answered by a thread per connection.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
import tty
from typing import Any

import numpy as np

from drivers.fpga import protocol as p

from .firmware import FpgaFirmware
from .nvm import Nvm, world_nvm

FAULT_KINDS = ("corrupt", "drop", "stall", "link-drop")


class _Port:
    """A byte pipe to one client: send with a wall timeout, receive with a poll timeout."""

    def send(self, data: bytes, timeout_s: float) -> bool: ...

    def recv(self, timeout_s: float) -> bytes | None: ...

    def close(self) -> None: ...


class _SocketPort(_Port):
    def __init__(self, conn: socket.socket) -> None:
        self.conn = conn
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn.setblocking(True)
        self.closed = False
        self._timeout_s: float | None = None

    def send(self, data: bytes, timeout_s: float) -> bool:
        try:
            if timeout_s != self._timeout_s:  # settimeout costs a call per block: set it on change
                self.conn.settimeout(timeout_s)
                self._timeout_s = timeout_s
            self.conn.sendall(data)
            return True
        except OSError:
            self.close()
            return False

    def recv(self, timeout_s: float) -> bytes | None:
        try:
            ready, _, _ = select.select([self.conn], [], [], timeout_s)
            if not ready:
                return b""
            data = self.conn.recv(65536)
        except (OSError, ValueError):
            return None
        return data or None

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self.conn.close()


class _PtyPort(_Port):
    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        # non-blocking: a blocking write to a pty waits for room for ALL its bytes, past select
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.closed = False
        self.blocked = False  # a write timed out: nobody reads; skip writes until the pty drains

    def send(self, data: bytes, timeout_s: float) -> bool:
        view = memoryview(data)
        try:
            if self.blocked:
                _, ready, _ = select.select([], [self.master], [], 0)
                if not ready:
                    return False
                self.blocked = False
            while view:
                _, ready, _ = select.select([], [self.master], [], timeout_s)
                if not ready:
                    self.blocked = True
                    return False
                try:
                    n = os.write(self.master, view)
                except BlockingIOError:
                    continue
                view = view[n:]
            return True
        except (OSError, ValueError):
            return False

    def recv(self, timeout_s: float) -> bytes | None:
        try:
            ready, _, _ = select.select([self.master], [], [], timeout_s)
            if not ready:
                return b""
            return os.read(self.master, 65536) or None
        except BlockingIOError:
            return b""
        except (OSError, ValueError):
            return None

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for fd in (self.master, self.slave):
                try:
                    os.close(fd)
                except OSError:
                    pass


class FpgaServer:
    """The simulated FPGA on a transport; `serve_fpga` builds and starts one."""

    def __init__(
        self, world, *, transport: str = "socket", seed: int = 0, write_timeout_s: float = 5.0, nvm: Nvm | None = None
    ) -> None:
        if transport not in ("socket", "pty"):
            raise ValueError(f"transport={transport!r} must be 'socket' or 'pty'")
        self.world = world
        self.transport = transport
        self.write_timeout_s = float(write_timeout_s)
        self.firmware = FpgaFirmware(world, nvm if nvm is not None else world_nvm(world))  # the unit's NVM
        self.firmware.sink = self._send_stream
        self.rng = np.random.default_rng(seed)
        self._write_lock = threading.Lock()
        self._stop = threading.Event()
        self._port: _Port | None = None
        self._threads: list[threading.Thread] = []
        self._listener: socket.socket | None = None
        # faults
        self.corrupt_rate = 0.0
        self.drop_rate = 0.0
        self.stalled = False
        # counters of what the faults did (ground truth for tests)
        self.frames_corrupted = 0
        self.frames_dropped = 0
        self.frames_lost = 0  # frames produced while no client, stalled or after a write timeout
        self.url = ""
        # stream frames of the current World.advance, written in one piece at its end (or once
        # STREAM_FLUSH_BYTES are waiting, or before a reply): one write and one wake-up of the
        # driver's reader per advance instead of one per 50 ms block
        self._stream_pending: list[bytes] = []
        self._stream_pending_n = 0
        self._stream_pending_bytes = 0

    #: stream bytes held back at most before they are written: 2048 frames (147 KiB of 72-byte
    #: frames), so a 1 s advance at 1 kHz goes out in one write whatever the frame's size
    STREAM_FLUSH_BYTES = 2048 * p.STREAM_FRAME_SIZE

    # --- lifecycle ------------------------------------------------------------------------------
    def start(self) -> FpgaServer:
        if self.transport == "socket":
            self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind(("127.0.0.1", 0))
            self._listener.listen(1)
            self._listener.settimeout(0.1)  # so stop() is seen promptly
            self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
            self._spawn(self._accept_loop, "fpga-accept")
        else:
            port = _PtyPort()
            self._port = port
            self.url = port.path
            self._spawn(lambda: self._command_loop(port), "fpga-commands")
        self.world.attach(self.firmware)
        self.world.add_advance_listener(self._flush_stream)
        return self

    def stop(self) -> None:
        self._stop.set()
        self.world.detach(self.firmware)
        self.world.remove_advance_listener(self._flush_stream)
        with self.world.lock:
            self.world.set_force("fpga", None)
        if self._listener is not None:
            with contextlib.suppress(OSError):  # wakes a blocked accept() now (Linux), not at its 0.1 s timeout
                self._listener.shutdown(socket.SHUT_RDWR)
            self._listener.close()
        port = self._port
        if port is not None:
            port.close()
        for t in self._threads:
            t.join(timeout=2.0)

    def _spawn(self, target, name: str) -> None:
        t = threading.Thread(target=target, name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def truth(self) -> dict[str, float]:
        """What the outputs' truth needs from the FPGA's registers (FpgaFirmware.truth)."""
        return self.firmware.truth()

    # --- faults ---------------------------------------------------------------------------------
    def inject(self, kind: str, rate: float = 0.01) -> None:
        """'corrupt' (one byte of a frame altered, at a per-frame rate), 'drop' (stream frames
        not sent, per-frame rate), 'stall' (no replies, no stream), 'link-drop' (close the link)."""
        if kind not in FAULT_KINDS:
            raise ValueError(f"fault kind {kind!r} is not one of {FAULT_KINDS}")
        if kind in ("corrupt", "drop") and not 0.0 <= rate <= 1.0:
            raise ValueError(f"fault rate={rate!r} must be in [0, 1]")
        if kind == "corrupt":
            self.corrupt_rate = rate
        elif kind == "drop":
            self.drop_rate = rate
        elif kind == "stall":
            self.stalled = True
        else:
            self._flush_stream()  # what was produced before the drop still goes out
            port = self._port
            if port is not None:
                port.close()

    def clear_faults(self) -> None:
        self.corrupt_rate = self.drop_rate = 0.0
        self.stalled = False

    # --- transport ------------------------------------------------------------------------------
    def _accept_loop(self) -> None:
        assert self._listener is not None
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            old = self._port
            port = _SocketPort(conn)
            self._port = port
            if old is not None:
                old.close()
            self._spawn(lambda port=port: self._command_loop(port), "fpga-commands")

    def _write(self, data: bytes) -> bool:
        """Write a reply: after the stream frames produced before it (the driver relies on a
        reply coming after every frame that came before it)."""
        port = self._port
        if port is None or getattr(port, "closed", False):
            return False
        with self._write_lock:
            if self._stream_pending:
                self._send_pending(port)
            return port.send(data, self.write_timeout_s)

    def _flush_stream(self, _world: object = None) -> None:
        """Write the stream frames held back (World thread, end of an advance)."""
        if self._stream_pending:
            with self._write_lock:
                if self._stream_pending:
                    self._send_pending(self._port)

    def _send_pending(self, port: _Port | None) -> None:
        """(under _write_lock) one write of the held-back frames; lost ones are counted."""
        pending, n = self._stream_pending, self._stream_pending_n
        self._stream_pending, self._stream_pending_n, self._stream_pending_bytes = [], 0, 0
        data = pending[0] if len(pending) == 1 else b"".join(pending)
        if port is None or getattr(port, "closed", False) or not port.send(data, self.write_timeout_s):
            self.frames_lost += n

    def _send_stream(self, data: bytes, n: int) -> None:
        """Stream sink of the firmware (World thread): apply faults, then a blocking write."""
        if self.stalled or self._port is None or getattr(self._port, "closed", False):
            self.frames_lost += n
            return
        size = p.STREAM_FRAME_SIZE
        if self.drop_rate > 0.0:
            keep = self.rng.random(n) >= self.drop_rate
            if not keep.all():
                self.frames_dropped += int(n - keep.sum())
                frames = np.frombuffer(data, np.uint8).reshape(n, size)[keep]
                data, n = frames.tobytes(), int(keep.sum())
        if self.corrupt_rate > 0.0 and n:
            data = self._corrupt(data, n, size)
        if not n:
            return
        with self._write_lock:
            self._stream_pending.append(bytes(data))
            self._stream_pending_n += n
            self._stream_pending_bytes += len(data)
            if self._stream_pending_bytes >= self.STREAM_FLUSH_BYTES:
                self._send_pending(self._port)

    def _corrupt(self, data: bytes, n: int, size: int) -> bytes:
        hit = np.flatnonzero(self.rng.random(n) < self.corrupt_rate)
        if len(hit) == 0:
            return data
        buf = bytearray(data)
        offsets = self.rng.integers(0, size, len(hit))
        flips = self.rng.integers(1, 256, len(hit))
        for j, off, flip in zip(hit, offsets, flips, strict=True):
            buf[j * size + int(off)] ^= int(flip)
        self.frames_corrupted += len(hit)
        return bytes(buf)

    def _command_loop(self, port: _Port) -> None:
        parser = p.FrameParser()
        while not self._stop.is_set() and not getattr(port, "closed", False):
            data = port.recv(0.05)
            if data is None:
                if self.transport == "socket":
                    port.close()
                    return
                continue  # a pty whose client closed: wait for the next one
            if not data:
                continue
            _, frames = parser.feed(data)
            with self.firmware.lock:
                self.firmware.regs["ERR_CRC"] = parser.corrupt
            if self.stalled:
                continue
            for frame in frames:
                reply = self._handle(frame)
                if reply is not None:
                    if self.corrupt_rate > 0.0:
                        reply = self._corrupt(reply, 1, len(reply))
                    self._write(reply)

    def _handle(self, frame: p.Frame) -> bytes | None:
        fw = self.firmware
        if frame.type not in (p.READ, p.WRITE):
            return None
        reg = p.BY_ADDR.get(frame.addr)
        code = 0
        if reg is None:
            code = p.ERR_UNKNOWN_ADDRESS
        elif frame.type == p.READ:
            if reg.access == "wo":
                code = p.ERR_WRITE_ONLY
            elif frame.payload:
                code = p.ERR_BAD_LENGTH
            else:
                return p.encode_frame(p.ACK, frame.seq, frame.addr, p.encode_value(reg, fw.read(reg)))
        else:
            if reg.access == "ro":
                code = p.ERR_READ_ONLY
            elif len(frame.payload) != 8:
                code = p.ERR_BAD_LENGTH
            else:
                value = p.decode_value(reg, frame.payload)
                if not p.in_range(reg, value):
                    code = p.ERR_OUT_OF_RANGE
                else:
                    stored = fw.write(reg, value)
                    return p.encode_frame(p.ACK, frame.seq, frame.addr, p.encode_value(reg, stored))
        with fw.lock:
            fw.regs["ERR_CMD"] += 1
        return p.encode_frame(p.NACK, frame.seq, frame.addr, code.to_bytes(8, "little"))


def serve_fpga(
    world, *, transport: str = "socket", seed: int = 0, write_timeout_s: float = 5.0, nvm: Nvm | None = None
) -> FpgaServer:
    """Start the simulated FPGA on `world`; the handle has `.url`, `.stop()`, `.inject(kind)`,
    `.clear_faults()`, `.firmware` and the fault counters.  Its NVM is the World's (`nvm` to
    give another): a restart on the same World finds the trims committed before."""
    return FpgaServer(world, transport=transport, seed=seed, write_timeout_s=write_timeout_s, nvm=nvm).start()


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[FpgaServer, dict[str, Any]]:
    """A simulated station's `fpga-link` (seeded by the world); (handle, the link's URL)."""
    handle = serve_fpga(world, seed=world.seed, nvm=world_nvm(world, cfg.get("nvm_file") or None))
    return handle, {"url": handle.url}
