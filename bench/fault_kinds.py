"""The station fault kinds (`--fault KIND@SECONDS`): each kind's name, the role of the simulated
device it hits and the simulator's own inject kind; the parser of the option.  A data contract
between the faces that take the option, the simulated station that schedules it and the
simulators that act on it (simulators.faults)."""

from __future__ import annotations

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
