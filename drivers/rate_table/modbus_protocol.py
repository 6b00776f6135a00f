"""Register map of the Modbus rate-table controller (docs/rate_table_modbus.md), shared by the
driver and the simulator so the two cannot drift apart.

Addresses are protocol addresses from 0.  Floats are IEEE-754 float32 across two registers,
high word first ("big" word order), each word big-endian as Modbus sends it.
"""

from __future__ import annotations

import math
import struct

# --- holding registers (FC3 read, FC6/FC16 write) ----------------------------------------------
HR_MODE = 0  # 0 stop, 1 rate, 2 position
HR_RATE_CMD = 1  # float32 deg/s (2 regs): rate mode setpoint; position mode traverse speed (magnitude)
HR_ANGLE_CMD = 3  # float32 deg (2 regs): position mode target in [0, 360)
HR_ACCEL = 5  # float32 deg/s^2 (2 regs): acceleration limit of the profile, > 0
HR_ENABLE = 7  # 1 enable the drive, 0 disable (brakes to rest first)
HR_FAULT_RESET = 8  # write 1: clear latched e-stop / fault / watchdog whose cause is gone
HR_HEARTBEAT = 9  # any write feeds the watchdog (so does every write to any holding register)
HR_WATCHDOG_MS = 10  # watchdog timeout in wall-clock ms; 0 disables it
HR_COUNT = 11
#: the command block a driver writes in one FC16 transaction: mode, rate, angle, accel
CMD_BLOCK_START = HR_MODE
CMD_BLOCK_COUNT = 7

MODE_STOP, MODE_RATE, MODE_POSITION = 0, 1, 2
MODES = (MODE_STOP, MODE_RATE, MODE_POSITION)

# --- input registers (FC4) ----------------------------------------------------------------------
IR_RATE_ACT = 0  # float32 deg/s
IR_ANGLE_ACT = 2  # float32 deg in [0, 360)
IR_STATUS = 4  # status bits below
IR_FAULT_CODE = 5  # first latched cause, FAULT_* below
IR_COUNT = 6  # one FC4 read of 6 registers gives rate, angle, status and fault code

# --- status bits (IR_STATUS) ------------------------------------------------------------------------
ST_ENABLED = 1 << 0
ST_AT_RATE = 1 << 1
ST_IN_POSITION = 1 << 2
ST_FAULT = 1 << 3
ST_ESTOP = 1 << 4
ST_INTERLOCK_OPEN = 1 << 5
ST_WATCHDOG_EXPIRED = 1 << 6
ST_MOVING = 1 << 7

# --- fault codes (IR_FAULT_CODE) -----------------------------------------------------------------
FAULT_NONE = 0
FAULT_ESTOP = 1
FAULT_DRIVE = 2  # drive fault (over-current, encoder); the simulator's inject("fault")
FAULT_INTERLOCK = 3
FAULT_WATCHDOG = 4

# Modbus exception codes the controller answers with
EXC_ILLEGAL_ADDRESS = 0x02  # register outside the map, or a write to an input-only address
EXC_ILLEGAL_VALUE = 0x03  # a value outside the controller's range (mode, NaN, rate, accel)
EXC_DEVICE_FAILURE = 0x04  # a command the drive cannot take now (not enabled, tripped)
EXCEPTION_NAMES = {
    0x01: "illegal function",
    0x02: "illegal data address",
    0x03: "illegal data value",
    0x04: "device failure (command refused in this state)",
    0x06: "device busy",
    0x0A: "gateway path unavailable",
    0x0B: "gateway target device failed to respond (no such unit id)",
}


def float_to_regs(value: float) -> list[int]:
    """float32 -> [high word, low word]."""
    raw = struct.pack(">f", value)
    return [int.from_bytes(raw[0:2], "big"), int.from_bytes(raw[2:4], "big")]


def regs_to_float(regs) -> float:
    """[high word, low word] -> float."""
    return struct.unpack(">f", int(regs[0]).to_bytes(2, "big") + int(regs[1]).to_bytes(2, "big"))[0]


def encode_command(mode: int, rate_dps: float, angle_deg: float, accel_dps2: float) -> list[int]:
    """The 7-register command block (HR_MODE .. HR_ACCEL+1)."""
    return [int(mode), *float_to_regs(rate_dps), *float_to_regs(angle_deg), *float_to_regs(accel_dps2)]


def encode_status(rate_dps: float, angle_deg: float, bits: int, fault_code: int) -> list[int]:
    """The 6 input registers a status read returns."""
    return [*float_to_regs(rate_dps), *float_to_regs(angle_deg), int(bits) & 0xFFFF, int(fault_code) & 0xFFFF]


def decode_status(regs) -> tuple[float, float, int, int]:
    """6 input registers -> (rate_dps, angle_deg, bits, fault_code); ProtocolError-worthy input
    (wrong length, non-finite float) raises ValueError."""
    if len(regs) != IR_COUNT:
        raise ValueError(f"status read returned {len(regs)} registers, expected {IR_COUNT}")
    rate, angle = regs_to_float(regs[0:2]), regs_to_float(regs[2:4])
    if not (math.isfinite(rate) and math.isfinite(angle)):
        raise ValueError(f"status read returned a non-finite rate or angle ({rate!r}, {angle!r})")
    return rate, angle, int(regs[4]), int(regs[5])
