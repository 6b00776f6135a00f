"""The forcers' rotation against the pickoffs through the FPGA link (docs/readout_phase.md section 6):
with the wave held in whole-angle mode, step the AGC setpoint between a and ratio x a and read the
wave's turn per unit of ln a (bench.analysis.forcer_rotation) at eight wave angles over 90 deg; the
constant of its fit on the 4 and 8 theta shares is delta_c, whose constant drift gamma delta_c / 2
the self-calibration cycles cannot see.  A step of hrg-selfcal before its cycles (after the readout
phase calibration)."""

from __future__ import annotations

import math

import numpy as np

from bench.analysis import forcer_rotation as fr
from bench.streams import Column, StreamSchema, declare

ROTATION = "forcer_rotation_readings"
ROTATION_COLUMNS = declare(StreamSchema(ROTATION, "forcer-rotation", (
    Column("theta_deg", "deg", doc="wave angle of the reading"),
    Column("turn_deg", "deg", doc="the wave's turn per unit of ln(amplitude) read there"),
    Column("turn_se_deg", "deg", doc="its standard error"),
    Column("steps", "1", doc="setpoint steps read")))).names  # fmt: skip
#: settling after the wave is turned or the setpoint goes back (the AGC settles in a few seconds)
SETTLE_S = 10.0


def _ln_amplitude(col: dict[str, np.ndarray]) -> np.ndarray:
    """ln of the measured amplitude from the stream's slow variables (a^2 + k^2: k held near 0)."""
    return 0.5 * np.log(col["cx"] ** 2 + col["sx"] ** 2 + col["cy"] ** 2 + col["sy"] ** 2)


def calibrate_forcer_rotation(ctx, fpga, tap, columns: tuple[str, ...], *, steps: int, hold_s: float, ratio: float,
                              amplitude: float, move_dps: float, fm_amplitude_hz: float = 0.0,
                              fm_rate_hz: float = 0.0) -> tuple[float, float, np.ndarray]:
    """At each of fr.ANGLES_DEG (the wave turned at move_dps between them, and back at the end): `steps`
    holds of hold_s alternating the setpoint ratio x amplitude and amplitude; the turn per ln a read
    from the stream tap (t_s, angle_out_deg, cx, sx, cy, sy among `columns`).  Returns delta_c (rad),
    its standard error and one row of ROTATION_COLUMNS a reading."""
    readings, rows = [], []
    turned = 0.0
    for i, ang in enumerate(fr.ANGLES_DEG):
        if ang != turned:
            fpga.set_whole_angle(True, move_dps, fm_amplitude_hz, fm_rate_hz)
            ctx.sleep((ang - turned) / move_dps)
            fpga.set_whole_angle(True, 0.0, fm_amplitude_hz, fm_rate_hz)
            turned = ang
            ctx.sleep(SETTLE_S)
        fpga.sync()
        t0 = ctx.clock.now()
        tap.take(-math.inf, math.inf)
        for s in range(steps):
            fpga.write_register("AGC_SETPOINT", amplitude * (ratio if s % 2 == 0 else 1.0))
            ctx.sleep_until(t0 + (s + 1) * hold_s)
        fpga.write_register("AGC_SETPOINT", amplitude)
        fpga.sync()
        rows_i = tap.take(t0, t0 + steps * hold_s)
        col = {name: rows_i[:, k] for k, name in enumerate(columns)}
        r = fr.read_turn(col["t_s"], np.radians(col["angle_out_deg"]), _ln_amplitude(col), hold_s)
        readings.append(r)
        rows.append([r.theta_deg, math.degrees(r.turn_rad), math.degrees(r.se_rad), float(r.steps)])
        ctx.log.info(f"forcer rotation reading {i + 1}/{len(fr.ANGLES_DEG)} at {r.theta_deg:.1f} deg: "
                     f"{math.degrees(r.turn_rad):+.5f} +- {math.degrees(r.se_rad):.5f} deg per unit ln a")
        ctx.sleep(SETTLE_S)
    fpga.set_whole_angle(True, -move_dps, fm_amplitude_hz, fm_rate_hz)
    ctx.sleep(turned / move_dps)
    fpga.set_whole_angle(True, 0.0, fm_amplitude_hz, fm_rate_hz)
    ctx.sleep(SETTLE_S)
    rot, se = fr.rotation_from_readings(readings)
    return rot, se, np.array(rows)
