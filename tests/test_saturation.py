"""Saturation is an error, not a result (issue 31 item 3).

The simulated FPGA flags every stream frame whose loop force sat at FORCE_LIMIT (`sat_flags`); a
procedure whose record saw a flag ends ERROR naming the loop; a command above a loop's limit is
refused before anything moves, the message naming the value and the limit (hrg-damping's
verification at 20 deg/s: the precession force 4 a Omega reaches FORCE_LIMIT 1 at 14.3 deg/s)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.fpga import protocol as p
from procedures.hrg_damping import HrgDamping

SHORT = {"rate_dps": 20.0, "record_s": 12.0, "stream_hz": 200.0, "verify_s": 12.0, "verify_settle_s": 1.0}


@pytest.fixture
def station():
    from bench.composition.sim_station import SimStation

    st = SimStation("sim-hrg", seed=2).open()
    try:
        yield st
    finally:
        st.close()


def _precess(st, rate_dps: float, seconds: float) -> np.ndarray:
    """Rows of the FPGA stream while the wave is precessed at rate_dps in whole-angle mode."""
    fpga = st.devices["fpga"]
    rows: list[np.ndarray] = []
    unsubscribe = fpga.subscribe(lambda b: rows.append(b.copy()))
    try:
        fpga.set_whole_angle(True, rate_dps)
        fpga.sync()
        rows.clear()
        st.clock.sleep(seconds)
        fpga.sync()
    finally:
        unsubscribe()
    return np.vstack(rows)


def test_the_stream_flags_a_saturated_precession_loop(station):
    """At 10 deg/s the wave turns as commanded and no frame is flagged; at 20 deg/s the force
    clamps, the wave turns at the limit (14.3 deg/s) and the frames carry SAT_PREC."""
    fpga = station.devices["fpga"]
    fpga.start_stream(10)
    S = p.STREAM_SCHEMA
    rows: list[np.ndarray] = []
    unsubscribe = fpga.subscribe(lambda b: rows.append(b.copy()))
    fpga.set_pll(True)
    fpga.set_quadrature_loop(True)
    fpga.set_agc(True, 1.0)
    fpga.set_drive_enabled(True)
    station.clock.sleep(30.0)
    fpga.sync()
    unsubscribe()
    start = np.vstack(rows)
    amp = start[:, S.index("sat_flags")].astype(int) & p.SAT_AMP
    t = start[:, S.index("t_s")]
    assert amp[t < t[0] + 1.0].mean() > 0.9 and not amp[t > t[-1] - 10.0].any()  # the AGC at its limit from rest
    slow = _precess(station, 10.0, 5.0)
    fast = _precess(station, 20.0, 5.0)
    assert not slow[:, S.index("sat_flags")].any()
    rate = np.polyfit(fast[:, S.index("t_s")], fast[:, S.index("angle_out_deg")], 1)[0]
    flags = fast[:, S.index("sat_flags")].astype(int)
    assert rate == pytest.approx(np.degrees(0.25), rel=2e-3)  # FORCE_LIMIT / (4 a): the clamp, not 20
    assert (flags & p.SAT_PREC).mean() > 0.9 and p.saturation_text(int(np.bitwise_or.reduce(flags))) == "precession"


def test_a_precession_above_the_force_limit_is_refused_before_anything_moves(station):
    from bench.engine import Runner, StationMismatch

    with pytest.raises(StationMismatch) as err:
        Runner(station).run(HrgDamping, SHORT | {"verify_rate_dps": 20.0})
    text = str(err.value)
    assert "verify_rate_dps=20" in text and "14.3 deg/s" in text and "13.6 deg/s" in text
    assert "FORCE_LIMIT" in text and "nothing was moved" in text
    assert not int(station.devices["fpga"].read_register("CTRL")) & p.DRIVE_EN
    HrgDamping(SHORT | {"verify_rate_dps": 20.0, "compensate": False}).preflight(station.devices)  # not commanded


class _Unchecked(HrgDamping):
    """hrg-damping without its up-front check, so the record meets the saturation."""

    name = "hrg-damping-unchecked"

    def preflight(self, devices) -> None:
        return None


def test_a_record_that_saw_saturation_ends_the_run_in_error(station, tmp_path):
    from bench.engine import Runner

    rec = Runner(station, runs_dir=tmp_path).run(_Unchecked, SHORT | {"verify_rate_dps": 20.0})
    assert rec.outcome == "ERROR" and rec.failed_step == "compensate_step"
    assert "LoopSaturated" in rec.end_reason and "precession loop saturated" in rec.end_reason
    assert "drift_reduction_ratio" not in {r.name for r in rec.measurements if r.measured}
    from bench.recorder import RunData

    with RunData(rec.raw_file) as data, pytest.raises(ValueError, match="precession loop saturated"):
        HrgDamping(rec.params).analysis(data)  # a re-fit of the raw file refuses it too


def test_settle_times_follow_from_the_loops_bandwidth_and_the_command(station):
    """A PI loop around an integrator x' = g F settles with its slowest pole; the wait before a
    record is ln(100) of those time constants (1 % of the step left), plus the wave's turn of
    22.5 deg when a whole-angle precession starts (the split observer's learning)."""
    import math

    from procedures.hrg_excitation import pi_loop_time_constant_s, settle_time_s

    assert pi_loop_time_constant_s(2.0, 1.0, 0.5) == pytest.approx(2.0)  # the FPGA's AGC: s^2 + s + 1/2
    assert pi_loop_time_constant_s(4.0, 4.0, 1.0) == pytest.approx(0.5)  # the rebalance loop: (s + 2)^2
    assert pi_loop_time_constant_s(10.0, 1.0, 1.0) == pytest.approx(2.0 / (10.0 - math.sqrt(96.0)))  # overdamped
    fpga = station.devices["fpga"]
    assert settle_time_s(fpga) == pytest.approx(2.0 * math.log(100.0))
    assert settle_time_s(fpga, 2.0) == pytest.approx(2.0 * math.log(100.0) + 22.5 / 2.0)
    for reg in ("AGC_KP", "AGC_KI"):  # a faster amplitude loop, s^2 + 2 s + 2: the quadrature loop is slowest
        fpga.write_register(reg, 4.0)
    assert settle_time_s(fpga) == pytest.approx(2.0 * math.log(100.0))
    for reg in ("QUAD_KP", "QUAD_KI"):
        fpga.write_register(reg, 4.0)
    assert settle_time_s(fpga) == pytest.approx(1.0 * math.log(100.0))


def test_the_cli_refuses_the_precession_with_the_limit_and_exit_2(tmp_path, capsys):
    from bench.cli import main

    code = main(["run", "hrg-damping", "--station", "sim-hrg", "--set", "verify_rate_dps=20",
                 "--runs-dir", str(tmp_path / "runs"), "--results", str(tmp_path / "r.sqlite")])
    err = capsys.readouterr().err
    assert code == 2 and "verify_rate_dps=20" in err and "14.3 deg/s" in err and "internal error" not in err
    assert not list((tmp_path / "runs").glob("*.h5"))  # refused before the run began


def test_force_to_rebalance_beyond_its_range_ends_the_series_in_error(tmp_path):
    """cvg-scale-factor on a force-to-rebalance unit at 80 deg/s: the wave's rate K Omega = 22 deg/s
    is beyond what the rebalance force can hold (14.3 deg/s at FORCE_LIMIT 1), the loop saturates and
    the run ends ERROR naming it, where it used to report a scale factor."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.cvg_scale_factor import CvgScaleFactor

    station = SimStation("sim-hrg-ftr", seed=1).open()
    try:
        rec = Runner(station, runs_dir=tmp_path).run(CvgScaleFactor, {"max_rate_dps": 80.0, "steps": 1,
                                                                      "average_s": 2.0, "settle_s": 1.0})
    finally:
        station.close()
    assert rec.outcome == "ERROR" and "rebalance loop saturated" in rec.end_reason
    assert "scale_factor" not in {r.name for r in rec.measurements if r.measured}
