"""Command set of the ASCII rate-table controller (docs/rate_table_ascii.md), shared by the
driver and the simulator.

Lines end in LF (CR LF accepted); commands on one line are separated by ';'.  Every line gets
exactly one reply line: the query answers joined by ';', or "OK" when the line had no query, or
"ERR <code>,<text>" for the first command that failed (the rest of the line is not executed).
"""

from __future__ import annotations

import math

TERMINATOR = "\n"
IDN = "GYROBENCH,RT-ASCII,0,1.0"

# settings (each takes one number, except MODE and ENA)
CMD_MODE = "MODE"  # MODE RATE | POS | STOP: engage the mode with the current setpoints
CMD_RATE = "RATE"  # RATE <deg/s>: rate setpoint (live in RATE mode)
CMD_POS = "POS"  # POS <deg>: position target in [0, 360)
CMD_SPD = "SPD"  # SPD <deg/s>: traverse speed of position moves, > 0
CMD_ACC = "ACC"  # ACC <deg/s^2>: acceleration limit, > 0 (live)
CMD_ENA = "ENA"  # ENA 1 | 0: drive enable
CMD_STOP = "STOP"  # STOP: ramp to rest at ACC (same as MODE STOP)
CMD_FRST = "FRST"  # FRST: clear latched e-stop / fault / watchdog whose cause is gone
CMD_HB = "HB"  # HB: feed the watchdog (every setting command also feeds it)
CMD_WDT = "WDT"  # WDT <s>: watchdog timeout, wall clock; 0 disables
# queries
Q_IDN = "*IDN?"
Q_STAT = "STAT?"  # <rate deg/s>,<angle deg>,<status bits>,<fault code>: one consistent read
Q_MODE = "MODE?"
Q_WDT = "WDT?"

MODE_NAMES = {"STOP": 0, "RATE": 1, "POS": 2}
MODE_BY_NUMBER = {v: k for k, v in MODE_NAMES.items()}

# errors, numbered after IEEE 488.2 / SCPI
ERR_COMMAND = -100  # unknown mnemonic or bad syntax
ERR_DATA_TYPE = -104  # argument is not a number
ERR_SETTINGS_CONFLICT = -221  # refused in this state (not enabled, tripped)
ERR_OUT_OF_RANGE = -222  # value outside the controller's range


def format_status(rate_dps: float, angle_deg: float, bits: int, fault_code: int) -> str:
    """STAT? reply body (status bits and fault codes as in modbus_protocol)."""
    return f"{rate_dps:+.6f},{angle_deg:.6f},{int(bits)},{int(fault_code)}"


def parse_status(line: str) -> tuple[float, float, int, int]:
    """STAT? reply -> (rate_dps, angle_deg, bits, fault_code); ValueError when malformed."""
    parts = line.strip().split(",")
    if len(parts) != 4:
        raise ValueError(f"STAT? reply {line!r} does not have 4 fields")
    rate, angle = float(parts[0]), float(parts[1])
    if not (math.isfinite(rate) and math.isfinite(angle)):
        raise ValueError(f"STAT? reply {line!r} has a non-finite rate or angle")
    bits, code = int(parts[2]), int(parts[3])
    if not (0 <= bits < 1 << 16 and 0 <= code < 1 << 16):
        raise ValueError(f"STAT? reply {line!r} has status fields out of range")
    return rate, angle, bits, code


def parse_error(line: str) -> tuple[int, str] | None:
    """ "ERR <code>,<text>" -> (code, text); None if the line is not an error."""
    if not line.startswith("ERR "):
        return None
    code, _, text = line[4:].partition(",")
    try:
        return int(code), text.strip().strip('"')
    except ValueError:
        return ERR_COMMAND, line
