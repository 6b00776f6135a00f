"""One simulated SCPI instrument served on a loopback socket, with the faults a test injects."""

from __future__ import annotations

from typing import Any

from simulators.line_server import TextLineServer

from .scpi import ScpiInstrument


class InstrumentServer:
    """Handle of one simulated instrument: `.resource`, `.model`, `inject`, `stop`."""

    def __init__(self, world: Any, model: ScpiInstrument, name: str) -> None:
        self.world, self.model = world, model
        self.server = TextLineServer(world, model.execute, name=name)

    @property
    def resource(self) -> str:
        return self.server.resource_name

    def inject(self, fault: str | None) -> None:
        """ "hang": stop answering; "garble": spoil every answer; None/"none": clear."""
        fault = "none" if fault is None else fault
        if fault not in ("none", "hang", "garble"):
            raise ValueError(f"unknown instrument fault {fault!r}; known: none, hang, garble")
        self.server.hang, self.server.garble = fault == "hang", fault == "garble"

    def stop(self) -> None:
        self.server.stop()
