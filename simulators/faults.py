"""Station faults of a simulated station (`--fault KIND@SECONDS`): the kinds, which simulated device
each one hits and how, a World device that fires them at given simulated seconds, and the parser."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bench.devices import StationError
from bench.validation import ValidationError, convert


@dataclass(frozen=True)
class FaultKind:
    """A station fault: the role whose simulator it hits, the simulator's own inject kind and
    arguments, and (optionally) the wall seconds after which the simulator clears it itself."""

    role: str
    inject: str
    args: tuple[Any, ...] = ()
    clears_after_wall_s: float | None = None


#: wall seconds a simulated front-end hang lasts (its own watchdog then reboots it)
FRONTEND_HANG_WALL_S = 3.0
#: station fault kinds (`--fault KIND@SECONDS`)
FAULTS: dict[str, FaultKind] = {
    "link-drop": FaultKind("fpga", "link-drop"),
    "link-corrupt": FaultKind("fpga", "corrupt", (0.05,)),
    "table-estop": FaultKind("table", "estop"),
    "table-fault": FaultKind("table", "fault"),
    "frontend-hang": FaultKind("frontend", "hang", clears_after_wall_s=FRONTEND_HANG_WALL_S),
}


def check_kind(kind: str) -> FaultKind:
    if kind not in FAULTS:
        raise StationError(f"fault {kind!r} is not one of {', '.join(FAULTS)}")
    return FAULTS[kind]


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


def parse_fault(text: str) -> tuple[str, float]:
    """`KIND@SECONDS` -> (kind, seconds)."""
    kind, sep, at = text.partition("@")
    if not sep:
        raise StationError(f"--fault {text!r}: expected KIND@SECONDS, e.g. link-drop@2.5")
    if kind not in FAULTS:
        raise StationError(f"--fault {text!r}: kind {kind!r} is not one of {', '.join(FAULTS)}")
    try:
        at_s = float(at)
    except ValueError:
        raise StationError(f"--fault {text!r}: {at!r} is not a number of seconds") from None
    try:
        at_s = convert("time", at_s, float, low=0.0, unit="s")
    except ValidationError as exc:
        raise StationError(f"--fault {text!r}: {exc}") from None
    return kind, at_s


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
