"""Register map of the Watlow F4 chamber controller (docs/chamber.md), shared by the driver and
the simulator so the two cannot drift apart.

Addresses are Modbus protocol addresses from 0, as the F4's Modbus map numbers them (read with
FC3, written with FC6/FC16).  Temperatures are signed 16-bit integers in units of
10**-decimals degC, the decimals being the input's own decimal-places register."""

from __future__ import annotations

# --- holding registers ------------------------------------------------------------------------
HR_PV_AIR = 100  # input 1 process value: the chamber air (signed, scaled)
HR_PV_PART = 108  # input 3 process value: the part (product) thermocouple on the unit's case
HR_PROFILE_STATUS = 200  # 0 / 1: constant set point, 2: profile running, 3: profile paused
HR_SETPOINT = 300  # set point 1 in constant (static) mode (signed, scaled)
HR_RANGE_LOW = 602  # input 1 range low (signed, scaled): the lowest set point taken
HR_RANGE_HIGH = 603  # input 1 range high (signed, scaled)
HR_DECIMALS_AIR = 606  # input 1 decimal places (0 or 1 on a TestEquity chamber)
HR_DECIMALS_PART = 626  # input 3 decimal places
HR_UNITS = 901  # temperature units: 0 degF, 1 degC
HR_PROFILE_TERMINATE = 1217  # write 1: terminate a running profile (back to constant set point)
HR_RAMP_RATE = 4043  # ramp rate of a ramp-rate step, 0.1 deg/min units (here: the set-point ramp limit)

PROFILE_CONSTANT, PROFILE_CONSTANT_ALT, PROFILE_RUNNING, PROFILE_PAUSED = 0, 1, 2, 3
UNITS_F, UNITS_C = 0, 1
RAMP_RATE_SCALE = 10.0  # register counts per deg/min

#: every register the controller answers, read-only ones marked False
REGISTERS: dict[int, bool] = {
    HR_PV_AIR: False, HR_PV_PART: False, HR_PROFILE_STATUS: False, HR_SETPOINT: True,
    HR_RANGE_LOW: False, HR_RANGE_HIGH: False, HR_DECIMALS_AIR: False, HR_DECIMALS_PART: False,
    HR_UNITS: False, HR_PROFILE_TERMINATE: True, HR_RAMP_RATE: True,
}

EXC_ILLEGAL_FUNCTION = 0x01
EXC_ILLEGAL_ADDRESS = 0x02
EXC_ILLEGAL_VALUE = 0x03


def to_signed(word: int) -> int:
    """A register's 16 bits as a signed integer (two's complement)."""
    word = int(word) & 0xFFFF
    return word - 0x10000 if word & 0x8000 else word


def to_word(value: int) -> int:
    """A signed integer in [-32768, 32767] as the 16 bits a register holds."""
    value = int(value)
    if not -0x8000 <= value <= 0x7FFF:
        raise ValueError(f"{value} does not fit a signed 16-bit register")
    return value & 0xFFFF


def encode_temperature(temperature_c: float, decimals: int) -> int:
    """degC -> register word at `decimals` decimal places (rounded)."""
    return to_word(round(temperature_c * 10**decimals))


def decode_temperature(word: int, decimals: int) -> float:
    """register word at `decimals` decimal places -> degC."""
    return to_signed(word) / 10**decimals


def encode_ramp_rate(rate_c_per_min: float) -> int:
    """deg/min -> the ramp-rate register (0.1 deg/min counts, unsigned)."""
    counts = round(rate_c_per_min * RAMP_RATE_SCALE)
    if not 0 <= counts <= 0xFFFF:
        raise ValueError(f"ramp rate {rate_c_per_min!r} deg/min is outside [0, 6553.5]")
    return counts


def decode_ramp_rate(word: int) -> float:
    return int(word) / RAMP_RATE_SCALE
