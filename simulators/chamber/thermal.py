"""The chamber's thermal model in virtual time (docs/chamber.md): the air follows the set point
at the controller's ramp limit (a running ramp-rate profile step moves the set point itself at
its rate, the air following it), the unit's case follows the air through a first-order time
constant, and the resonator follows the case through its own time constant (in vacuum it takes
heat by radiation and through its stem; 0: it is at the case's temperature): the resonator's
temperature is the World's (every slot World's when several gyros share the chamber)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass
class ChamberThermal:
    """Air and case temperatures (degC); attached to a World as a device (before_block)."""

    setpoint_c: float = 25.0
    ramp_c_per_min: float = 2.0
    case_tau_s: float = 1200.0
    air_c: float = 25.0
    case_c: float = 25.0
    ambient_c: float = 25.0
    resonator_tau_s: float = 0.0
    resonator_c: float | None = None
    #: the running profile's ramp-rate steps still to go, (target degC, rate deg/min) each; empty:
    #: constant set point (or a profile that has ended holding its last target)
    profile_ramps: list[tuple[float, float]] = field(default_factory=list)
    profile_paused: bool = False
    #: the chamber's own limit (its heaters and compressor): a profile's set point is followed up
    #: to it; in constant mode the air moves at the lower of it and ramp_c_per_min
    max_rate_c_per_min: float = math.inf
    #: every unit in the chamber (a rig's slot worlds, which share its air and housing); empty: the
    #: World the model is attached to
    units: tuple = ()

    def __post_init__(self) -> None:
        if not (self.case_tau_s > 0 and math.isfinite(self.case_tau_s)):
            raise ValueError(f"case_tau_s={self.case_tau_s!r} must be > 0")
        if not (self.resonator_tau_s >= 0 and math.isfinite(self.resonator_tau_s)):
            raise ValueError(f"resonator_tau_s={self.resonator_tau_s!r} must be >= 0")
        if self.resonator_c is None:
            self.resonator_c = self.case_c

    @staticmethod
    def _lag(x0: float, u0: float, u1: float, dt_s: float, tau_s: float) -> float:
        """Exact first-order response x' = (u - x) / tau over dt_s to an input moving linearly u0 -> u1."""
        a = math.exp(-dt_s / tau_s)
        lag = (u1 - u0) / dt_s * tau_s if dt_s > 0 else 0.0
        return (u1 - lag) + (x0 - u0 + lag) * a

    def step(self, dt_s: float) -> None:
        """Advance the air (ramp-limited toward the set point), the case (exact first-order
        response to the air's linear path over dt_s) and the resonator (the same behind the case,
        whose path over a short block is taken as a straight line).  A ramp-rate profile step
        first moves the set point toward its target at its rate and ends (holding the target)
        when the set point arrives."""
        following = bool(self.profile_ramps)  # the air follows a profile's set point at the chamber's limit
        if self.profile_ramps and not self.profile_paused:
            target, rate = self.profile_ramps[0]
            sp_step = rate / 60.0 * dt_s
            gap = target - self.setpoint_c
            if abs(gap) <= sp_step:  # the step ends; the next starts with the next block
                self.setpoint_c = target
                self.profile_ramps.pop(0)
            else:
                self.setpoint_c += math.copysign(sp_step, gap)
        air0 = self.air_c
        rate = self.max_rate_c_per_min if following else min(self.ramp_c_per_min, self.max_rate_c_per_min)
        max_step = rate / 60.0 * dt_s
        err = self.setpoint_c - air0
        air1 = self.setpoint_c if abs(err) <= max_step else air0 + math.copysign(max_step, err)
        case0 = self.case_c
        self.case_c = self._lag(case0, air0, air1, dt_s, self.case_tau_s)
        self.air_c = air1
        if self.resonator_tau_s > 0:
            self.resonator_c = self._lag(self.resonator_c, case0, self.case_c, dt_s, self.resonator_tau_s)
        else:
            self.resonator_c = self.case_c

    def ramping(self) -> bool:
        return self.air_c != self.setpoint_c or bool(self.profile_ramps)

    def start_profile(self, ramps: list[tuple[float, float]]) -> None:
        """Ramp-rate steps from the set point now, each (target degC, rate deg/min > 0), in turn."""
        for _, rate in ramps:
            if not (rate > 0 and math.isfinite(rate)):
                raise ValueError(f"ramp rate {rate!r} deg/min must be > 0")
        self.profile_ramps = [(float(t), float(r)) for t, r in ramps]
        self.profile_paused = False

    # --- World device ---------------------------------------------------------------------------
    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        """Attached to a rig's table world, whose block runs first: every unit's from this block on."""
        self.step(n * dt_s)
        for unit in self.units or (world,):
            unit.set_temperature(self.resonator_c)

    def after_block(self, world, block) -> None:
        pass
