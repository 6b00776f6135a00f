"""Station faults of a simulated station (`--fault KIND@SECONDS`, kinds in bench.fault_kinds): how each
hits its simulated device, and a World device that fires them at given simulated seconds."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

from bench.devices import StationError
from bench.fault_kinds import check_kind


def inject(handles: dict[str, Any], kind: str, timers: list[threading.Timer]) -> None:
    """Inject fault `kind` now into the simulator of its role (handles by role); a fault that
    clears itself gets a timer (appended to `timers`, for the station to cancel on close)."""
    fault = check_kind(kind)
    handle = handles.get(fault.role)
    if handle is None:
        raise StationError(f"fault {kind!r}: this station has no simulated {fault.role}")
    handle.inject(fault.inject, *fault.args)
    if fault.clears_after_wall_s is not None:
        timer = threading.Timer(fault.clears_after_wall_s, handle.inject, args=("none",))
        timer.daemon = True
        timer.start()
        timers.append(timer)


class FaultScheduler:
    """A World device that injects station faults at given simulated seconds (block-aligned)."""

    def __init__(self, inject: Callable[[str], None]) -> None:
        self.inject = inject
        self.pending: list[tuple[float, str]] = []
        self.fired: list[tuple[float, str]] = []

    def add(self, kind: str, at_s: float) -> None:
        self.pending.append((float(at_s), kind))
        self.pending.sort()

    def max_block_samples(self, world: Any) -> int | None:
        if not self.pending:
            return None
        left = self.pending[0][0] - world.t_s
        return max(1, int(math.ceil(left / world.sample_period_s - 1e-9)))

    def before_block(self, world: Any, t_s: float, n: int, dt_s: float) -> None:
        while self.pending and self.pending[0][0] <= t_s + 1e-9:
            at, kind = self.pending.pop(0)
            self.inject(kind)
            self.fired.append((t_s, kind))

    def after_block(self, world: Any, block: Any) -> None:
        pass


def stop_simulators(timers: list, handles: dict) -> None:
    """A simulated station's close: cancel its pending fault timers and stop every simulator it
    serves (one failing to stop does not keep the others running)."""
    for t in timers:
        t.cancel()
    for handle in handles.values():
        try:
            handle.stop()
        except Exception:  # noqa: BLE001
            pass
    handles.clear()
