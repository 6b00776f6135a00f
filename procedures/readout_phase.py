"""Readout phase calibration through the FPGA link (docs/readout_phase.md): with the wave held in
whole-angle mode under the frequency-control force, read the loops' phase error from the amplitude
loop's response to that force (bench.analysis.readout_phase) at two wave angles 45 deg apart (the x
and the y chain), turn each chain's demodulation reference by it (TRIM_PHASE_X_DEG, _Y_DEG) and
repeat: each pass nulls what the last one left, so the estimator's own scale error (about 1 % of
what it reads) drops out.  A step of hrg-selfcal before its cycles; any whole-angle procedure with
the stream tap of hrg_damping can call `calibrate_readout_phase`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.analysis import readout_phase as rp
from bench.streams import Column, StreamSchema, declare

PHASES = "readout_phase_passes"
PHASE_COLUMNS = declare(StreamSchema(PHASES, "readout-phase", (
    Column("t_s", "s", doc="end of the pass"),
    Column("theta_1_deg", "deg", doc="wave angle of the first hold"),
    Column("phase_1_deg", "deg", doc="loops' phase error read there"),
    Column("phase_1_se_deg", "deg", doc="its standard error"),
    Column("theta_2_deg", "deg", doc="wave angle of the second hold (45 deg on)"),
    Column("phase_2_deg", "deg", doc="loops' phase error read there"),
    Column("phase_2_se_deg", "deg", doc="its standard error"),
    Column("residual_x_deg", "deg", doc="x chain's phase left by the trim in place during the pass"),
    Column("residual_y_deg", "deg", doc="y chain's phase left by the trim in place during the pass"),
    Column("residual_x_se_deg", "deg", doc="its standard error"),
    Column("residual_y_se_deg", "deg", doc="its standard error"),
    Column("trim_x_deg", "deg", doc="x chain's phase trim after the pass (TRIM_PHASE_X_DEG)"),
    Column("trim_y_deg", "deg", doc="y chain's phase trim after the pass (TRIM_PHASE_Y_DEG)")))).names  # fmt: skip

#: a floor added in quadrature to each chain's interval: what the loops' model leaves in the null
#: (0.0002 deg on the hrg-realistic unit, noise-free: its electrode angles and gains; docs/readout_phase.md)
PHASE_FLOOR_DEG = 1e-3
#: settling after a trim is written or the wave stops (the PLL re-locks to the turned phase in ~1 s)
SETTLE_S = 10.0


@dataclass(frozen=True)
class PhaseCal:
    """The calibration's outcome: the chains' phase delays (the trims in place at the end) and
    their standard errors, and one row of PHASE_COLUMNS a pass."""

    phase_x_deg: float
    phase_y_deg: float
    se_x_deg: float
    se_y_deg: float
    rows: np.ndarray


def result_from_rows(rows: np.ndarray) -> PhaseCal:
    """The outcome from the recorded passes: the last pass's trims, its residual's errors with the floor."""
    last = {n: float(rows[-1, i]) for i, n in enumerate(PHASE_COLUMNS)}
    se_x = math.hypot(last["residual_x_se_deg"], PHASE_FLOOR_DEG)
    se_y = math.hypot(last["residual_y_se_deg"], PHASE_FLOOR_DEG)
    return PhaseCal(last["trim_x_deg"], last["trim_y_deg"], se_x, se_y, rows)


def _hold(ctx, fpga, tap, columns: tuple[str, ...], hold_s: float, amplitude: float, fm_force_hz: float,
          fm_rate_hz: float) -> rp.PhaseReading:
    """Hold the wave hold_s and read the loops' phase error from the stream tap's rows."""
    fpga.sync()
    t0 = ctx.clock.now()
    tap.take(-math.inf, math.inf)
    ctx.sleep_until(t0 + hold_s)
    fpga.sync()
    rows = tap.take(t0, math.inf)
    col = {name: rows[:, i] for i, name in enumerate(columns)}
    return rp.read_phase(col["t_s"], np.radians(col["angle_out_deg"]), col["amp_ctrl"] / amplitude, col["freq_ctrl"],
                         fm_force_hz=fm_force_hz, fm_rate_hz=fm_rate_hz)


def calibrate_readout_phase(ctx, fpga, tap, columns: tuple[str, ...], *, passes: int, hold_s: float, move_dps: float,
                            amplitude: float, fm_force_hz: float, fm_rate_hz: float,
                            fm_amplitude_hz: float = 0.0) -> PhaseCal:
    """`passes` passes of: hold (read), turn the wave 45 deg at move_dps, hold (read), solve both
    chains, add them to the trims (TRIM_EN's TRIM_PHASE on).  The wave is in whole-angle mode with
    the frequency-control force on and the stream tap (t_s, angle_out_deg, amp_ctrl, freq_ctrl
    among `columns`) on.  Starts from the trims in place when TRIM_PHASE is on."""
    from drivers.fpga.protocol import TRIM_PHASE  # the frame codec's numba on a run, not on loading

    on = int(fpga.read_register("TRIM_EN")) & TRIM_PHASE
    trim = np.array([float(fpga.read_register(n)) if on else 0.0 for n in ("TRIM_PHASE_X_DEG", "TRIM_PHASE_Y_DEG")])
    rows = []
    sign = 1.0
    for k in range(passes):
        r1 = _hold(ctx, fpga, tap, columns, hold_s, amplitude, fm_force_hz, fm_rate_hz)
        fpga.set_whole_angle(True, sign * move_dps, fm_amplitude_hz, fm_rate_hz)
        ctx.sleep(45.0 / move_dps)
        fpga.set_whole_angle(True, 0.0, fm_amplitude_hz, fm_rate_hz)
        ctx.sleep(SETTLE_S)
        sign = -sign  # back and forth: the wave stays near where it started
        r2 = _hold(ctx, fpga, tap, columns, hold_s, amplitude, fm_force_hz, fm_rate_hz)
        res, cov = rp.channel_phases([r1, r2], floor_deg=1e-6)
        trim = trim + res
        fpga.set_readout_phase_trim(float(trim[0]), float(trim[1]))
        ctx.sleep(SETTLE_S)
        rows.append([ctx.clock.now(), r1.theta_deg, r1.phase_deg, r1.se_deg, r2.theta_deg, r2.phase_deg, r2.se_deg,
                     float(res[0]), float(res[1]), math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]), float(trim[0]),
                     float(trim[1])])
        ctx.log.info(f"readout phase pass {k + 1}/{passes}: read {r1.phase_deg:+.5f} deg at {r1.theta_deg:.1f} deg, "
                     f"{r2.phase_deg:+.5f} deg at {r2.theta_deg:.1f} deg; trims x {trim[0]:.5f}, y {trim[1]:.5f} deg")
    return result_from_rows(np.array(rows))
