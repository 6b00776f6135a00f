"""What the HRG decay procedures share: excite the resonator and hold its amplitude with the
FPGA's loops, spin the table to a stable rate, cut the drive.  A parameter mixin (not a
Procedure, so it is never listed) whose Params and helpers the procedures inherit; the
self-calibration procedures of the next wave stand on the same pieces."""

from __future__ import annotations

import math
import threading

import numpy as np

from bench.analysis.slow_model import orbit_elements
from bench.engine import Demand, Param, StationMismatch
from drivers.fpga.stream import STREAM_SCHEMA as FPGA
from drivers.fpga.stream import saturation_text


class LoopSaturated(RuntimeError):
    """A loop's force sat at FORCE_LIMIT during a record: the record is not a measurement."""


class SaturationWatch:
    """FPGA stream subscriber (the link's reader thread): the time and the saturation bits of every
    frame that has any (`sat_flags`), so a record can be checked for them afterwards."""

    def __init__(self) -> None:
        self._i_t, self._i_f = FPGA.indices("t_s", "sat_flags")
        self._t: list[np.ndarray] = []
        self._flags: list[np.ndarray] = []
        self._lock = threading.Lock()

    def __call__(self, block: np.ndarray) -> None:
        flags = block[:, self._i_f]
        hit = flags != 0
        if hit.any():
            with self._lock:
                self._t.append(block[hit, self._i_t])
                self._flags.append(flags[hit])

    def within(self, t_start_s: float, t_end_s: float) -> tuple[int, int, float, float]:
        """(saturated frames, their bits or-ed, first and last time) in (t_start_s, t_end_s]."""
        with self._lock:
            t = np.concatenate(self._t) if self._t else np.empty(0)
            f = np.concatenate(self._flags) if self._flags else np.empty(0)
        sel = (t > t_start_s) & (t <= t_end_s)
        if not sel.any():
            return 0, 0, np.nan, np.nan
        bits = int(np.bitwise_or.reduce(f[sel].astype(np.int64)))
        return int(sel.sum()), bits, float(t[sel][0]), float(t[sel][-1])


#: the share of the force limit a command may use (the rest: the drift compensation's force, the
#: loops' transients); above it the loop would run at its clamp
FORCE_HEADROOM = 0.95


def precession_limit_dps(force_limit: float, amplitude: float) -> float:
    """The wave rate whole-angle precession (or the rebalance loop) can force at amplitude a: the
    force 4 a Omega at FORCE_LIMIT, Omega = FORCE_LIMIT / (4 a) (docs/fpga_link.md, "Saturation")."""
    return math.degrees(force_limit / (4.0 * amplitude))


def refuse_above_precession_limit(proc, devices, name: str, wave_rate_dps: float, what: str = "") -> None:
    """StationMismatch when a commanded wave rate |wave_rate_dps| (from parameter `name`) is above
    FORCE_HEADROOM of the FPGA's precession limit at the procedure's amplitude; reads FORCE_LIMIT."""
    fpga = devices.get("fpga") if hasattr(devices, "get") else None
    if fpga is None:
        return
    force = float(fpga.read_register("FORCE_LIMIT"))
    full = precession_limit_dps(force, proc.amplitude)
    usable = FORCE_HEADROOM * full
    if abs(wave_rate_dps) > usable:
        raise StationMismatch(
            f"{proc.name}: {name}={getattr(proc, name):g} {what}is above the FPGA's precession limit "
            f"{usable:.3g} deg/s ({FORCE_HEADROOM:.0%} of FORCE_LIMIT / (4 x amplitude) = {force:g} / (4 x "
            f"{proc.amplitude:g}) rad/s = {full:.3g} deg/s): the precession force would saturate and the wave "
            "turn slower than commanded; nothing was moved")


#: a loop has settled when its error is this share of the step it was given (ln 100 = 4.6 time constants)
SETTLE_FRACTION = 0.01
#: whole-angle: the wave turns this far before the FPGA's split observer has seen both components
#: of the 4 theta quadrature pattern (a quarter of its period; docs/fpga_link.md)
SPLIT_LEARN_DEG = 22.5


def pi_loop_time_constant_s(kp: float, ki: float, plant_gain: float) -> float:
    """The slowest time constant of a PI loop around an integrator x' = g F (closed loop
    s^2 + g kp s + g ki = 0): 1 / the smallest |real part| of its poles."""
    a, b = plant_gain * kp, plant_gain * ki
    if a <= 0.0:
        return math.inf
    disc = a * a - 4.0 * b
    slowest = 0.5 * a if disc <= 0.0 else 0.5 * (a - math.sqrt(disc))
    return math.inf if slowest <= 0.0 else 1.0 / slowest


def loops_time_constant_s(fpga) -> float:
    """The slowest of the FPGA's amplitude and quadrature loops (da/dt = F_a / 2, dk/dt = F_q / 2;
    docs/fpga_link.md "The loops"), from their gain registers."""
    reg = fpga.read_register
    return max(pi_loop_time_constant_s(float(reg("AGC_KP")), float(reg("AGC_KI")), 0.5),
               pi_loop_time_constant_s(float(reg("QUAD_KP")), float(reg("QUAD_KI")), 0.5))


def settle_time_s(fpga, precession_dps: float = 0.0) -> float:
    """The wait after a command before a record: the slowest loop's time constant times
    ln(1 / SETTLE_FRACTION), plus, when a whole-angle precession starts, the time the wave takes to
    turn SPLIT_LEARN_DEG (the split observer's learning)."""
    learn_s = SPLIT_LEARN_DEG / abs(precession_dps) if precession_dps else 0.0
    return loops_time_constant_s(fpga) * math.log(1.0 / SETTLE_FRACTION) + learn_s


def saturation_refusal(label: str, n: int, bits: int, t_first: float, t_last: float) -> str:
    """The error a saturated record ends the run with."""
    return (f"{label}: the {saturation_text(bits)} loop saturated (force held at FPGA FORCE_LIMIT) in {n} "
            f"stream frames, t = {t_first:.3f} .. {t_last:.3f} s; a loop at its limit does not do what it "
            "is asked, so this record is no measurement")


class HrgExcitation:
    """Params and helpers for 'excite, hold, spin, cut'.  The procedure keeps the newest stream
    row in `self._latest_row` (a stream subscriber it owns) and calls these from its steps."""

    amplitude = Param(1.0, unit="", low=0.01, high=10.0, doc="amplitude setpoint held by the AGC before the cut")
    amplitude_tolerance = Param(0.01, unit="", low=1e-4, high=0.5, doc="relative amplitude tolerance to go on")
    amplitude_timeout_s = Param(120.0, unit="s", low=1.0, high=3600.0, doc="time allowed to reach the amplitude")
    rate_tolerance_dps = Param(0.05, unit="deg/s", low=1e-4, high=10.0, doc="rate-stability tolerance")
    rate_hold_s = Param(2.0, unit="s", low=0.0, high=600.0, doc="time the rate must stay within tolerance")
    rate_timeout_s = Param(120.0, unit="s", low=1.0, high=3600.0, doc="time allowed to become stable at rate")

    _latest_row: np.ndarray | None = None
    _saturation: SaturationWatch | None = None

    def demands(self) -> list[Demand]:
        """The table's rate and acceleration (the procedure's `rate_dps`, `accel_dps2`)."""
        return [
            Demand("table", "max_rate_dps", "rate_dps", self.rate_dps, "deg/s"),
            Demand("table", "max_accel_dps2", "accel_dps2", self.accel_dps2, "deg/s^2"),
        ]

    def _keep_latest(self, block: np.ndarray) -> None:
        """Stream subscriber (the link's reader thread): keep the newest row only."""
        self._latest_row = block[-1].copy()

    def _amplitude_now(self, ctx) -> float:
        ctx.devices.fpga.sync()  # every frame up to the bench clock's now has been seen
        row = self._latest_row
        return 0.0 if row is None else float(orbit_elements(FPGA.columns_of(row, "cx", "sx", "cy", "sy"))["a"])

    def _start_loops(self, ctx) -> None:
        """AGC (at the amplitude setpoint), PLL and quadrature loop on, drive on."""
        fpga = ctx.devices.fpga
        if self._saturation is None:  # every record is checked for a saturated loop
            self._saturation = SaturationWatch()
            ctx.subscribe(fpga, self._saturation)
        if hasattr(fpga, "reload_trims") and fpga.read_register("TRIM_EN"):
            # a trimmed unit (a retest): identify the raw resonator; its trims come back from NVM at the end
            fpga.write_register("TRIM_EN", 0)
            ctx.defer(fpga.reload_trims, "FPGA trims back from NVM")
            ctx.log.info("FPGA trims off for the identification (NVM keeps them; reloaded at the run's end)")
        fpga.set_whole_angle(False)
        fpga.set_drift_compensation(False)
        fpga.set_pll(True)
        fpga.set_quadrature_loop(True)
        fpga.set_agc(True, self.amplitude)
        fpga.set_drive_enabled(True)

    def _refuse_saturation(self, t_start_s: float, t_end_s: float, label: str) -> None:
        """LoopSaturated (the run ends ERROR) when any loop sat at its limit in (t_start_s, t_end_s]."""
        if self._saturation is None:
            return
        n, bits, t_first, t_last = self._saturation.within(t_start_s, t_end_s)
        if n:
            raise LoopSaturated(saturation_refusal(label, n, bits, t_first, t_last))

    def _hold_amplitude(self, ctx) -> float:
        """Wait (bench clock) until the amplitude is within tolerance of the setpoint; returns it."""
        tol = self.amplitude_tolerance * self.amplitude
        ok = ctx.wait_until(lambda: abs(self._amplitude_now(ctx) - self.amplitude) <= tol,
                            timeout_s=self.amplitude_timeout_s, poll_s=0.5)
        if not ok:
            raise TimeoutError(
                f"amplitude {self._amplitude_now(ctx):.4g} not within {tol:.3g} of the setpoint {self.amplitude:g} "
                f"after {self.amplitude_timeout_s:g} s"
            )
        return self._amplitude_now(ctx)

    def _start_spin(self, ctx) -> None:
        table = ctx.devices.table
        table.enable()
        table.set_rate(self.rate_dps, self.accel_dps2)

    def _wait_stable(self, ctx):
        return ctx.devices.table.wait_at_rate(self.rate_tolerance_dps, self.rate_hold_s, self.rate_timeout_s)

    def _cut_drive(self, ctx) -> None:
        """Drive off; PLL off so the reference holds (a PLL cannot follow a decaying wave, and the
        detuning then stays constant through the record); front-end outputs off if there is one."""
        fpga = ctx.devices.fpga
        fpga.set_drive_enabled(False)
        fpga.set_pll(False)
        frontend = ctx.devices.get("frontend")
        if frontend is not None:
            for ch in (1, 2):
                frontend.set_drive(ch, output_on=False)
        ctx.sleep(0.1)  # the forces leave at the next loop block
