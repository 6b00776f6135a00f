"""A line-oriented instrument on a loopback TCP socket: LF-terminated commands in, each answered
(or not) by a reply function.  `LineServer` is the socket (shared by the simulated tables' ASCII
and ACL dialects); `TextLineServer` answers `execute(line)` under the world's lock with the
faults a test injects (`hang`, `garble`), for the SCPI instruments (VISA `TCPIP::host::port::SOCKET`)."""

from __future__ import annotations

import socket
import socketserver
import threading
from collections.abc import Callable
from typing import Any


class LineServer:
    """Serve `reply(line) -> bytes | None` on a loopback port (0: a free one) until `stop()`."""

    def __init__(self, reply: Callable[[str], bytes | None], host: str = "127.0.0.1", port: int = 0,
                 name: str = "line-server", max_line: int = 65536, whole_lines: bool = False,
                 drop_long_lines: bool = False) -> None:
        """whole_lines: a line without its LF (too long, or cut by the peer closing) ends the
        connection unanswered instead of being answered as it is.  drop_long_lines: a line longer
        than max_line is read to its LF and dropped unanswered (an instrument's input buffer
        overflowing), the connection stays."""
        self._stop = threading.Event()
        self._conns: set[socket.socket] = set()
        self._conns_lock = threading.Lock()
        outer = self
        self.reply = reply

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                with outer._conns_lock:
                    if outer._stop.is_set():
                        return
                    outer._conns.add(self.connection)
                try:
                    while not outer._stop.is_set():
                        raw = self.rfile.readline(max_line)
                        if drop_long_lines and len(raw) == max_line and not raw.endswith(b"\n"):
                            while raw and not raw.endswith(b"\n"):
                                raw = self.rfile.readline(max_line)
                            continue
                        if not raw or (whole_lines and not raw.endswith(b"\n")):
                            return
                        out = outer.reply(raw.decode("ascii", "replace"))
                        if out is not None:
                            self.wfile.write(out)
                except OSError:
                    return
                finally:
                    with outer._conns_lock:
                        outer._conns.discard(self.connection)

        self._tcp = socketserver.ThreadingTCPServer((host, port), Handler, bind_and_activate=False)
        self._tcp.daemon_threads = True
        self._tcp.allow_reuse_address = True
        self._tcp.server_bind()
        self._tcp.server_activate()
        self.host, self.port = self._tcp.server_address[:2]
        self._thread = threading.Thread(
            target=self._tcp.serve_forever, kwargs={"poll_interval": 0.05}, name=name, daemon=True
        )
        self._thread.start()

    def send_all(self, data: bytes) -> None:
        """Write `data` to every connected client now (an unsolicited message)."""
        with self._conns_lock:
            conns = list(self._conns)
        for conn in conns:
            try:
                conn.sendall(data)
            except OSError:
                pass

    @property
    def resource_name(self) -> str:
        """The socket as a VISA resource (pyvisa-py)."""
        return f"TCPIP::{self.host}::{self.port}::SOCKET"

    def stop(self) -> None:
        """Stop listening and close every connection (its client sees the link go)."""
        self._stop.set()
        self._tcp.shutdown()
        self._tcp.server_close()
        self._thread.join(timeout=5.0)
        with self._conns_lock:
            conns = list(self._conns)
        for conn in conns:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


class TextLineServer(LineServer):
    """Answer `execute(line) -> str | None` under `world.lock`, LF-terminated; `hang` stops the
    answers, `garble` sends two noise bytes and half of each answer."""

    def __init__(self, world: Any, execute: Callable[[str], str | None], host: str = "127.0.0.1",
                 name: str = "instrument-sim") -> None:
        self.world, self.execute = world, execute
        self.hang = False
        self.garble = False
        super().__init__(self._answer, host, 0, name)

    def _answer(self, line: str) -> bytes | None:
        with self.world.lock:
            answer = self.execute(line)
        if answer is None or self.hang:
            return None
        if self.garble:
            answer = "\x7f#" + answer[: len(answer) // 2]
        return (answer + "\n").encode("ascii", "replace")
