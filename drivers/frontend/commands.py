"""The front end's SCPI command vocabulary and instrument ranges, shared by driver and simulator.

One place holds every command header, the instrument's own ranges and the SCPI error codes, so
the driver and the simulated instrument cannot drift apart.  `docs/frontend_scpi.md` documents
the command set for a lab engineer.
"""

from __future__ import annotations

# --- channels ----------------------------------------------------------------------------------
#: drive outputs and pickoff inputs: 1 = x coordinate, 2 = y coordinate
CHANNELS: tuple[int, ...] = (1, 2)

# --- instrument ranges (what the hardware accepts; a bench may be stricter) ----------------------
AMPLITUDE_RANGE_V: tuple[float, float] = (0.0, 10.0)
FREQUENCY_RANGE_HZ: tuple[float, float] = (1.0, 200_000.0)
PHASE_RANGE_DEG: tuple[float, float] = (-360.0, 360.0)
BIAS_RANGE_V: tuple[float, float] = (-50.0, 50.0)
INPUT_RANGES_V: tuple[float, ...] = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)
SAMPLE_RATE_RANGE_HZ: tuple[float, float] = (1_000.0, 2_000_000.0)
TIME_CONSTANT_RANGE_S: tuple[float, float] = (0.0, 100.0)
CAPTURE_POINTS_RANGE: tuple[int, int] = (1, 1_000_000)
ADC_BITS = 16

# --- defaults after *RST -------------------------------------------------------------------------
RST_FREQUENCY_HZ = 1_000.0
RST_INPUT_RANGE_V = 10.0
RST_SAMPLE_RATE_HZ = 1_000_000.0
RST_TIME_CONSTANT_S = 0.01
RST_CAPTURE_POINTS = 1_000
IDN_FIELDS = ("GYROBENCH", "FE-2CH", "SIM0001", "1.0")

# --- command headers ({ch} is the channel number) --------------------------------------------------
IDN = "*IDN?"
RST = "*RST"
CLS = "*CLS"
OPC = "*OPC?"
ESR = "*ESR?"
#: *ESE <n> / *ESE? (IEEE 488.2 event status enable, 0..255): the driver's transaction tag
ESE = "*ESE"
TAG_RANGE: tuple[int, int] = (1, 255)
SYST_ERR = "SYST:ERR?"
DRIVE_AMPLITUDE = "SOUR{ch}:VOLT"
DRIVE_FREQUENCY = "SOUR{ch}:FREQ"
DRIVE_PHASE = "SOUR{ch}:PHAS"
DRIVE_BIAS = "SOUR{ch}:BIAS"
OUTPUT = "OUTP{ch}"
INPUT_RANGE = "SENS{ch}:RANG"
SAMPLE_RATE = "SENS:SRAT"
LOCKIN_TC = "SENS:LOCK:TC"
LOCKIN_XY = "FETC:LOCK{ch}?"
LOCKIN_ALL = "FETC:LOCK:ALL?"
CAPTURE_POINTS = "CAPT:POIN"
CAPTURE_START = "INIT:CAPT"
CAPTURE_DONE = "CAPT:DONE?"
CAPTURE_FETCH = "FETC:CAPT{ch}?"

#: compound messages: units separated by ';' (each one a full command from the root)
SEPARATOR = ";"
TERMINATION = "\n"
#: capture blocks are little-endian float32 volts
BLOCK_DTYPE = "<f4"

# --- SCPI error codes (IEEE 488.2 / SCPI-99 standard numbers) --------------------------------------
NO_ERROR = (0, "No error")
COMMAND_ERROR = -100
SYNTAX_ERROR = -102
DATA_TYPE_ERROR = -104
PARAMETER_NOT_ALLOWED = -108
MISSING_PARAMETER = -109
UNDEFINED_HEADER = -113
HEADER_SUFFIX_OUT_OF_RANGE = -114
EXECUTION_ERROR = -200
SETTINGS_CONFLICT = -221
DATA_OUT_OF_RANGE = -222
ILLEGAL_PARAMETER_VALUE = -224
DATA_STALE = -230
QUEUE_OVERFLOW = -350
QUERY_ERROR = -400
ERROR_MESSAGES: dict[int, str] = {
    COMMAND_ERROR: "Command error",
    SYNTAX_ERROR: "Syntax error",
    DATA_TYPE_ERROR: "Data type error",
    PARAMETER_NOT_ALLOWED: "Parameter not allowed",
    MISSING_PARAMETER: "Missing parameter",
    UNDEFINED_HEADER: "Undefined header",
    HEADER_SUFFIX_OUT_OF_RANGE: "Header suffix out of range",
    EXECUTION_ERROR: "Execution error",
    SETTINGS_CONFLICT: "Settings conflict",
    DATA_OUT_OF_RANGE: "Data out of range",
    ILLEGAL_PARAMETER_VALUE: "Illegal parameter value",
    DATA_STALE: "Data corrupt or stale",
    QUEUE_OVERFLOW: "Queue overflow",
    QUERY_ERROR: "Query error",
}
ERROR_QUEUE_DEPTH = 16

# --- *ESR bits --------------------------------------------------------------------------------------
ESR_OPC = 1 << 0
ESR_QYE = 1 << 2
ESR_DDE = 1 << 3
ESR_EXE = 1 << 4
ESR_CME = 1 << 5


def esr_bit_for(code: int) -> int:
    """The *ESR bit an error code sets (-1xx command, -2xx execution, -3xx device, -4xx query)."""
    if -199 <= code <= -100:
        return ESR_CME
    if -299 <= code <= -200:
        return ESR_EXE
    if -399 <= code <= -300:
        return ESR_DDE
    if -499 <= code <= -400:
        return ESR_QYE
    return 0


def format_error(code: int, detail: str = "") -> str:
    """SYST:ERR? reply text: `<code>,"<message>[;detail]"`."""
    msg = ERROR_MESSAGES.get(code, NO_ERROR[1] if code == 0 else "Error")
    if detail:
        msg = f"{msg};{detail}"
    return f'{code},"{msg}"'


def parse_error(reply: str) -> tuple[int, str]:
    """Parse a SYST:ERR? reply into (code, message); raises ValueError when malformed."""
    code_text, _, msg = reply.partition(",")
    return int(code_text), msg.strip().strip('"')


def block_header(n_bytes: int) -> bytes:
    """IEEE 488.2 definite-length block header `#<ndigits><nbytes>`."""
    digits = str(n_bytes)
    if len(digits) > 9:
        raise ValueError(f"block of {n_bytes} bytes does not fit a definite-length header")
    return f"#{len(digits)}{digits}".encode("ascii")

#: long-form header nodes the instrument also accepts (the driver always sends short forms)
LONG_FORMS: dict[str, str] = {
    "SOURCE": "SOUR",
    "VOLTAGE": "VOLT",
    "FREQUENCY": "FREQ",
    "PHASE": "PHAS",
    "OUTPUT": "OUTP",
    "SENSE": "SENS",
    "RANGE": "RANG",
    "SRATE": "SRAT",
    "LOCKIN": "LOCK",
    "FETCH": "FETC",
    "CAPTURE": "CAPT",
    "POINTS": "POIN",
    "INITIATE": "INIT",
    "SYSTEM": "SYST",
    "ERROR": "ERR",
    "ROUTE": "ROUT",
}
#: ROUT:SLOT n: the slot a front end shared by several gyros is switched to (1 on a single-gyro bench)
SLOT_RANGE = (1, 64)
