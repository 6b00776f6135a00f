"""A Watlow F4 chamber controller over Modbus (TCP, or RTU on a serial line) with pymodbus's
sync client (register map: watlow_f4_protocol, docs/chamber.md).

Reads are retried on a lost reply; writes (a set point, a ramp rate, a profile stop) are all
idempotent and retried too.  Modbus exceptions become DeviceError, a lost link LinkLostError."""

from __future__ import annotations

import threading
from dataclasses import dataclass

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusIOException

from drivers.errors import DeviceError, LinkLostError

from . import watlow_f4_protocol as fp

#: the set point the safe state leaves: lab ambient
AMBIENT_C = 25.0


@dataclass(frozen=True)
class ChamberStatus:
    """One read of the controller: air and part temperatures, set point (degC), profile status."""

    air_c: float
    part_c: float
    setpoint_c: float
    profile_status: int


class WatlowF4Chamber:
    """A Watlow F4 (a TestEquity or ESPEC chamber's controller): constant set point mode, and a
    ramp-rate profile for a ramp on the controller's own clock."""

    def __init__(self, host: str | None = None, port: int = 502, *, device_id: int = 1, timeout_s: float = 1.0,
                 retries: int = 2, client=None) -> None:
        if client is None:
            if host is None:
                raise ValueError("WatlowF4Chamber needs host= (TCP) or use WatlowF4Chamber.rtu(port)")
            client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0)
        self.client = client
        self.address = f"{host}:{port}" if host is not None else str(getattr(client, "comm_params", "serial"))
        self.device_id = int(device_id)
        self.retries = int(retries)
        self._io_lock = threading.Lock()
        self.decimals_air = 1
        self.decimals_part = 1
        self.range_c = (-70.0, 180.0)
        #: the ramp profile this driver made and has not deleted (the safe state deletes it)
        self.ramp_profile: int | None = None

    @classmethod
    def rtu(cls, port: str, *, device_id: int = 1, baudrate: int = 9600, timeout_s: float = 1.0) -> WatlowF4Chamber:
        """RTU framing on a serial port (a device path or a pyserial URL such as `socket://h:p`)."""
        client = ModbusSerialClient(port, framer=FramerType.RTU, baudrate=baudrate, timeout=timeout_s, retries=0)
        chamber = cls(client=client, device_id=device_id)
        chamber.address = port
        return chamber

    # --- link ----------------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the link and read the controller's scaling: decimals, units (degC required), range."""
        try:
            ok = self.client.connect()
        except OSError as exc:
            raise LinkLostError(f"chamber at {self.address}: cannot connect ({exc!r})") from exc
        if not ok:
            raise LinkLostError(f"chamber at {self.address}: cannot connect")
        self.decimals_air = self._read(fp.HR_DECIMALS_AIR)[0]
        self.decimals_part = self._read(fp.HR_DECIMALS_PART)[0]
        if self._read(fp.HR_UNITS)[0] != fp.UNITS_C:
            raise DeviceError(f"chamber at {self.address}: controller set to degF (register {fp.HR_UNITS}); "
                              "set it to degC")
        low, high = self._read(fp.HR_RANGE_LOW, 2)
        self.range_c = (fp.decode_temperature(low, self.decimals_air), fp.decode_temperature(high, self.decimals_air))

    @property
    def connected(self) -> bool:
        return bool(self.client.connected)

    def close(self) -> None:
        self.client.close()

    def _call(self, what: str, fn):
        last: Exception | None = None
        for _ in range(self.retries + 1):
            try:
                with self._io_lock:
                    rr = fn()
            except (ModbusIOException, ConnectionException, OSError) as exc:
                last = exc
                continue
            if rr.isError():
                code = getattr(rr, "exception_code", None)
                if code is None:
                    last = RuntimeError(str(rr))
                    continue
                raise DeviceError(f"chamber at {self.address}: {what} refused (Modbus exception {code})")
            return rr
        raise LinkLostError(f"chamber at {self.address}: {what}: no reply ({last!r})")

    def _read(self, address: int, count: int = 1) -> list[int]:
        rr = self._call(f"read {address}", lambda: self.client.read_holding_registers(
            address, count=count, device_id=self.device_id))
        return list(rr.registers)

    def _write(self, address: int, word: int) -> None:
        self._call(f"write {address}", lambda: self.client.write_register(address, word, device_id=self.device_id))

    def _write_many(self, address: int, words: list[int]) -> None:
        """Consecutive registers in one FC16 write (the F4 takes them in address order)."""
        self._call(f"write {address}..{address + len(words) - 1}",
                   lambda: self.client.write_registers(address, words, device_id=self.device_id))

    # --- what a procedure uses ----------------------------------------------------------------
    def air_c(self) -> float:
        """The chamber air temperature (input 1), degC."""
        return fp.decode_temperature(self._read(fp.HR_PV_AIR)[0], self.decimals_air)

    def part_c(self) -> float:
        """The part thermocouple on the unit's case (input 3), degC."""
        return fp.decode_temperature(self._read(fp.HR_PV_PART)[0], self.decimals_part)

    def setpoint_c(self) -> float:
        return fp.decode_temperature(self._read(fp.HR_SETPOINT)[0], self.decimals_air)

    def set_setpoint(self, temperature_c: float) -> None:
        """Set point 1 (constant mode); ValueError outside the controller's range."""
        low, high = self.range_c
        if not low <= temperature_c <= high:
            raise ValueError(f"set point {temperature_c:g} degC is outside the chamber's range [{low:g}, {high:g}]")
        self._write(fp.HR_SETPOINT, fp.encode_temperature(temperature_c, self.decimals_air))

    def ramp_rate_c_per_min(self) -> float:
        return fp.decode_ramp_rate(self._read(fp.HR_RAMP_RATE)[0])

    def set_ramp_rate(self, rate_c_per_min: float) -> None:
        """The set-point ramp limit, deg/min (> 0)."""
        if not rate_c_per_min > 0:
            raise ValueError(f"ramp rate {rate_c_per_min!r} deg/min must be > 0")
        self._write(fp.HR_RAMP_RATE, fp.encode_ramp_rate(rate_c_per_min))

    def stop_profile(self) -> None:
        """Terminate a running profile: the controller holds its constant set point."""
        self._write(fp.HR_PROFILE_TERMINATE, 1)

    # --- the controller's own ramp: a ramp-rate profile (docs/chamber.md "Ramp profiles") ------
    def supports_profiles(self) -> bool:
        """True when the controller answers its profile registers with steps free (an F4 with the
        profile option); a refused read (Modbus exception) means constant set point only."""
        try:
            return self._read(fp.HR_STEPS_AVAILABLE)[0] >= 2
        except DeviceError:
            return False

    def start_ramp(self, target_c: float, rate_c_per_min: float) -> int:
        """Ramp the set point from where it is to target_c at rate_c_per_min on the controller's own
        clock: a new profile of one ramp-rate step and an End-Hold step, started at once; its
        number (end_ramp deletes it).  ValueError for a target outside the range or a rate <= 0."""
        low, high = self.range_c
        if not low <= target_c <= high:
            raise ValueError(f"ramp target {target_c:g} degC is outside the chamber's range [{low:g}, {high:g}]")
        rate = fp.encode_ramp_rate(rate_c_per_min)
        if rate <= 0:
            raise ValueError(f"ramp rate {rate_c_per_min!r} deg/min must be >= 0.1 (the register's step)")
        self._write(fp.HR_PROFILE_ACTION, fp.ACTION_CREATE)
        number = self._read(fp.HR_EDIT_PROFILE)[0]
        self._write_many(fp.HR_EDIT_STEP, [1, fp.ACTION_INSERT_STEP])  # step 1 before the End step
        self._write(fp.HR_STEP_TYPE, fp.STEP_RAMP_RATE)
        self._write(fp.HR_STEP_WAIT, 0)
        self._write(fp.HR_RAMP_RATE, rate)
        self._write(fp.HR_STEP_TARGET, fp.encode_temperature(target_c, self.decimals_air))
        self._write(fp.HR_STEP_PID_SET, 0)
        self._write(fp.HR_STEP_GUARANTEED_SOAK, 0)
        self._write(fp.HR_EDIT_STEP, 2)
        self._write(fp.HR_END_ACTION, fp.END_HOLD)
        self._write(fp.HR_SAVE, 0)
        self._write_many(fp.HR_EDIT_PROFILE, [number, 1, fp.ACTION_START])
        self.ramp_profile = number
        return number

    def ramp_running(self) -> bool:
        """A profile is running (or paused)."""
        return self._read(fp.HR_PROFILE_STATUS)[0] in (fp.PROFILE_RUNNING, fp.PROFILE_PAUSED)

    def running_setpoint_c(self) -> float:
        """The set point the controller holds now (the running profile's, else the constant one)."""
        if self.ramp_running():
            return fp.decode_temperature(self._read(fp.HR_RUN_SETPOINT)[0], self.decimals_air)
        return self.setpoint_c()

    def end_ramp(self, number: int, hold_c: float) -> None:
        """After a ramp: the constant set point to hold_c (where the End-Hold left it), the profile
        terminated and deleted, so the controller is back in constant mode with nothing left behind."""
        self.set_setpoint(hold_c)
        self.stop_profile()
        self._delete_profile(number)

    def _delete_profile(self, number: int) -> None:
        self._write_many(fp.HR_EDIT_PROFILE, [number, 1, fp.ACTION_DELETE])
        self._write(fp.HR_SAVE, 0)
        if self.ramp_profile == number:
            self.ramp_profile = None

    def status(self) -> ChamberStatus:
        air, part = self.air_c(), self.part_c()
        return ChamberStatus(air, part, self.setpoint_c(), self._read(fp.HR_PROFILE_STATUS)[0])

    def safe_state(self) -> bool:
        """Profile stopped (a ramp profile of ours deleted), set point to ambient; True when the
        read-back confirms both."""
        self.stop_profile()
        if self.ramp_profile is not None:
            try:
                self._delete_profile(self.ramp_profile)
            except DeviceError:  # refused: the stopped profile stays stored, harmless; ambient comes first
                pass
        self.set_setpoint(AMBIENT_C)
        st = self.status()
        constant = st.profile_status in (fp.PROFILE_CONSTANT, fp.PROFILE_CONSTANT_ALT)
        return constant and abs(st.setpoint_c - AMBIENT_C) < 0.05
