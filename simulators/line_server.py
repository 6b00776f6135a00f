"""A line-oriented instrument on a loopback TCP socket: LF-terminated commands in, each answered
(or not) by a reply function.  `LineServer` is the socket (shared by the simulated tables' ASCII
and ACL dialects); `TextLineServer` answers `execute(line)` under the world's lock with the
faults a test injects (`hang`, `garble`), for the SCPI instruments (VISA `TCPIP::host::port::SOCKET`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, BinaryIO

from .tcp_server import LoopbackTcpServer


class LineServer(LoopbackTcpServer):
    """Serve `reply(line) -> bytes | None` on a loopback port (0: a free one) until `stop()`."""

    def __init__(self, reply: Callable[[str], bytes | None], host: str = "127.0.0.1", port: int = 0,
                 name: str = "line-server", max_line: int = 65536, whole_lines: bool = False,
                 drop_long_lines: bool = False) -> None:
        """whole_lines: a line without its LF (too long, or cut by the peer closing) ends the
        connection unanswered instead of being answered as it is.  drop_long_lines: a line longer
        than max_line is read to its LF and dropped unanswered (an instrument's input buffer
        overflowing), the connection stays."""
        self.reply = reply
        self.max_line, self.whole_lines, self.drop_long_lines = max_line, whole_lines, drop_long_lines
        super().__init__(host, port, name)

    def serve_connection(self, conn: Any, rfile: BinaryIO, wfile: BinaryIO) -> None:
        """Answer each line read until the peer closes, a line breaks the rules, or `stop()`."""
        while not self.stopping:
            raw = rfile.readline(self.max_line)
            if self.drop_long_lines and len(raw) == self.max_line and not raw.endswith(b"\n"):
                while raw and not raw.endswith(b"\n"):
                    raw = rfile.readline(self.max_line)
                continue
            if not raw or (self.whole_lines and not raw.endswith(b"\n")):
                return
            out = self.reply(raw.decode("ascii", "replace"))
            if out is not None:
                wfile.write(out)

    def send_all(self, data: bytes) -> None:
        """Write `data` to every connected client now (an unsolicited message)."""
        for conn in self.connections():
            try:
                conn.sendall(data)
            except OSError:
                pass

    @property
    def resource_name(self) -> str:
        """The socket as a VISA resource (pyvisa-py)."""
        return f"TCPIP::{self.host}::{self.port}::SOCKET"


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
