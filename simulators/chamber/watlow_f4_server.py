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


_STEPS_TOTAL = 256  # the profile steps a controller holds in all


class ChamberRegisters:
    """Answers one request PDU from the thermal model (reads) or into it (writes); with `profiles`
    the F4's profile registers too (docs/chamber.md "Ramp profiles": the simulator runs ramp-rate
    steps ending in End-Hold)."""

    def __init__(self, world, thermal: ChamberThermal, *, low_c: float, high_c: float, decimals: int = 1,
                 profiles: bool = True) -> None:
        self.world, self.thermal = world, thermal
        self.low_c, self.high_c, self.decimals = float(low_c), float(high_c), int(decimals)
        self.constant_sp_c = thermal.setpoint_c
        self.profiles_on = bool(profiles)
        self.registers = fp.REGISTERS | (fp.PROFILE_REGISTERS if profiles else {})
        self.profiles: dict[int, list[dict[int, int]]] = {}
        self.edit_profile, self.edit_step = 0, 1
        self.run_profile, self.run_first_step, self.run_steps = 0, 0, 0

    @property
    def profile_status(self) -> int:
        th = self.thermal
        if not th.profile_ramps:
            return fp.PROFILE_CONSTANT
        return fp.PROFILE_PAUSED if th.profile_paused else fp.PROFILE_RUNNING

    def _edited(self) -> dict[int, int] | None:
        """The step selected for editing, or None (no such profile or step)."""
        steps = self.profiles.get(self.edit_profile)
        return steps[self.edit_step - 1] if steps and 1 <= self.edit_step <= len(steps) else None

    def _step_left(self) -> list[int]:
        th = self.thermal
        if not th.profile_ramps:
            return [0, 0, 0]
        target, rate = th.profile_ramps[0]
        s = int(round(abs(target - th.setpoint_c) / rate * 60.0))
        return [s // 3600, s // 60 % 60, s % 60]

    def _read(self, address: int) -> int:
        th, d = self.thermal, self.decimals
        if address in fp.STEP_FIELDS:
            step = self._edited()
            if step is not None:
                return step.get(address, 0)
            return fp.encode_ramp_rate(th.ramp_c_per_min) if address == fp.HR_RAMP_RATE else 0
        running = bool(th.profile_ramps)
        values = {
            fp.HR_PV_AIR: lambda: fp.encode_temperature(th.air_c, d),
            fp.HR_PV_PART: lambda: fp.encode_temperature(th.case_c, d),
            fp.HR_PROFILE_STATUS: lambda: self.profile_status,
            fp.HR_SETPOINT: lambda: fp.encode_temperature(self.constant_sp_c, d),
            fp.HR_RANGE_LOW: lambda: fp.encode_temperature(self.low_c, d),
            fp.HR_RANGE_HIGH: lambda: fp.encode_temperature(self.high_c, d),
            fp.HR_DECIMALS_AIR: lambda: d,
            fp.HR_DECIMALS_PART: lambda: d,
            fp.HR_UNITS: lambda: fp.UNITS_C,
            fp.HR_STEPS_AVAILABLE: lambda: _STEPS_TOTAL - sum(len(v) for v in self.profiles.values()),
            fp.HR_EDIT_PROFILE: lambda: self.edit_profile,
            fp.HR_EDIT_STEP: lambda: self.edit_step,
            fp.HR_RUN_PROFILE: lambda: self.run_profile if running else 0,
            fp.HR_RUN_STEP: lambda: self.run_first_step + self.run_steps - len(th.profile_ramps) if running else 0,
            fp.HR_RUN_SETPOINT: lambda: fp.encode_temperature(th.setpoint_c, d),
        }
        left = self._step_left()
        values |= {fp.HR_RUN_STEP_LEFT + i: (lambda i=i: left[i]) for i in range(3)}
        return values[address]() if address in values else 0  # write-only registers read 0

    def _in_range(self, word: int) -> bool:
        return self.low_c <= fp.decode_temperature(word, self.decimals) <= self.high_c

    def _action(self, code: int) -> int | None:
        """HR_PROFILE_ACTION: create, insert a step, delete, start; a Modbus exception code or None."""
        if code == fp.ACTION_CREATE:
            free = [n for n in range(1, fp.MAX_PROFILES + 1) if n not in self.profiles]
            if not free or sum(len(v) for v in self.profiles.values()) >= _STEPS_TOTAL:
                return fp.EXC_ILLEGAL_VALUE
            self.edit_profile, self.edit_step = free[0], 1
            self.profiles[free[0]] = [{fp.HR_STEP_TYPE: fp.STEP_END, fp.HR_END_ACTION: fp.END_HOLD}]
            return None
        steps = self.profiles.get(self.edit_profile)
        if steps is None:
            return fp.EXC_ILLEGAL_VALUE
        if code == fp.ACTION_INSERT_STEP:
            if not 1 <= self.edit_step <= len(steps) or sum(len(v) for v in self.profiles.values()) >= _STEPS_TOTAL:
                return fp.EXC_ILLEGAL_VALUE
            steps.insert(self.edit_step - 1, {fp.HR_STEP_TYPE: fp.STEP_SOAK})
            return None
        if code == fp.ACTION_DELETE:
            if self.thermal.profile_ramps and self.run_profile == self.edit_profile:
                return fp.EXC_ILLEGAL_VALUE  # a running profile is not deleted
            del self.profiles[self.edit_profile]
            self.edit_profile, self.edit_step = 0, 1
            return None
        if code == fp.ACTION_START:
            return self._start(steps)
        return fp.EXC_ILLEGAL_VALUE

    def _start(self, steps: list[dict[int, int]]) -> int | None:
        """Run ramp-rate steps from the edited step to an End-Hold (what the simulator runs)."""
        ramps = []
        for step in steps[self.edit_step - 1:]:
            kind = step.get(fp.HR_STEP_TYPE)
            if kind == fp.STEP_END:
                if step.get(fp.HR_END_ACTION, fp.END_HOLD) != fp.END_HOLD:
                    return fp.EXC_ILLEGAL_VALUE
                break
            target, rate = step.get(fp.HR_STEP_TARGET, 0), fp.decode_ramp_rate(step.get(fp.HR_RAMP_RATE, 0))
            if kind != fp.STEP_RAMP_RATE or step.get(fp.HR_STEP_WAIT, 0) or not rate > 0 or not self._in_range(target):
                return fp.EXC_ILLEGAL_VALUE
            ramps.append((fp.decode_temperature(target, self.decimals), rate))
        else:
            return fp.EXC_ILLEGAL_VALUE
        if not ramps:
            return fp.EXC_ILLEGAL_VALUE
        self.thermal.start_profile(ramps)
        self.run_profile, self.run_first_step, self.run_steps = self.edit_profile, self.edit_step, len(ramps)
        return None

    def _write(self, address: int, word: int) -> int | None:
        th = self.thermal
        if address in fp.STEP_FIELDS:
            step = self._edited()
            if step is not None:
                if address == fp.HR_STEP_TARGET and not self._in_range(word):
                    return fp.EXC_ILLEGAL_VALUE
                step[address] = word
                return None
            if address != fp.HR_RAMP_RATE:
                return fp.EXC_ILLEGAL_VALUE  # no step selected
            rate = fp.decode_ramp_rate(word)  # no profile edited: the simulator's constant-mode ramp limit
            if not rate > 0 or not math.isfinite(rate):
                return fp.EXC_ILLEGAL_VALUE
            th.ramp_c_per_min = rate
        elif address == fp.HR_SETPOINT:
            if not self._in_range(word):
                return fp.EXC_ILLEGAL_VALUE
            self.constant_sp_c = fp.decode_temperature(word, self.decimals)
            if not th.profile_ramps:
                th.setpoint_c = self.constant_sp_c
        elif address == fp.HR_PROFILE_TERMINATE:
            if word == 1:  # back to constant mode at the constant set point
                th.profile_ramps, th.profile_paused = [], False
                th.setpoint_c = self.constant_sp_c
        elif address == fp.HR_PROFILE_PAUSE:
            th.profile_paused = bool(word == 1 and th.profile_ramps) or th.profile_paused
        elif address == fp.HR_PROFILE_RESUME:
            th.profile_paused = th.profile_paused and word != 1
        elif address == fp.HR_EDIT_PROFILE:
            if not 0 <= word <= fp.MAX_PROFILES:
                return fp.EXC_ILLEGAL_VALUE
            self.edit_profile = word
        elif address == fp.HR_EDIT_STEP:
            if not 1 <= word <= _STEPS_TOTAL:
                return fp.EXC_ILLEGAL_VALUE
            self.edit_step = word
        elif address == fp.HR_PROFILE_ACTION:
            return self._action(word)
        return None  # HR_SAVE: the profiles are kept in memory

    def answer(self, pdu: bytes) -> bytes:
        """The reply PDU to a request PDU (FC3 read, FC6/FC16 write; others: exception 1)."""
        fc = pdu[0]
        if fc == 3:
            if len(pdu) != 5:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            address, count = struct.unpack_from(">HH", pdu, 1)
            if not 1 <= count <= _MAX_READ_REGS:
                return _exception(fc, fp.EXC_ILLEGAL_VALUE)
            if any(a not in self.registers for a in range(address, address + count)):
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
        if any(not self.registers.get(a, False) for a in range(address, address + len(values))):
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
    profiles: bool = True,
    **thermal_kw,
) -> ModbusTableServer:
    """Attach a ChamberThermal (starting at the world's temperature) to the world (a rig: to its
    table world, setting every slot world's temperature) and serve the F4's registers over Modbus on
    loopback (port 0: any; profiles: answer the profile registers too); the handle's `.mechanics` is
    the model."""
    units = tuple(getattr(world, "worlds", ()))  # a rig: every slot's unit sits in the chamber
    start = (units[0] if units else world).temperature_c
    at_start = {"setpoint_c": start, "air_c": start, "case_c": start, "resonator_c": start}
    thermal = ChamberThermal(**(at_start | thermal_kw), units=units)
    registers = ChamberRegisters(world, thermal, low_c=low_c, high_c=high_c, profiles=profiles)
    with world.lock:
        world.attach(thermal)
    return ModbusTableServer(world, thermal, host=host, port=port, framer=framer, device_id=device_id,
                             registers=registers)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[ModbusTableServer, dict[str, Any]]:
    """A simulated station's `watlow-f4` chamber: served from its station keys; (handle, address keys)."""
    handle = serve_watlow_f4(world, device_id=cfg["device_id"], low_c=cfg["min_degc"], high_c=cfg["max_degc"],
                             ramp_c_per_min=cfg["ramp_degc_per_min"], max_rate_c_per_min=cfg["ramp_degc_per_min"],
                             case_tau_s=cfg["case_tau_s"],
                             resonator_tau_s=cfg["resonator_tau_s"], profiles=cfg["profiles"])
    return handle, {"host": handle.host, "port": handle.port}
