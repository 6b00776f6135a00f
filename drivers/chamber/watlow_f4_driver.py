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
    """A Watlow F4 (a TestEquity or ESPEC chamber's controller): constant set point mode."""

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

    def status(self) -> ChamberStatus:
        air, part = self.air_c(), self.part_c()
        return ChamberStatus(air, part, self.setpoint_c(), self._read(fp.HR_PROFILE_STATUS)[0])

    def safe_state(self) -> bool:
        """Profile stopped, set point to ambient; True when the read-back confirms both."""
        self.stop_profile()
        self.set_setpoint(AMBIENT_C)
        st = self.status()
        constant = st.profile_status in (fp.PROFILE_CONSTANT, fp.PROFILE_CONSTANT_ALT)
        return constant and abs(st.setpoint_c - AMBIENT_C) < 0.05
