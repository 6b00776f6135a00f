"""cvg-allan on sim-hrg-wa through the real transports: a 1 h static record, in whole-angle
(sim-hrg-wa) and in force-to-rebalance (sim-hrg-wa-ftr), recovers
the simulated angle random walk, bias instability and rate random walk within its intervals, and
each interval is decisive (excludes 0); re-analysis of the raw file gives the same; the figure
draws the curve with its band and the three slope lines.  (benchmarks/cvg_allan_speed.py runs the
10 h record.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.recorder import open_run
from procedures.cvg_allan import CvgAllan, rate_from_stream


@pytest.mark.parametrize("sim_station", ["sim-hrg-wa", "sim-hrg-wa-ftr"], indirect=True)
def test_cvg_allan_recovers_the_simulated_noise_terms(run_procedure, sim_truth):
    """In both output modes: whole-angle (the wave angle's rate) and force-to-rebalance (the rate
    output over G K, the mode and scale factor read from the FPGA and recorded)."""
    record = run_procedure(CvgAllan, {"record_s": 3600.0, "settle_s": 10.0})
    assert record.outcome == "COMPLETE", (record.end_reason, record.traceback)
    got = {m.name: m for m in record.measurements}
    for name in ("arw_deg_rth", "bias_instability_dph", "rrw_dph_rth"):
        m, true = got[name], sim_truth[name]
        assert m.ci95[0] <= true <= m.ci95[1], (name, m.value, m.ci95, true)
        assert m.ci95[0] > 0, (name, m.ci95)  # decisive: the term is seen
    assert CvgAllan.truth_for(sim_truth)["arw_deg_rth"] == 0.01
    # the mean output: Earth's rate on the axis and the turn-on bias (the drive's turn-on, the
    # world's second), within the mean's rough interval
    world = record.truth
    assert world["earth_rate_dph"] == pytest.approx(15.041 * math.sin(math.radians(48.0)), abs=1e-3)
    # the same numbers from the raw file, and the figure
    data = open_run(record.raw_file)
    win = data.table("cvg_allan_window")
    ftr = sim_truth.get("cvg_output_mode", 0.0) == 1.0
    assert win["output_mode"][-1] == float(ftr)
    assert win["scale_factor"][-1] == pytest.approx(3.6 * 0.277 if ftr else -0.277, rel=1e-6)
    again = {r.name: r.value for r in CvgAllan(record.params).analysis(data)}
    for name in ("arw_deg_rth", "bias_instability_dph", "rrw_dph_rth"):
        assert again[name] == pytest.approx(got[name].value, rel=1e-9)
    figs = CvgAllan(record.params).figures(data)
    assert [f.key for f in figs] == ["cvg-allan_adev"]
    ax = figs[0].figure.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    labels = [line.get_label() for line in ax.get_lines()]
    assert any("-1/2" in lab or "−1/2" in lab for lab in labels) and any("+1/2" in lab for lab in labels)
    assert any("slope 0" in lab for lab in labels)


def test_rate_from_stream_is_the_wave_rate_over_minus_k():
    """A wave-angle output turning at -K Omega gives the rate Omega (deg/h) at the midpoints."""
    k, omega_dph = 0.277, 11.2
    t = np.arange(0.0, 100.0, 0.1)
    theta_deg = -k * (omega_dph / 3600.0) * t + math.degrees(0.3)
    tm, rate = rate_from_stream(t, theta_deg, k)
    assert np.allclose(tm, t[:-1] + 0.05) and np.allclose(rate, omega_dph, rtol=1e-9)
