"""The chamber's thermal model in virtual time (docs/chamber.md): the air follows the set point
at the controller's ramp limit, the unit's case follows the air through a first-order time
constant, and the case temperature is the World's temperature (what the resonator feels)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class ChamberThermal:
    """Air and case temperatures (degC); attached to a World as a device (before_block)."""

    setpoint_c: float = 25.0
    ramp_c_per_min: float = 2.0
    case_tau_s: float = 1200.0
    air_c: float = 25.0
    case_c: float = 25.0
    ambient_c: float = 25.0

    def __post_init__(self) -> None:
        if not (self.case_tau_s > 0 and math.isfinite(self.case_tau_s)):
            raise ValueError(f"case_tau_s={self.case_tau_s!r} must be > 0")

    def step(self, dt_s: float) -> None:
        """Advance the air (ramp-limited toward the set point) and the case (exact first-order
        response to the air's linear path over dt_s)."""
        air0 = self.air_c
        max_step = self.ramp_c_per_min / 60.0 * dt_s
        err = self.setpoint_c - air0
        air1 = self.setpoint_c if abs(err) <= max_step else air0 + math.copysign(max_step, err)
        tau = self.case_tau_s
        a = math.exp(-dt_s / tau)
        slope = (air1 - air0) / dt_s if dt_s > 0 else 0.0
        # x' = (air0 + slope t - x) / tau, exact over the step
        lag = slope * tau
        self.case_c = (air1 - lag) + (self.case_c - air0 + lag) * a
        self.air_c = air1

    def ramping(self) -> bool:
        return self.air_c != self.setpoint_c

    # --- World device ---------------------------------------------------------------------------
    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        self.step(n * dt_s)
        world.set_temperature(self.case_c)

    def after_block(self, world, block) -> None:
        pass
