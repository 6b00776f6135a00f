"""A pty whose master end is wired to a loopback TCP server: a serial-port path for a client
whose server only listens on TCP (the Modbus RTU table)."""

from __future__ import annotations

import os
import pty
import select
import socket
import threading
import tty


class PtyBridge:
    """Opens a pty and copies bytes both ways between its master and a TCP connection."""

    def __init__(self, host: str, port: int) -> None:
        self._master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        self._sock = socket.create_connection((host, port), timeout=5.0)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-bridge", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master, self._sock], [], [], 0.05)
            try:
                if self._master in ready:
                    self._sock.sendall(os.read(self._master, 4096))
                if self._sock in ready:
                    data = self._sock.recv(4096)
                    if not data:
                        return
                    os.write(self._master, data)
            except OSError:
                return

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._sock.close()
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
