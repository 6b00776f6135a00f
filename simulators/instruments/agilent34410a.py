"""A simulated Agilent/Keysight 34410A multimeter (the SCPI subset PyMeasure's Agilent34410A uses)
wired across the x drive electrode: `MEAS:VOLT:AC?` reads the rms drive voltage the world holds
(DRIVE_VOLTS_PER_FORCE per model unit of force), `MEAS:VOLT:DC?` its DC part (none).
Deterministic: it takes no random draws, so adding it to a station changes no other result."""

from __future__ import annotations

import math
from typing import Any

from .scpi import ScpiInstrument
from .server import InstrumentServer

DRIVE_VOLTS_PER_FORCE = 1.0  # peak electrode volts per model unit of x drive force


class Agilent34410AModel(ScpiInstrument):
    idn = "Agilent Technologies,34410A,SIM0002,2.35-2.35-0.09-46-09"

    def __init__(self, world: Any) -> None:
        super().__init__()
        self.world = world

    def command(self, header: str, args: list[str]) -> str | None:
        if header == "MEAS:VOLT:AC?":
            cx, sx = self.world.total_force[:2]
            return f"{DRIVE_VOLTS_PER_FORCE * math.hypot(cx, sx) / math.sqrt(2.0):.9E}"
        if header == "MEAS:VOLT:DC?":
            return f"{0.0:.9E}"
        return super().command(header, args)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[InstrumentServer, dict[str, Any]]:
    """A simulated station's 34410A (`simulator = "simulators.instruments.agilent34410a:serve_station"`)."""
    handle = InstrumentServer(world, Agilent34410AModel(world), "agilent34410a-sim")
    return handle, {"resource": handle.resource}
