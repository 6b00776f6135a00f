"""The subset of the Acutrol3000 command language (ACL, Acutronic TM-8004) gyrobench speaks, as
formatting and parsing shared by the driver and the simulator (docs/rate_table_acutronic.md).

Messages are ASCII lines ending in LF; commands in one message are separated by ';' and a
command that does not start with ':' stays in the subsystem of the one before it (TM-8004 2.3).
Only queries answer: the answers of one message come back as one line, joined by ';'.  The
driver ends every command message with `*ESR?`, so each message gets exactly one reply line
over TCP (port 9878, TM-9384C 1) and over GPIB alike, and a refused command shows up at once.
"""

from __future__ import annotations

import math

TERMINATOR = "\n"
TCP_PORT = 9878  # TM-9384C section 1
IDN = "Acutronic R&D USA,Acutrol3000,0,GYROBENCH-SIM-1.0"  # field layout of TM-8004 3.4

#: Limit-mode letters of the Command Processor (TM-8004 4.6): Off, Position, Rate
LIMIT_MODES = ("O", "P", "R")
#: :Mode? answers (TM-8004 4.7 shows single letters; some firmware answers the full word)
MODE_OFF, MODE_POSITION, MODE_RATE = "O", "P", "R"
#: :Interlock? answers (the states of TM-8004 4.5.3; see the doc for why these words)
INTERLOCK_STATES = ("Close", "Open", "Fault")

# IEEE 488.2 standard event status register bits (*ESR?, TM-8004 3.3)
ESR_OPC = 1 << 0
ESR_QUERY_ERROR = 1 << 2
ESR_DEVICE_ERROR = 1 << 3
ESR_EXECUTION_ERROR = 1 << 4
ESR_COMMAND_ERROR = 1 << 5
ESR_ERRORS = ESR_QUERY_ERROR | ESR_DEVICE_ERROR | ESR_EXECUTION_ERROR | ESR_COMMAND_ERROR
ESR_NAMES = {
    ESR_QUERY_ERROR: "query error",
    ESR_DEVICE_ERROR: "device error",
    ESR_EXECUTION_ERROR: "execution error (refused or out of range)",
    ESR_COMMAND_ERROR: "command error (unknown or bad syntax)",
}

# :Status:CSR? SI bits (system interlocks summary, TM-8004 4.11 register table)
SI_GLOBAL1 = 1 << 0  # global interlocks incl. the master interlock (the e-stop string)
SI_AXIS1_HW = 1 << 2  # axis 1 hardware interlock / fault (a door or guard switch)
SI_AXIS1_SW = 1 << 3  # axis 1 software-detected fault (velocity trip, drive fault)


def number(value: float) -> str:
    """A program-data number (<NRf>, TM-8004 2.6.1.2): the shortest text that reads back exactly."""
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{value!r} is not a finite number")
    return repr(v)


# --- commands (TM-8004 section numbers) ------------------------------------------------------
def demand_rate(axis: int, rate_dps: float) -> str:
    """4.3.6: rate demand."""
    return f":DEM:RATE {int(axis)},{number(rate_dps)}"


def demand_position(axis: int, angle_deg: float) -> str:
    """4.3.5: position demand."""
    return f":DEM:POS {int(axis)},{number(angle_deg)}"


def demand_acceleration(axis: int, accel_dps2: float) -> str:
    """4.3.1: acceleration demand."""
    return f":DEM:ACC {int(axis)},{number(accel_dps2)}"


def mode_off(axis: int) -> str:
    """4.7.3: Off mode, the controlled stop (rate 0 at the Off mode's acceleration limit)."""
    return f":MODE:OFF {int(axis)}"


def mode_position(axis: int) -> str:
    """4.7.4."""
    return f":MODE:POS {int(axis)}"


def mode_rate(axis: int) -> str:
    """4.7.5."""
    return f":MODE:RATE {int(axis)}"


def limit_rate(mode: str, axis: int, rate_dps: float) -> str:
    """4.6.8: rate limit of one Command Processor mode."""
    return f":LIM:RATE {_mode(mode)},{int(axis)},{number(rate_dps)}"


def limit_acceleration(mode: str, axis: int, accel_dps2: float) -> str:
    """4.6.2: acceleration limit of one mode."""
    return f":LIM:ACC {_mode(mode)},{int(axis)},{number(accel_dps2)}"


def limit_vtrip(mode: str, axis: int, rate_dps: float) -> str:
    """4.6.9: velocity trip (over-rate shutdown on the estimated rate)."""
    return f":LIM:VTR {_mode(mode)},{int(axis)},{number(rate_dps)}"


def interlock_close(axis: int) -> str:
    """4.5.1: close the interlock string and servo the axis (our `enable`)."""
    return f":INT:CLOSE {int(axis)}"


def interlock_open(axis: int) -> str:
    """4.5.5: orderly shut-down of the axis (our `disable`)."""
    return f":INT:OPEN {int(axis)}"


INTERLOCK_RESET = ":INT:RES"  # 4.5.6: unfreeze the latched interlock status of all axes


def lockout(on: bool) -> str:
    """4.14.2: keep other interfaces (the operator's GUI) from commanding motion."""
    return f":Utility:Lockout {'ON' if on else 'OFF'}"


def read_rate(axis: int) -> str:
    """4.10.5."""
    return f":READ:RATE? {int(axis)}"


def read_position(axis: int) -> str:
    """4.10.4."""
    return f":READ:POS? {int(axis)}"


def read_acceleration(axis: int) -> str:
    """4.10.1."""
    return f":READ:ACC? {int(axis)}"


def status_query(axis: int) -> str:
    """Rate, position, interlock state, mode and the system-interlock register in ONE message: the
    read-backs of one message come from the same controller frame (TM-8004 4.10.3)."""
    a = int(axis)
    return f"{read_rate(a)};POS? {a};:INT? {a};:MODE? {a};:STAT:CSR? SI"


def with_esr(command: str) -> str:
    """A command message that also answers: `*ESR?` appended (reading clears it, TM-8004 3.3)."""
    return f"{command};*ESR?"


def _mode(mode: str) -> str:
    m = mode.upper()[:1]
    if m not in LIMIT_MODES:
        raise ValueError(f"limit mode {mode!r}: expected one of {LIMIT_MODES}")
    return m


# --- replies -----------------------------------------------------------------------------------
def parse_esr(reply: str) -> int:
    """*ESR? answer -> the register (0..255); ValueError when malformed."""
    v = int(reply.strip())
    if not 0 <= v <= 255:
        raise ValueError(f"*ESR? answer {reply!r} outside 0..255")
    return v


def esr_text(esr: int) -> str:
    names = [text for bit, text in ESR_NAMES.items() if esr & bit]
    return f"*ESR?={esr}: " + (", ".join(names) or "no error bits")


def parse_mode(text: str) -> str:
    """:Mode? answer -> "O", "P", "R" (or the first letter of another mode)."""
    t = text.strip().upper()
    if not t or not t[0].isalpha():
        raise ValueError(f":Mode? answer {text!r} is not a mode")
    return t[0]


def parse_interlock(text: str) -> str:
    t = text.strip().capitalize()
    if t not in INTERLOCK_STATES:
        raise ValueError(f":Interlock? answer {text!r} is not one of {INTERLOCK_STATES}")
    return t


def parse_status(reply: str) -> tuple[float, float, str, str, int]:
    """status_query answer -> (rate_dps, angle_deg, interlock, mode, SI register); ValueError when malformed."""
    parts = reply.strip().split(";")
    if len(parts) != 5:
        raise ValueError(f"status reply {reply!r} does not have 5 fields")
    rate, angle = float(parts[0]), float(parts[1])
    if not (math.isfinite(rate) and math.isfinite(angle)):
        raise ValueError(f"status reply {reply!r} has a non-finite rate or position")
    si = int(parts[4])
    if not 0 <= si < 1 << 16:
        raise ValueError(f"status reply {reply!r}: SI register out of range")
    return rate, angle, parse_interlock(parts[2]), parse_mode(parts[3]), si


def format_float(value: float) -> str:
    """Response data in FLOat format: <NR2>, no exponent (TM-8004 4.14.1)."""
    return f"{float(value):.6f}"


# --- the ACL parser (simulator side) -------------------------------------------------------------
#: the command tree the simulator knows: subsystem -> its nodes, in the order a one-letter short
#: form resolves (TM-8004's own short examples: :D:P, :D:R, :M:O, :I:C, :L:R, :L:V, :R:A ...)
TREE: dict[str, tuple[str, ...]] = {
    "DEMAND": ("POSITION", "RATE", "ACCELERATION"),
    "INTERLOCK": ("CLOSE", "OPEN", "RESET"),
    "LIMIT": ("RATE", "ACCELERATION", "VTRIP", "VELOCITYTRIP"),
    "MODE": ("OFF", "POSITION", "RATE"),
    "READ": ("ACCELERATION", "RATE", "POSITION"),
    "STATUS": ("CSR",),
    "UTILITY": ("LOCKOUT", "REMOTELOCKOUT"),
}
ROOTS = ("DEMAND", "INTERLOCK", "LIMIT", "MODE", "READ", "STATUS", "UTILITY")


def resolve(token: str, names: tuple[str, ...]) -> str | None:
    """A (short) mnemonic -> the full name it abbreviates, or None (case-insensitive prefix)."""
    t = token.upper()
    if not t:
        return None
    for n in names:
        if n == t:
            return n
    for n in names:
        if n.startswith(t):
            return n
    return None


BAD = ("?BAD",)  # the path of a command that did not parse (strict=False)


def split_message(line: str, *, strict: bool = True) -> list[tuple[tuple[str, ...], bool, list[str]]]:
    """One program message -> [(full header path, is_query, args)], resolving short forms and the
    tree position (TM-8004 2.3).  A common command (`*IDN?`) has the path ("*IDN",).  ValueError
    names the first bad command; with strict=False a bad command becomes (BAD, False, [why])."""
    out: list[tuple[tuple[str, ...], bool, list[str]]] = []
    current: tuple[str, ...] = ()
    for raw in line.strip().split(";"):
        try:
            current = _one_header(raw.strip(), current, out)
        except ValueError as exc:
            if strict:
                raise
            out.append((BAD, False, [str(exc)]))
    return out


def _one_header(cmd: str, current: tuple[str, ...], out: list) -> tuple[str, ...]:
    """Parse one command into `out`; return the new tree position."""
    if not cmd:
        raise ValueError("empty command")
    head, _, argtext = cmd.partition(" ")
    args = [a.strip() for a in argtext.split(",")] if argtext.strip() else []
    query = head.endswith("?")
    head = head.rstrip("?")
    if head.startswith("*"):
        out.append(((head.upper(),), query, args))
        return current
    if head.startswith(":"):
        parts, base = head[1:].split(":"), ()
    else:
        parts, base = head.split(":"), current[:-1]
    path = list(base)
    for token in parts:
        names = ROOTS if not path else TREE.get(path[0], ()) if len(path) == 1 else ()
        full = resolve(token, names)
        if full is None:
            raise ValueError(f"unknown mnemonic {token!r} in {cmd!r}")
        path.append(full)
    if not path:
        raise ValueError(f"no header in {cmd!r}")
    out.append((tuple(path), query, args))
    return tuple(path)
