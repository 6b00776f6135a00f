"""A simulated Keithley 2200-series supply (the SCPI subset PyMeasure's Keithley2200 uses) powering
the gyro's electronics on channel 1: it draws a quiescent current plus a share proportional to the
drive force the world holds, so a run's logged supply current follows the drive (docs/instruments.md).
It does not switch the simulated gyro off: the FPGA simulator stands for the electronics."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .scpi import ILLEGAL_PARAMETER, ScpiError, ScpiInstrument
from .server import InstrumentServer

VOLTAGE_RANGE_V = (0.0, 70.0)
CURRENT_RANGE_A = (0.0, 45.0)
QUIESCENT_A = 0.150  # electronics at rest, at or above BROWNOUT_V
AMPS_PER_FORCE = 0.020  # extra current per unit of drive force (model units)
BROWNOUT_V = 5.0  # below it the electronics draw as a resistor


@dataclass
class Channel:
    enabled: bool = False
    voltage_v: float = 0.0
    current_limit_a: float = 1.0
    voltage_limit_v: float = 70.0
    voltage_limit_on: bool = False


class Keithley2200Model(ScpiInstrument):
    """Three channels; channel 1 is wired to the gyro electronics (the load), 2 and 3 are open."""

    idn = "KEITHLEY INSTRUMENTS,MODEL 2230-30-1,SIM0001,1.00"

    def __init__(self, world: Any) -> None:
        super().__init__()
        self.world = world
        self.reset()

    def reset(self) -> None:
        self.channels = {n: Channel() for n in (1, 2, 3)}
        self.selected = 1

    def load_current_a(self, n: int) -> float:
        """What channel n delivers now (0 when off or open); limited by its current limit."""
        ch = self.channels[n]
        if not ch.enabled or n != 1 or ch.voltage_v <= 0.0:
            return 0.0
        if ch.voltage_v < BROWNOUT_V:
            amps = QUIESCENT_A * ch.voltage_v / BROWNOUT_V
        else:
            amps = QUIESCENT_A + AMPS_PER_FORCE * float(np.abs(self.world.total_force).sum())
        return min(amps, ch.current_limit_a)

    def output_voltage_v(self, n: int) -> float:
        ch = self.channels[n]
        if not ch.enabled:
            return 0.0
        amps = self.load_current_a(n)
        if n == 1 and amps >= ch.current_limit_a and ch.voltage_v >= BROWNOUT_V:  # in current limit
            return min(ch.voltage_v, BROWNOUT_V * amps / QUIESCENT_A)
        return ch.voltage_v

    def command(self, header: str, args: list[str]) -> str | None:
        ch = self.channels[self.selected]
        if header in ("INST:SEL", "INST:NSEL", "INSTRUMENT:SELECT"):
            text = (args[0] if args else "").strip().upper().removeprefix("CH")
            if text not in ("1", "2", "3"):
                raise ScpiError(ILLEGAL_PARAMETER, f"Illegal parameter value {args!r}")
            self.selected = int(text)
            return None
        if header in ("SOURCE:OUTP:ENAB?", "OUTP:ENAB?", "OUTP?"):
            return "1" if ch.enabled else "0"
        if header in ("SOURCE:OUTP:ENAB", "OUTP:ENAB", "OUTP"):
            word = (args[0] if args else "").strip().upper()
            if word not in ("0", "1", "ON", "OFF"):
                raise ScpiError(ILLEGAL_PARAMETER, f"Illegal parameter value {args!r}")
            ch.enabled = word in ("1", "ON")
            return None
        if header == "VOLT?":
            return f"{ch.voltage_v:.4f}"
        if header == "VOLT":
            limit = ch.voltage_limit_v if ch.voltage_limit_on else VOLTAGE_RANGE_V[1]
            ch.voltage_v = self.number(args, VOLTAGE_RANGE_V[0], limit)
            return None
        if header == "CURR?":
            return f"{ch.current_limit_a:.4f}"
        if header == "CURR":
            ch.current_limit_a = self.number(args, *CURRENT_RANGE_A)
            return None
        if header == "VOLT:LIM?":
            return f"{ch.voltage_limit_v:.4f}"
        if header == "VOLT:LIM":
            ch.voltage_limit_v = self.number(args, *VOLTAGE_RANGE_V)
            return None
        if header == "VOLT:LIM:STAT?":
            return "1" if ch.voltage_limit_on else "0"
        if header == "VOLT:LIM:STAT":
            ch.voltage_limit_on = self.number(args, 0, 1) == 1
            return None
        if header == "MEAS:CURR?":
            return f"{self.load_current_a(self.selected):.5f}"
        if header == "MEAS:VOLT?":
            return f"{self.output_voltage_v(self.selected):.4f}"
        if header == "MEAS:POW?":
            return f"{self.load_current_a(self.selected) * self.output_voltage_v(self.selected):.4f}"
        return super().command(header, args)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[InstrumentServer, dict[str, Any]]:
    """A simulated station's Keithley 2200 (`simulator = "simulators.instruments.keithley2200:serve_station"`)."""
    handle = InstrumentServer(world, Keithley2200Model(world), "keithley2200-sim")
    return handle, {"resource": handle.resource}
