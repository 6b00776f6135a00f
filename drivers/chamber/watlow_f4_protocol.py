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

# --- profiles (ramp and soak programs; docs/chamber.md "Ramp profiles") ---------------------------
HR_SAVE = 25  # write 0: save the profiles to EEPROM
HR_PROFILE_RESUME = 1209  # write 1: resume a paused profile
HR_PROFILE_PAUSE = 1210  # write 1: pause a running profile
HR_STEPS_AVAILABLE = 1219  # profile steps left free (0 or no answer: the controller runs no profiles)
HR_EDIT_PROFILE = 4000  # the profile being edited or started (1..40; a create writes the new one here)
HR_EDIT_STEP = 4001  # the step being edited or started from (1..)
HR_PROFILE_ACTION = 4002  # write: 1 create a profile, 2 insert a step before HR_EDIT_STEP, 3 delete the profile,
#                           5 start the profile at HR_EDIT_STEP
HR_STEP_TYPE = 4003  # 0 autostart, 1 ramp time, 2 ramp rate, 3 soak, 4 jump, 5 end
HR_STEP_HOURS, HR_STEP_MINUTES, HR_STEP_SECONDS = 4009, 4010, 4011  # duration of a ramp-time or soak step
HR_STEP_WAIT = 4012  # 1: the step waits for an event or input first
HR_STEP_TARGET = 4044  # loop 1's target set point of a ramp or soak step (signed, scaled as HR_SETPOINT)
HR_STEP_PID_SET = 4046  # loop 1's PID set of the step (0: set 1)
HR_STEP_GUARANTEED_SOAK = 4048  # loop 1's guaranteed soak: 1 on
HR_END_ACTION = 4060  # end step: 0 hold the last set points, 1 control off, 2 all off, 3 idle set point
HR_RUN_PROFILE = 4100  # the running profile's number
HR_RUN_STEP = 4101  # the running step
HR_RUN_STEP_LEFT = 4119  # 4119..4121: the running step's time left, h, min, s
HR_RUN_SETPOINT = 4122  # loop 1's set point now, as the running profile moves it (signed, scaled)

ACTION_CREATE, ACTION_INSERT_STEP, ACTION_DELETE, ACTION_START = 1, 2, 3, 5
STEP_AUTOSTART, STEP_RAMP_TIME, STEP_RAMP_RATE, STEP_SOAK, STEP_JUMP, STEP_END = 0, 1, 2, 3, 4, 5
END_HOLD, END_CONTROL_OFF, END_ALL_OFF, END_IDLE = 0, 1, 2, 3
MAX_PROFILES = 40
#: the editable registers of the step selected by HR_EDIT_PROFILE and HR_EDIT_STEP (4003..4062)
STEP_FIELDS = range(HR_STEP_TYPE, 4063)

PROFILE_CONSTANT, PROFILE_CONSTANT_ALT, PROFILE_RUNNING, PROFILE_PAUSED = 0, 1, 2, 3
UNITS_F, UNITS_C = 0, 1
RAMP_RATE_SCALE = 10.0  # register counts per deg/min

#: every register the controller answers, read-only ones marked False
REGISTERS: dict[int, bool] = {
    HR_PV_AIR: False, HR_PV_PART: False, HR_PROFILE_STATUS: False, HR_SETPOINT: True,
    HR_RANGE_LOW: False, HR_RANGE_HIGH: False, HR_DECIMALS_AIR: False, HR_DECIMALS_PART: False,
    HR_UNITS: False, HR_PROFILE_TERMINATE: True, HR_RAMP_RATE: True,
}

#: the profile registers (a controller with profiles answers them too)
PROFILE_REGISTERS: dict[int, bool] = {
    HR_SAVE: True, HR_PROFILE_RESUME: True, HR_PROFILE_PAUSE: True, HR_STEPS_AVAILABLE: False,
    HR_EDIT_PROFILE: True, HR_EDIT_STEP: True, HR_PROFILE_ACTION: True,
    **{a: True for a in STEP_FIELDS},
    HR_RUN_PROFILE: False, HR_RUN_STEP: False, HR_RUN_STEP_LEFT: False, HR_RUN_STEP_LEFT + 1: False,
    HR_RUN_STEP_LEFT + 2: False, HR_RUN_SETPOINT: False,
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
