"""A loopback TCP server for the simulated instruments: a thread per connection, the live
connections known, and `stop()` that ends them all (their clients see the link go).

Subclasses say how one connection is served (`serve_connection`): LF-terminated lines
(simulators.line_server), ONC RPC records (simulators.vxi11) or Modbus frames
(simulators.rate_table.modbus_server)."""

from __future__ import annotations

import selectors
import socket
import socketserver
import threading
from typing import BinaryIO


class LoopbackTcpServer:
    """Listen on `host:port` (0: a free port) from construction until `stop()`."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, name: str = "tcp-sim") -> None:
        self._stop = threading.Event()
        self._conns: set[socket.socket] = set()
        self._conns_lock = threading.Lock()
        outer = self

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                with outer._conns_lock:
                    if outer._stop.is_set():
                        return
                    outer._conns.add(self.connection)
                try:
                    outer.serve_connection(self.connection, self.rfile, self.wfile)
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
        # stop() wakes the accept loop through this pair at once (serve_forever's poll cost each
        # station's close up to 50 ms a server; issue 36)
        self._wake_r, self._wake_w = socket.socketpair()
        self._thread = threading.Thread(target=self._accept_loop, name=name, daemon=True)
        self._thread.start()

    def _accept_loop(self) -> None:
        """Accept connections (a thread each, as ThreadingTCPServer does) until stop() wakes it."""
        with selectors.DefaultSelector() as sel:
            sel.register(self._tcp, selectors.EVENT_READ)
            sel.register(self._wake_r, selectors.EVENT_READ)
            while not self._stop.is_set():
                for key, _ in sel.select():
                    if key.fileobj is self._tcp and not self._stop.is_set():
                        self._tcp._handle_request_noblock()

    def serve_connection(self, conn: socket.socket, rfile: BinaryIO, wfile: BinaryIO) -> None:
        """Read requests (from `rfile`, or the socket `conn` itself) and write answers until the peer
        or `stop()` ends it."""
        raise NotImplementedError

    @property
    def stopping(self) -> bool:
        """True once `stop()` was called: connection loops end."""
        return self._stop.is_set()

    def connections(self) -> list[socket.socket]:
        """The connections open now."""
        with self._conns_lock:
            return list(self._conns)

    def stop(self) -> None:
        """Stop listening and close every connection (its client sees the link go); once."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._wake_w.send(b"\0")
        self._thread.join(timeout=5.0)
        self._tcp.server_close()
        self._wake_r.close()
        self._wake_w.close()
        for conn in self.connections():
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
