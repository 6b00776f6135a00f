"""A line-oriented instrument on a loopback TCP socket (VISA `TCPIP::host::port::SOCKET`): LF-terminated
commands in, each answered (or not) by `execute(line)` under the world's lock.  Shared by the
simulated lock-ins, supply and multimeter; `hang` and `garble` are the faults a test injects."""

from __future__ import annotations

import socket
import socketserver
import threading
from collections.abc import Callable
from typing import Any


class LineServer:
    """Serve `execute` (str -> answer or None) on a free loopback port until `stop()`."""

    def __init__(self, world: Any, execute: Callable[[str], str | None], host: str = "127.0.0.1",
                 name: str = "instrument-sim") -> None:
        self.world, self.execute = world, execute
        self.hang = False  # stop answering (a hung instrument)
        self.garble = False  # two noise bytes, then half of every answer
        self._stop = threading.Event()
        outer = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                while not outer._stop.is_set():
                    raw = self.rfile.readline(65536)
                    if not raw:
                        return
                    with outer.world.lock:
                        answer = outer.execute(raw.decode("ascii", "replace"))
                    if answer is not None and not outer.hang:
                        if outer.garble:
                            answer = "\x7f#" + answer[: len(answer) // 2]
                        self.wfile.write((answer + "\n").encode("ascii", "replace"))

        self._tcp = socketserver.ThreadingTCPServer((host, 0), Handler, bind_and_activate=False)
        self._tcp.daemon_threads = True
        self._tcp.allow_reuse_address = True
        self._tcp.server_bind()
        self._tcp.server_activate()
        self.host, self.port = self._tcp.server_address[:2]
        self._thread = threading.Thread(
            target=self._tcp.serve_forever, kwargs={"poll_interval": 0.05}, name=name, daemon=True
        )
        self._thread.start()

    @property
    def resource_name(self) -> str:
        return f"TCPIP::{self.host}::{self.port}::SOCKET"

    def stop(self) -> None:
        self._stop.set()
        self._tcp.shutdown()
        self._tcp.server_close()
        self._thread.join(timeout=5.0)
