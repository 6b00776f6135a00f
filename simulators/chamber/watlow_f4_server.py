"""The Watlow F4 chamber controller on loopback: the register map of
drivers/chamber/watlow_f4_protocol.py answered over Modbus TCP (or RTU framing over a TCP socket)
on the rate-table server's framing, backed by a `ChamberThermal` attached to the World."""

from __future__ import annotations

import math
import struct
from typing import Any

from drivers.chamber import watlow_f4_protocol as fp
from simulators.rate_table.modbus_server import ModbusTableServer

from .thermal import ChamberThermal

_MAX_READ_REGS = 125
_MAX_WRITE_REGS = 123


def _exception(fc: int, code: int) -> bytes:
    return bytes((fc | 0x80, code))


class ChamberRegisters:
    """Answers one request PDU from the thermal model (reads) or into it (writes)."""

    def __init__(self, world, thermal: ChamberThermal, *, low_c: float, high_c: float, decimals: int = 1) -> None:
        self.world, self.thermal = world, thermal
        self.low_c, self.high_c, self.decimals = float(low_c), float(high_c), int(decimals)
        self.profile_status = fp.PROFILE_CONSTANT

    def _read(self, address: int) -> int:
        th, d = self.thermal, self.decimals
        values = {
            fp.HR_PV_AIR: lambda: fp.encode_temperature(th.air_c, d),
            fp.HR_PV_PART: lambda: fp.encode_temperature(th.case_c, d),
            fp.HR_PROFILE_STATUS: lambda: self.profile_status,
            fp.HR_SETPOINT: lambda: fp.encode_temperature(th.setpoint_c, d),
            fp.HR_RANGE_LOW: lambda: fp.encode_temperature(self.low_c, d),
            fp.HR_RANGE_HIGH: lambda: fp.encode_temperature(self.high_c, d),
            fp.HR_DECIMALS_AIR: lambda: d,
            fp.HR_DECIMALS_PART: lambda: d,
            fp.HR_UNITS: lambda: fp.UNITS_C,
            fp.HR_PROFILE_TERMINATE: lambda: 0,
            fp.HR_RAMP_RATE: lambda: fp.encode_ramp_rate(th.ramp_c_per_min),
        }
        return values[address]()

    def _write(self, address: int, word: int) -> int | None:
        th = self.thermal
        if address == fp.HR_SETPOINT:
            sp = fp.decode_temperature(word, self.decimals)
            if not self.low_c <= sp <= self.high_c:
                return fp.EXC_ILLEGAL_VALUE
            th.setpoint_c = sp
        elif address == fp.HR_RAMP_RATE:
            rate = fp.decode_ramp_rate(word)
            if not rate > 0 or not math.isfinite(rate):
                return fp.EXC_ILLEGAL_VALUE
            th.ramp_c_per_min = rate
        elif address == fp.HR_PROFILE_TERMINATE:
            if word == 1:
                self.profile_status = fp.PROFILE_CONSTANT
        return None

    def answer(self, pdu: bytes) -> bytes:
        """The reply PDU to a request PDU (FC3 read, FC6/FC16 write; others: exception 1)."""
        fc = pdu[0]
        if fc == 3:
            if len(pdu) != 5:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            address, count = struct.unpack_from(">HH", pdu, 1)
            if not 1 <= count <= _MAX_READ_REGS:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            if any(a not in fp.REGISTERS for a in range(address, address + count)):
                return _exception(fc, fp.EXC_ILLEGAL_ADDRESS)
            with self.world.lock:
                values = [self._read(a) for a in range(address, address + count)]
            return struct.pack(f">BB{count}H", fc, 2 * count, *values)
        if fc == 6:
            if len(pdu) != 5:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            address, value = struct.unpack_from(">HH", pdu, 1)
            values = [value]
        elif fc == 16:
            if len(pdu) < 6:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            address, count, n_bytes = struct.unpack_from(">HHB", pdu, 1)
            if not 1 <= count <= _MAX_WRITE_REGS or n_bytes != 2 * count or len(pdu) != 6 + n_bytes:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            values = list(struct.unpack_from(f">{count}H", pdu, 6))
        else:
            return _exception(fc, fp.EXC_ILLEGAL_FUNCTION)
        if any(not fp.REGISTERS.get(a, False) for a in range(address, address + len(values))):
            return _exception(fc, fp.EXC_ILLEGAL_ADDRESS)
        with self.world.lock:
            for i, word in enumerate(values):
                code = self._write(address + i, word)
                if code is not None:
                    return _exception(fc, code)
        return pdu if fc == 6 else struct.pack(">BHH", fc, address, len(values))


def serve_watlow_f4(
    world,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    framer: str = "tcp",
    device_id: int = 1,
    low_c: float = -70.0,
    high_c: float = 180.0,
    **thermal_kw,
) -> ModbusTableServer:
    """Attach a ChamberThermal (starting at the world's temperature) to the world (a rig: to its
    table world, setting every slot world's temperature) and serve the F4's
    registers over Modbus on loopback (port 0: any); the handle's `.mechanics` is the model."""
    units = tuple(getattr(world, "worlds", ()))  # a rig: every slot's unit sits in the chamber
    start = (units[0] if units else world).temperature_c
    at_start = {"setpoint_c": start, "air_c": start, "case_c": start, "resonator_c": start}
    thermal = ChamberThermal(**(at_start | thermal_kw), units=units)
    registers = ChamberRegisters(world, thermal, low_c=low_c, high_c=high_c)
    with world.lock:
        world.attach(thermal)
    return ModbusTableServer(world, thermal, host=host, port=port, framer=framer, device_id=device_id,
                             registers=registers)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[ModbusTableServer, dict[str, Any]]:
    """A simulated station's `watlow-f4` chamber: served from its station keys; (handle, address keys)."""
    handle = serve_watlow_f4(world, device_id=cfg["device_id"], low_c=cfg["min_degc"], high_c=cfg["max_degc"],
                             ramp_c_per_min=cfg["ramp_degc_per_min"], case_tau_s=cfg["case_tau_s"],
                             resonator_tau_s=cfg["resonator_tau_s"])
    return handle, {"host": handle.host, "port": handle.port}
