"""`gyrobench report RAMP --against SOAK`: the two thermal methods' residuals on the same unit.
The pure comparison against known numbers; the pairing rules (a soak and a ramp, one unit); a
short soak and ramp on sim-hrg-thermal-quick whose comparison page (HTML and PDF) shows the
comparison's own numbers; one-line refusals for a mismatched pair."""

from __future__ import annotations

import contextlib
import io
import json
import shutil

import h5py
import numpy as np
import pytest

from bench.analysis.thermal_compare import compare_at_soak_points, frequency_as_temperature
from bench.analysis.thermal_fit import fit_temperature_polynomial
from bench.numbers import sig
from bench.reporting.thermal_compare import CompareRefused, order_pair, unit_of

SOAK = ["--set", "t_low_degc=15", "--set", "t_high_degc=35", "--set", "points=3", "--set", "ramp_degc_per_min=30",
        "--set", "settle_window_s=30", "--set", "settle_ppm_per_min=0.2", "--set", "record_s=60",
        "--set", "max_order=2"]
RAMP = ["--set", "t_low_degc=15", "--set", "t_high_degc=35", "--set", "cycle_degc_per_min=5", "--set", "segment_s=20",
        "--set", "tail_s=60", "--set", "settle_window_s=30", "--set", "settle_ppm_per_min=0.2", "--set", "max_order=2",
        "--set", "rate_dps=10"]


def test_the_comparison_takes_each_fit_at_the_soak_points():
    """Bias 100 + 0.5 (T - 25) with known offsets left by each fit: the rms and ratios are those offsets'."""
    t = np.array([0.0, 25.0, 50.0])
    bias = 100.0 + 0.5 * (t - 25.0)
    line = fit_temperature_polynomial(t, 5500.0 + 0.3 * (t - 25.0), np.full(3, 1e-4), max_order=1, min_order=1)
    f = line(t)
    assert np.allclose(frequency_as_temperature(f, line), t)
    soak_fit = lambda x: 100.0 + 0.5 * (np.asarray(x) - 25.0) + np.array([0.1, -0.1, 0.1])  # noqa: E731
    ramp = {"frequency": lambda x: 100.0 + 0.5 * (np.asarray(x) - 25.0) + 0.14,
            "part": lambda x: 100.0 + 0.5 * (np.asarray(x) - 25.0) - 0.3,
            "air": lambda x: 100.0 + 0.5 * (np.asarray(x) - 25.0)}
    pts = {"part_c": t, "air_c": t + 1.0, "f0_hz": f, "bias_dph": bias, "bias_se_dph": np.full(3, 0.2)}
    c = compare_at_soak_points(pts, soak_fit, ramp, line, soak_s=3600.0, ramp_s=1000.0)
    assert c.soak.rms_dph == pytest.approx(0.1)
    assert c.ramp["frequency"].rms_dph == pytest.approx(0.14) and c.ramp["frequency"].ratio == pytest.approx(1.4)
    assert c.ramp["part"].ratio == pytest.approx(3.0)
    assert c.ramp["air"].rms_dph == pytest.approx(0.5)  # the settled air read 1 degC off: 0.5 deg/h
    assert c.best.thermometer == "frequency" and c.time_ratio == pytest.approx(1000 / 3600)
    assert c.meets_target() and not c.meets_target("part") and c.noise_rms_dph == pytest.approx(0.2)


def _attrs(proc, run_id, **kw):
    base = {"procedure": proc, "run_id": run_id, "duts": [], "simulated": True, "station_id": "sim-x",
            "station": {"simulation": {"preset": "hrg-realistic"}}, "seed": 0}
    return base | kw


def test_a_pair_is_one_soak_and_one_ramp_of_one_unit():
    soak, ramp = _attrs("thermal-soak", "s"), _attrs("thermal-ramp", "r")
    assert order_pair(ramp, soak) == (1, 0) and order_pair(soak, ramp) == (0, 1)
    assert unit_of(ramp) == "simulated sim-x (preset hrg-realistic, seed 0)"
    with pytest.raises(CompareRefused, match="not a thermal-soak and a thermal-ramp"):
        order_pair(ramp, _attrs("thermal-ramp", "r2"))
    with pytest.raises(CompareRefused, match="different units"):
        order_pair(ramp, soak | {"seed": 1})
    with pytest.raises(CompareRefused, match="different units"):
        order_pair(ramp | {"duts": ["SN1"]}, soak | {"duts": ["SN2"]})
    with pytest.raises(CompareRefused, match="names no unit"):
        order_pair(ramp | {"simulated": False}, soak | {"simulated": False})


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A short soak and a short ramp of unit SN1 on sim-hrg-thermal-quick, through the command line."""
    from bench.cli import main

    d = tmp_path_factory.mktemp("thermal_compare")
    out = {}
    for name, args in (("thermal-soak", SOAK), ("thermal-ramp", RAMP)):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            code = main(["run", name, "--station", "sim-hrg-thermal-quick", "--dut", "SN1", "--json",
                         "--results", str(d / "r.db"), "--runs-dir", str(d / "runs"), *args])
        assert code == 0, buf.getvalue()
        js = json.loads(buf.getvalue().strip().splitlines()[-1])
        out[name] = js["run_id"]
    return d, out


def test_the_page_shows_the_comparisons_numbers(runs, capsys):
    from bench.cli import main
    from bench.recorder import open_run
    from bench.reporting.thermal_compare import compare

    d, ids = runs
    code = main(["report", ids["thermal-soak"], "--against", ids["thermal-ramp"], "--results", str(d / "r.db"),
                 "--pdf"])
    out, err = capsys.readouterr()
    assert code == 0, err
    html_path, pdf_path = (d / "runs" / p.split("/")[-1] for p in out.split())
    assert html_path.name == f"{ids['thermal-ramp']}-vs-{ids['thermal-soak']}.html"
    assert pdf_path.read_bytes()[:4] == b"%PDF"
    html = html_path.read_text()
    with open_run(d / "runs" / f"{ids['thermal-soak']}.h5") as soak, \
            open_run(d / "runs" / f"{ids['thermal-ramp']}.h5") as ramp:
        cmp, sf = compare(soak, ramp)
        own_rms = {m["name"]: m["value"] for m in soak.measurements()}["bias_fit_rms_dph"]
        assert cmp.soak_s == soak.attrs["simulated_s"] and cmp.ramp_s == ramp.attrs["simulated_s"]
    assert cmp.soak.rms_dph == pytest.approx(own_rms, rel=1e-12)  # the soak's own fit, as its analysis had it
    assert len(sf["t_c"]) > 0  # the ramp turned the table: its scale factor is drawn
    for x in (cmp.soak.rms_dph, *(c.rms_dph for c in cmp.ramp.values()), *(c.ratio for c in cmp.ramp.values()),
              cmp.soak_s / 3600, cmp.ramp_s / 3600, cmp.time_ratio, cmp.noise_rms_dph):
        assert f">{sig(x)}<" in html, sig(x)
    assert html.count("<figure") == 2 + 2  # the comparison's two, then the ramp report's own two
    assert "Target met" in html or "Target not met" in html


def test_a_mismatched_pair_is_refused_in_one_line(runs, capsys, tmp_path):
    from bench.cli import main

    d, ids = runs
    soak_file = d / "runs" / f"{ids['thermal-soak']}.h5"
    ramp_file = d / "runs" / f"{ids['thermal-ramp']}.h5"
    pages = set((d / "runs").glob("*-vs-*"))
    for other, why in ((ramp_file, "not a thermal-soak and a thermal-ramp"), (None, "different units (SN1 and SN2)")):
        if other is None:
            other = tmp_path / "other.h5"
            shutil.copy(soak_file, other)
            with h5py.File(other, "r+") as f:
                f.attrs["duts"] = json.dumps(["SN2"])
        code = main(["report", str(ramp_file), "--against", str(other)])
        out, err = capsys.readouterr()
        assert code == 2 and why in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
        assert out == ""
    assert set((d / "runs").glob("*-vs-*")) == pages and not list(tmp_path.glob("*.html"))  # nothing written
