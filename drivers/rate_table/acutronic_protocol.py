"""The subset of the Acutrol3000 command language (ACL, Acutronic TM-8004) gyrobench speaks, as
formatting and parsing shared by the driver and the simulator (docs/rate_table_acutronic.md).

Messages are ASCII lines ending in LF; commands in one message are separated by ';' and a
command that does not start with ':' stays in the subsystem of the one before it (TM-8004 2.3).
The answers of one message come back together, joined by ';'; how they are framed (GPIB lines,
or the TCP header) is the last section's part.
"""

from __future__ import annotations

import math
import struct

TERMINATOR = "\n"
TCP_PORT = 9878  # TM-9384C section 1
IDN = "Acutronic R&D USA,Acutrol3000,0,GYROBENCH-SIM-1.0"  # field layout of TM-8004 3.4

#: Limit-mode letters of the Command Processor (TM-8004 4.6): Off, Position, Rate
LIMIT_MODES = ("O", "P", "R")
#: :Mode? answers (TM-8004 4.7 shows single letters; some firmware answers the full word)
MODE_OFF, MODE_POSITION, MODE_RATE = "O", "P", "R"
#: :Interlock? answers (the states of TM-8004 4.5.3; see the doc for why these words)
INTERLOCK_STATES = ("Close", "Open", "Fault")

# *ESR? (TM-8004 3.3).  The manual gives no bit table of the Acutrol3000's own; the one it prints
# after 3.9 is the ACT2000's (bit 3 "all axis profiles complete" is a normal event there, bit 0 a
# servo fault), while IEEE 488.2 numbers 2 query, 3 device, 4 execution, 5 command error.  The
# driver raises only on the bits that are errors in both: 2, 4 and 5 (docs: "*ESR? bits").
ESR_BIT0 = 1 << 0  # ACT2000: MIS servo fault (IEEE 488.2: operation complete)
ESR_BIT2 = 1 << 2  # ACT2000: bad device dependent message (IEEE: query error)
ESR_BIT3 = 1 << 3  # ACT2000: all axis profiles complete, a normal event (IEEE: device error)
ESR_BIT4 = 1 << 4  # ACT2000: fault during a mode transition (IEEE: execution error)
ESR_BIT5 = 1 << 5  # ACT2000: axis timed out, did not respond as commanded (IEEE: command error)
ESR_ERRORS = ESR_BIT2 | ESR_BIT4 | ESR_BIT5
ESR_TABLES = ("ieee488", "act2000")
ESR_NAMES = {
    ESR_BIT2: "bit 2: bad message / query error",
    ESR_BIT4: "bit 4: mode transition fault / execution error (refused or out of range)",
    ESR_BIT5: "bit 5: axis did not respond as commanded / command error (unknown or bad syntax)",
}

# :Status:CSR? SI, the system interlocks summary (TM-8004 4.11 register table): bit 0 sums
# G1INTLK (axes 1-3 interlock inputs, GLOBAL1-3 and the master interlock), bit 1 G2INTLK (axes
# 4-6); then per axis n, bit 2n its hardware interlock/fault register A(n)INTLK, bit 2n+1 its
# software-detected fault A(n)SWFLT.  SI bit 0 is set by a door as much as by the e-stop.
SI_G1INTLK = 1 << 0
SI_G2INTLK = 1 << 1

# A(n)INTLK, one axis's hardware interlock register (TM-8004 appendix B 6.3, TM-9385A table 2):
# bits 0-5 the general-purpose discrete inputs, 6 the power-amplifier acknowledge, 7-8 the
# interlock inputs INTLK1/INTLK2, 9 the master interlock (e-stop string and the front-panel
# disable, TM-9385A 3.3.4), 10-15 the axis interface module's own faults.  A set bit is failed.
INTLK_MASTER = 1 << 9
INTLK_PA_ACK = 1 << 6
INTLK_DOOR1 = 1 << 7  # INTLK1: where the simulator wires its door switch
INTLK_GUARDS = 0b1_1011_1111  # bits 0-5, 7, 8: door and guard switches, wired by the lab
INTLK_AIM_FAULTS = 0xFC00


def si_axis_interlock(axis: int) -> int:
    """SI bit of A(axis)INTLK."""
    return 1 << (2 * int(axis))


def si_axis_software_fault(axis: int) -> int:
    """SI bit of A(axis)SWFLT."""
    return 1 << (2 * int(axis) + 1)


def axis_conditions(axis: int, si: int, intlk: int) -> tuple[bool, bool, bool]:
    """(e-stop, door/guard open, fault) of one axis from the SI summary and its A(n)INTLK register:
    the master interlock is the e-stop, an interlock or guard input a door, the software fault bit,
    the drive acknowledge and the interface module's faults a fault."""
    estop = bool(intlk & INTLK_MASTER)
    door = bool(intlk & INTLK_GUARDS)
    fault = bool(si & si_axis_software_fault(axis)) or bool(intlk & (INTLK_PA_ACK | INTLK_AIM_FAULTS))
    return estop, door, fault


#: :Utility:Format answers (TM-8004 4.14.1); the driver reads and writes FLOAT (ASCII) numbers only
FORMAT_FLOAT, FORMAT_BINARY = "FLOAT", "BINARY"
FORMAT_QUERY = ":U:F?"
SET_FORMAT_FLOAT = ":U:F F"  # the manual's own example
#: engineering units the driver accepts for an axis (:Configure:Scaling, TM-8004 4.2.26; default deg)
DEGREE_UNITS = ("DEG", "DEGREE", "DEGREES")
IEEE488_LOCAL = ":Interface:IEEE488:Local"  # 4.4.2: the IEEE-488 interface back to local


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
    """Rate, position, interlock state, mode, the system-interlock summary and the axis's own
    interlock register in ONE message: the read-backs of one message come from the same controller
    frame (TM-8004 4.10.3)."""
    a = int(axis)
    return f"{read_rate(a)};POS? {a};:INT? {a};:MODE? {a};:STAT:CSR? SI;CSR? A{a}INTLK"


STATUS_FIELDS = 6


def scaling_query(axis: int) -> str:
    """4.2.26: the axis's demand scaling, whose 4th field is its engineering unit."""
    return f":CONF:SCAL? {int(axis)}"


def query_error(code: int) -> str:
    """4.9.1: the controller's description of an error code."""
    return f":Q:E? {int(code)}"


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


# Error codes in the tcp framing's header.  TM-8004 points to a list of them (its appendix C)
# that the TM-8004-C copy does not hold; these are the simulator's, and the driver treats any
# non-zero code as a refusal and asks :Query:Error? for the controller's own words.
ERR_NONE = 0
ERR_UNKNOWN = 1  # unknown command (ignored)
ERR_SYNTAX = 2  # wrong number or form of arguments
ERR_RANGE = 3  # axis or value out of range
ERR_REFUSED = 4  # refused in the axis's state (not servoed, tripped)
ERR_INTERFACE = 5  # not allowed from this interface (:Utility:Format from a non-GPIB link)
ERROR_TEXT = {
    ERR_UNKNOWN: "unknown command",
    ERR_SYNTAX: "bad arguments",
    ERR_RANGE: "axis or value out of range",
    ERR_REFUSED: "refused in the axis's present state",
    ERR_INTERFACE: "only the IEEE-488 controller in charge may issue this command",
}


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


def parse_status(reply: str) -> tuple[float, float, str, str, int, int]:
    """status_query answer -> (rate_dps, angle_deg, interlock, mode, SI, A(n)INTLK); ValueError
    when malformed: a field count other than 6 (a query the controller did not know answers
    nothing and shifts the fields after it), an empty field (a known query that failed)."""
    parts = reply.strip().split(";")
    if len(parts) != STATUS_FIELDS:
        raise ValueError(f"status reply {reply!r} has {len(parts)} fields, expected {STATUS_FIELDS}")
    if any(not p.strip() for p in parts):
        raise ValueError(f"status reply {reply!r} has an empty field (a query the controller refused)")
    rate, angle = float(parts[0]), float(parts[1])
    if not (math.isfinite(rate) and math.isfinite(angle)):
        raise ValueError(f"status reply {reply!r} has a non-finite rate or position")
    si, intlk = _register(parts[4], reply), _register(parts[5], reply)
    return rate, angle, parse_interlock(parts[2]), parse_mode(parts[3]), si, intlk


def _register(text: str, reply: str) -> int:
    v = int(text.strip())
    if not 0 <= v < 1 << 16:
        raise ValueError(f"status reply {reply!r}: register {v} outside 16 bits")
    return v


def parse_scaling(reply: str) -> tuple[float, str]:
    """:Configure:Scaling? answer -> (full-scale position, engineering unit); ValueError when malformed."""
    parts = [p.strip().strip('"') for p in reply.strip().split(",")]
    if len(parts) < 4 or not parts[3]:
        raise ValueError(f":Configure:Scaling? answer {reply!r} has no engineering unit (4th field)")
    return float(parts[0]), parts[3]


def format_float(value: float) -> str:
    """Response data in FLOat format: <NR2>, no exponent (TM-8004 4.14.1)."""
    return f"{float(value):.6f}"


# --- the ACL parser (simulator side) -------------------------------------------------------------
#: the command tree the simulator knows: a node's path -> its children, in the order a one-letter
#: short form resolves (TM-8004's own short examples: :D:P, :D:R, :M:O, :I:C, :L:R, :U:F ...)
TREE: dict[tuple[str, ...], tuple[str, ...]] = {
    (): ("CONFIGURE", "DEMAND", "INTERLOCK", "INTERFACE", "LIMIT", "MODE", "QUERY", "READ", "STATUS", "UTILITY"),
    ("CONFIGURE",): ("SCALING",),
    ("DEMAND",): ("POSITION", "RATE", "ACCELERATION"),
    ("INTERLOCK",): ("CLOSE", "OPEN", "RESET"),
    ("INTERFACE",): ("IEEE488",),
    ("INTERFACE", "IEEE488"): ("LOCAL",),
    ("LIMIT",): ("RATE", "ACCELERATION", "VTRIP", "VELOCITYTRIP"),
    ("MODE",): ("OFF", "POSITION", "RATE"),
    ("QUERY",): ("ERROR",),
    ("READ",): ("ACCELERATION", "RATE", "POSITION"),
    ("STATUS",): ("CSR",),
    ("UTILITY",): ("FORMAT", "LOCKOUT", "REMOTELOCKOUT"),
}
ROOTS = TREE[()]


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
        full = resolve(token, TREE.get(tuple(path), ()))
        if full is None:
            raise ValueError(f"unknown mnemonic {token!r} in {cmd!r}")
        path.append(full)
    if not path:
        raise ValueError(f"no header in {cmd!r}")
    out.append((tuple(path), query, args))
    return tuple(path)


# --- answer framing (TM-8004 section 2) ----------------------------------------------------------
# The two ways an Acutrol3000 frames its answers (TM-8004 section 2), shared by the driver and the
# simulator (docs/rate_table_acutronic.md, "Answers: two framings").
#
# - **gpib** (IEEE-488): only a message with a query is answered, one line ending in LF; a command
#   message gets no answer, so the driver appends `*ESR?` to learn whether it was refused.
# - **tcp** (Ethernet port 9878, and every other non-GPIB link): every message is answered.  The
#   answer is an 8-byte header, a 32-bit error code then a 32-bit length of the text, little endian
#   (TM-9374A 3.4.2 gives this layout for the ACL channel; TM-8004 5.1.1: Intel byte order), then
#   that many ASCII characters with no terminator.  A command's text is `OK` (Acutronic's own
#   client strips 8 bytes and compares with "OK"); a refused command's text is empty.
#
# Host messages end in LF on both (a CR before it is allowed, a CR alone ends nothing: TM-8004 2.4)
# and may hold up to 32,768 characters (TM-8004 2.5); longer ones are lost by the controller.


FRAMINGS = ("tcp", "gpib")
HEADER = struct.Struct("<iI")  # error code (0: none), length of the text that follows
HEADER_SIZE = HEADER.size
COMMAND_OK = "OK"
MAX_MESSAGE_CHARS = 32768  # TM-8004 2.5, the message without its terminator


def framing_for(resource: str, framing: str = "auto") -> str:
    """The framing a link uses: "tcp" or "gpib" as given, or chosen by the transport ("auto"):
    a GPIB resource speaks lines, a TCP socket (host/port or a VISA socket) the header."""
    f = framing.strip().lower()
    if f == "auto":
        return "gpib" if resource.strip().upper().startswith("GPIB") else "tcp"
    if f not in FRAMINGS:
        raise ValueError(f"framing {framing!r}: expected 'auto', 'tcp' or 'gpib'")
    return f


def message_bytes(message: str) -> bytes:
    """One host message as sent: ASCII, LF-terminated; ValueError when it cannot be one message."""
    if "\n" in message or "\r" in message:
        raise ValueError(f"message {message[:60]!r} holds a line break")
    if len(message) > MAX_MESSAGE_CHARS:
        raise ValueError(f"message of {len(message)} characters: the controller takes {MAX_MESSAGE_CHARS} at most")
    return message.encode("ascii") + b"\n"


def message_text(raw: str) -> str | None:
    """A received line -> the message (its LF and a CR before it removed); None when it is not a
    whole message (no LF: a CR alone ends nothing) or is too long, which the controller loses
    (TM-8004 2.5)."""
    if not raw.endswith("\n"):
        return None
    body = raw[:-1]
    if body.endswith("\r"):
        body = body[:-1]
    if len(body) > MAX_MESSAGE_CHARS:
        return None
    return body


def tcp_answer(error_code: int, text: str) -> bytes:
    """The tcp framing's answer: header then text."""
    data = text.encode("ascii", "replace")
    return HEADER.pack(int(error_code), len(data)) + data


def parse_tcp_header(raw: bytes) -> tuple[int, int]:
    """8 header bytes -> (error code, text length); ValueError when not 8 bytes or the length is absurd."""
    if len(raw) != HEADER_SIZE:
        raise ValueError(f"answer header of {len(raw)} bytes, expected {HEADER_SIZE}")
    code, length = HEADER.unpack(raw)
    if length > MAX_MESSAGE_CHARS:
        raise ValueError(f"answer header gives a length of {length}, above the controller's {MAX_MESSAGE_CHARS}")
    return code, length


def gpib_answer(text: str) -> bytes:
    """The gpib framing's answer: one line."""
    return text.encode("ascii", "replace") + b"\n"
