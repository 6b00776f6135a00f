"""The simulated front end's SCPI socket server on loopback (the shared threaded line server).

Lines terminated by '\\n' come in; each is executed under `world.lock` and its reply (text, or a
definite-length block) goes out with a '\\n'.  Faults: "hang" reads commands and never answers,
"garble" corrupts every reply (two noise bytes, then the first half of the reply), "duplicate"
sends every reply twice; "none" clears.  `send_unsolicited(line)` writes a stray line now.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from simulators.line_server import LineServer

from .model import FORCE_SOURCE, FrontEndModel

FAULTS = ("none", "hang", "garble", "duplicate")
MAX_LINE = 1 << 20  # a longer command line closes the connection unanswered


class FrontEndServer:
    """Handle of a running simulated front end: resource_name, port, inject(), stop()."""

    def __init__(self, world: Any, model: FrontEndModel, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.world, self.model, self.host = world, model, host
        self.port = port
        self.fault = "none"
        self._server: LineServer | None = None

    @property
    def resource_name(self) -> str:
        return f"TCPIP::{self.host}::{self.port}::SOCKET"

    def start(self) -> FrontEndServer:
        self.world.attach(self.model)
        try:
            self._server = LineServer(self._answer, self.host, self.port, name=f"frontend-sim:{self.port}",
                                      max_line=MAX_LINE, whole_lines=True)
        except OSError as exc:
            self.world.detach(self.model)
            raise RuntimeError(f"front-end simulator did not start: {exc}") from exc
        self.port = self._server.port
        return self

    def inject(self, fault: str | None) -> None:
        """Inject a fault: "hang" (stop answering), "garble" (corrupt replies), "duplicate" (every
        reply twice), "none"/None (clear)."""
        fault = "none" if fault is None else fault
        if fault not in FAULTS:
            raise ValueError(f"unknown front-end fault {fault!r}; known: {FAULTS}")
        self.fault = fault

    def send_unsolicited(self, line: bytes) -> None:
        """Write one line (a '\\n' is added) to every connected client now, answering nothing."""
        if self._server is None:
            raise RuntimeError("front-end simulator is not running")
        self._server.send_all(line + b"\n")

    def last_capture(self, channel: int) -> np.ndarray | None:
        """The instrument's own copy of the last capture (for tests; never over the protocol)."""
        with self.world.lock:
            data = self.model.captured.get(channel)
            return None if data is None else data.copy()

    def stop(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None
        self.world.detach(self.model)
        self.world.set_force(FORCE_SOURCE, None)

    def __enter__(self) -> FrontEndServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _answer(self, line: str) -> bytes | None:
        """One command line's reply bytes (with their '\\n'), None for silence; faults applied."""
        if self.fault == "hang":
            return None
        with self.world.lock:
            reply = self.model.execute(line.strip(), self.world)
        if reply is None:
            return None
        if self.fault == "garble":
            reply = b"\xff\xfe" + reply[: len(reply) // 2]
        out = reply + b"\n"
        return out + out if self.fault == "duplicate" else out
