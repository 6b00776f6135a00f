"""What the window asks of whatever runs procedures: the engine on a station, or a replay.

The window only calls these methods and listens to `bus`; every run executes in a worker
thread that publishes engine events, never touching a widget.
"""

from __future__ import annotations

from typing import Any, Protocol

from bench.engine.events import EventBus
from bench.engine.params import Param

SPEEDS: tuple[tuple[str, float], ...] = (
    ("real time", 1.0),
    ("10x", 10.0),
    ("100x", 100.0),
    ("max", float("inf")),
)


class GuiBackend(Protocol):
    """Runs procedures in a worker thread and publishes their events on `bus`."""

    bus: EventBus
    station_name: str
    simulated: bool

    def procedures(self) -> dict[str, tuple[Param, ...]]:
        """Procedure name -> its declared parameters (the engine's own Param objects), in order."""
        ...

    def start(self, procedure: str, values: dict[str, Any]) -> None:
        """Start a run in a worker thread (ValueError naming the value on bad input)."""
        ...

    def pause(self) -> None: ...

    def resume(self) -> None: ...

    def abort(self) -> None:
        """Ask the run to stop; the engine brings the station to its safe state and says so in
        RunFinished(safe_state=True) once confirmed."""
        ...

    def running(self) -> bool: ...

    def set_speed(self, speed: float) -> None:
        """Simulated station: the world's clock speed (x real time, inf = as fast as possible)."""
        ...

    def close(self) -> None:
        """Abort any run, wait for its thread, release the station."""
        ...
