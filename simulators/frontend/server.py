"""The simulated front end's SCPI socket server: asyncio on loopback, in its own thread.

Lines terminated by '\\n' come in; each is executed under `world.lock` and its reply (text, or a
definite-length block) goes out with a '\\n'.  Faults: "hang" reads commands and never answers,
"garble" corrupts every reply (two noise bytes, then the first half of the reply), "duplicate"
sends every reply twice; "none" clears.  `send_unsolicited(line)` writes a stray line now.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import numpy as np

from .model import FORCE_SOURCE, FrontEndModel

FAULTS = ("none", "hang", "garble", "duplicate")


class FrontEndServer:
    """Handle of a running simulated front end: resource_name, port, inject(), stop()."""

    def __init__(self, world: Any, model: FrontEndModel, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.world, self.model, self.host = world, model, host
        self.port = port
        self.fault = "none"
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.AbstractServer | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._thread = threading.Thread(target=self._run, name=f"frontend-sim:{port}", daemon=True)

    @property
    def resource_name(self) -> str:
        return f"TCPIP::{self.host}::{self.port}::SOCKET"

    def start(self) -> FrontEndServer:
        self.world.attach(self.model)
        self._thread.start()
        if not self._ready.wait(timeout=10.0) or self._error is not None:
            self.world.detach(self.model)
            raise RuntimeError(f"front-end simulator did not start: {self._error}")
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
        loop = self._loop
        if loop is None:
            raise RuntimeError("front-end simulator is not running")

        async def send() -> None:
            for writer in list(self._writers):
                writer.write(line + b"\n")
                await writer.drain()

        asyncio.run_coroutine_threadsafe(send(), loop).result(timeout=5.0)

    def last_capture(self, channel: int) -> np.ndarray | None:
        """The instrument's own copy of the last capture (for tests; never over the protocol)."""
        with self.world.lock:
            data = self.model.captured.get(channel)
            return None if data is None else data.copy()

    def stop(self) -> None:
        loop = self._loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        self._thread.join(timeout=5.0)
        self.world.detach(self.model)
        self.world.set_force(FORCE_SOURCE, None)

    def __enter__(self) -> FrontEndServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- the loop -------------------------------------------------------------------------------
    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            self._server = loop.run_until_complete(
                asyncio.start_server(self._serve_client, self.host, self.port, limit=1 << 20)
            )
            self.port = self._server.sockets[0].getsockname()[1]
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            self._server.close()
            for task in asyncio.all_tasks(loop):
                task.cancel()
            loop.run_until_complete(asyncio.sleep(0))
            loop.close()

    async def _serve_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._writers.add(writer)
        try:
            while True:
                try:
                    line = await reader.readuntil(b"\n")
                except asyncio.IncompleteReadError:
                    return
                except asyncio.LimitOverrunError:
                    return
                if self.fault == "hang":
                    continue
                text = line.decode("ascii", errors="replace").strip()
                with self.world.lock:
                    reply = self.model.execute(text, self.world)
                if reply is None:
                    continue
                if self.fault == "garble":
                    reply = b"\xff\xfe" + reply[: len(reply) // 2]
                writer.write(reply + b"\n")
                if self.fault == "duplicate":
                    writer.write(reply + b"\n")
                await writer.drain()
        except (ConnectionError, asyncio.CancelledError):
            return
        finally:
            self._writers.discard(writer)
            writer.close()
