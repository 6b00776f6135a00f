"""The run report (issue 15): numbers as a calibration file writes them, the figure helpers
against known answers, each procedure's figures and page from short simulated runs, the CLI's
`report --pdf` and `analyze --figures`, and the page loaded in Debian's headless Chromium (no
console message, every figure shown; under CI=true a missing browser fails the test)."""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.recorder import open_run
from bench.reporting import figures_for, render_html
from bench.reporting.damping import drift_model
from bench.reporting.figures import NO_UNIT, envelope
from bench.reporting.free_decay import trajectory
from bench.reporting.numbers import error_in_intervals, limits, plain, sig, with_interval
from tests.needs import need

#: short runs, seconds each (the report, not the physics, is under test here)
RUNS = {
    "hrg-damping": ("sim-hrg", {"rate_dps": 20.0, "record_s": 20.0, "stream_hz": 100.0, "verify_rate_dps": 8.0,
                                "verify_s": 15.0, "verify_settle_s": 1.0}),
    "hrg-free-decay": ("sim-hrg", {"record_s": 20.0, "rate_dps": 20.0}),
    "mems-sweep": ("sim-mems", {"n_points": 9}),
    "table-spin": ("sim-hrg", {"hold_s": 0.5}),
}
DOCS = Path(__file__).resolve().parents[1] / "docs"


# --- numbers ------------------------------------------------------------------------------------
def test_a_value_with_an_interval_gets_two_significant_digits_of_its_half_width():
    assert with_interval(19.968101807777803, (19.882257843751017, 20.05394577180459)) == ("19.968", "[19.882, 20.054]")
    assert with_interval(300.0022456402901, (299.99759600262433, 300.00689527795583)) == (
        "300.0022", "[299.9976, 300.0069]")
    assert with_interval(1.6062239e-4, (1.5962791e-4, 1.6161688e-4)) == ("1.6062e-4", "[1.5963e-4, 1.6162e-4]")
    assert with_interval(-12.790691629486028, (-12.828, -12.753)) == ("−12.791", "[−12.828, −12.753]")
    assert with_interval(3.0, None) == ("3.000", "—")


def test_a_value_without_an_interval_gets_four_significant_digits_and_empty_fields_a_dash():
    assert sig(-1.3889999999999998) == "−1.389"
    assert sig(5183627.878423158) == "5.184e6" and sig(0.045319814131001446) == "0.04532"
    assert sig(None) == sig(float("nan")) == sig("") == "—"
    assert plain(500.0) == "500" and plain(0.277) == "0.277" and plain(True) == "yes"
    assert limits(99.5, 100.5) == "[99.5, 100.5]" and limits(None, 3) == "≤ 3" and limits(None, None) == "—"
    assert error_in_intervals(19.968, 20.0, (19.882, 20.054)) == "−0.37"
    assert error_in_intervals(1.0, 2.0, None) == "—"


# --- figure helpers ----------------------------------------------------------------------------
def test_envelope_keeps_every_extreme_of_a_long_record():
    """A one-sample spike survives the reduction (decimation by 10 would drop 9 in 10 of them)."""
    rng = np.random.default_rng(1)
    t = np.arange(100_003) * 1e-3
    y = rng.normal(size=t.size)
    y[54_321] = 50.0
    x, lo, hi = envelope(t, y, bins=1000)
    assert len(x) == 1001 and hi.max() == 50.0 and lo.min() == y.min()
    assert np.all(lo <= hi)
    short = envelope(t[:100], y[:100])
    assert np.array_equal(short[1], y[:100])


def test_linear_trajectory_matches_an_adaptive_integration():
    """The free-decay model integrated exactly (eigen-decomposition) against scipy's integrator."""
    from scipy.integrate import solve_ivp

    from bench.analysis.slow_model import LINEAR_PARAM_NAMES, slow_rhs

    params = dict(zip(LINEAR_PARAM_NAMES, (0.05, 0.3, 0.01, -0.02, 0.4, 0.0, 0.03, 0.01), strict=True))
    zg = np.array(list(params.values()))
    t = np.linspace(10.0, 40.0, 301)
    q0 = np.array([1.0, 0.1, -0.2, 0.05])
    exact = trajectory(t, q0, params, lam_rad_s=0.2)
    ref = solve_ivp(lambda _t, x: slow_rhs(x, zg, lam=0.2), (0, 30.0), q0, t_eval=t - 10.0, rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(exact - ref.y.T)) < 1e-7


# --- each procedure's report from a short simulated run ------------------------------------------
@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One short run of each procedure: {name: raw file}."""
    from bench.engine import Runner
    from bench.station import SimStation
    from procedures import find_procedure

    tmp = tmp_path_factory.mktemp("report_runs")
    out = {}
    for name, (station_name, params) in RUNS.items():
        station = SimStation(station_name, seed=3).open()
        try:
            record = Runner(station, runs_dir=tmp / "runs", operator="A. Tester", duts=["HRG-0042"]).run(
                find_procedure(name), params)
        finally:
            station.close()
        assert record.outcome in ("COMPLETE", "PASS"), (name, record.traceback)
        out[name] = Path(record.raw_file)
    return out


EXPECTED_FIGURES = {
    "hrg-damping": ["hrg-damping_energy", "hrg-damping_theta", "hrg-damping_drift", "table", "hrg-damping_fpga"],
    "hrg-free-decay": ["hrg-free-decay_slow", "hrg-free-decay_elements", "table"],
    "mems-sweep": ["mems-sweep_channel1", "mems-sweep_channel2", "mems-sweep_polar", "mems-sweep_residuals"],
    "table-spin": ["table-spin_rate", "table"],
}


@pytest.fixture(scope="module")
def pages(runs, tmp_path_factory):
    """Each run's report page, rendered once: {name: (html file, figures, notes, measurements)}."""
    from bench.reporting import context

    tmp = tmp_path_factory.mktemp("report_pages")
    out = {}
    for name, raw in runs.items():
        with open_run(raw) as data:
            figs, notes = figures_for(data)
            ctx = context(data, figures=(figs, notes))
            page = tmp / f"{name}.html"
            page.write_text(render_html(data, ctx=ctx), encoding="utf-8")
            out[name] = (page, figs, notes, {m["name"]: m for m in data.measurements()})
    return out


@pytest.mark.parametrize("name", list(RUNS))
def test_each_procedure_names_its_figures_and_the_page_shows_them(pages, name):
    page, figs, notes, meas = pages[name]
    html = page.read_text(encoding="utf-8")
    assert [f.key for f in figs] == EXPECTED_FIGURES[name] and notes == []
    for f in figs:  # every axis names its quantity and unit
        for ax in f.figure.axes:
            if ax.get_xlabel():
                assert "(" in ax.get_xlabel() and ")" in ax.get_xlabel(), (f.key, ax.get_xlabel())
    assert html.count("<svg") == len(figs)
    for text in ("A. Tester", "HRG-0042", "sim-hrg" if name != "mems-sweep" else "sim-mems", "software version"):
        assert text in html
    assert "None" not in re.sub(r"<svg.*?</svg>", "", html, flags=re.S)
    # a very fine interval legitimately asks for many decimals (the output-error fit's bryan_factor
    # is 0.276999975 +- 3e-8); a float's repr (15-17 digits) never appears
    assert not re.search(r"\d\.\d{14,}", re.sub(r"<svg.*?</svg>", "", html, flags=re.S)), "17-digit numbers"
    assert ">deg/s</td>" in html or name == "mems-sweep"  # parameters carry units
    if name == "hrg-damping":  # truth and the error in units of the interval, on a simulated station
        v, ci = with_interval(meas["tau_s"]["value"], meas["tau_s"]["ci95"])
        assert f">{v}</td>" in html and ">300.00" in html
        err = error_in_intervals(meas["tau_s"]["value"], 300.0, meas["tau_s"]["ci95"])
        assert f">{err}</td>" in html
        assert "mean + 4θ, 8θ, 12θ" in html and "<td>8θ</td>" in html


def test_hrg_free_decay_model_trajectory_follows_the_record(runs):
    """The identified model integrated from the first sample stays on the measured slow variables:
    residual rms below 1 % of the amplitude over the record."""
    from bench.reporting.free_decay import _params, _record
    from procedures.hrg_free_decay import HrgFreeDecay

    with open_run(runs["hrg-free-decay"]) as data:
        proc = HrgFreeDecay(data.params)
        t, q, win = _record(proc, data)
        params, source = _params(proc, data, t, q)
        model = trajectory(t, q[0], params, 2 * math.pi * (win[2] - proc.natural_freq_hz))
    assert source == "the run's measurements"
    amp = np.sqrt(np.mean(np.sum(q ** 2, axis=1)))
    assert np.sqrt(np.mean(np.sum((q - model) ** 2, axis=1))) < 0.01 * amp


def test_cli_report_pdf_and_analyze_figures(runs, tmp_path):
    raw = runs["table-spin"]
    gyro = [sys.executable, "-m", "bench.cli"]
    rep = subprocess.run(gyro + ["report", str(raw), "--pdf", "-o", str(tmp_path / "r.html")], capture_output=True,
                         text=True, timeout=120)
    assert rep.returncode == 0, rep.stderr
    html, pdf = (Path(p) for p in rep.stdout.split())
    assert html.read_text().count("<svg") == 2
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 10_000
    an = subprocess.run(gyro + ["analyze", str(raw), "--figures", str(tmp_path / "figs")], capture_output=True,
                        text=True, timeout=120)
    assert an.returncode == 0, an.stderr
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == ["table-spin_rate.svg", "table.svg"]


# --- in a real browser -------------------------------------------------------------------------
def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def browse(page: Path, profile: Path, screenshot: Path | None = None) -> tuple[str, list[str]]:
    """(DOM after load, console messages) of a page in headless Chromium."""
    flags = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", "--hide-scrollbars"]
    run = subprocess.run(flags + ["--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
    if screenshot is not None:
        shot = subprocess.run(flags + [f"--screenshot={screenshot}", "--window-size=1280,4000", page.as_uri()],
                              capture_output=True, text=True, timeout=120)
        assert shot.returncode == 0 and screenshot.is_file(), shot.stderr[-2000:]
    return run.stdout, console


def test_the_console_check_sees_an_error(tmp_path):
    """The check below is not blind: a page that throws shows up."""
    need(_chromium() is not None, "Debian's chromium is not installed (apt-get install chromium)")
    page = tmp_path / "bad.html"
    page.write_text("<html><body><svg width='4' height='4'></svg><script>missing();</script></body></html>")
    dom, console = browse(page, tmp_path / "profile")
    assert dom.count("<svg") == 1 and any("missing is not defined" in c for c in console)


@pytest.mark.parametrize("name", list(RUNS))
def test_report_loads_in_headless_chromium_with_every_figure(pages, name, tmp_path):
    """No console message at all (the page has no script) and one <svg> a figure in the DOM.  With
    GYROBENCH_DOCS_SCREENSHOTS=1 a screenshot replaces docs/report_<name>.png."""
    need(_chromium() is not None, "Debian's chromium is not installed (apt-get install chromium)")
    update_docs = os.environ.get("GYROBENCH_DOCS_SCREENSHOTS") == "1"
    shot = tmp_path / f"report_{name}.png"
    dom, console = browse(pages[name][0], tmp_path / "profile", shot if update_docs else None)
    assert console == []
    assert dom.count("<svg") == len(EXPECTED_FIGURES[name])
    assert dom.count("<figcaption>") == len(EXPECTED_FIGURES[name])
    if update_docs:
        shutil.copy(shot, DOCS / f"report_{name}.png")


def test_report_pdf_without_weasyprint_writes_the_html_and_says_why(runs, tmp_path, monkeypatch, capsys):
    """One clear message naming the missing library and the extra, no traceback; exit code 2."""
    from bench.cli import main

    monkeypatch.setitem(sys.modules, "weasyprint", None)  # import fails as if not installed
    code = main(["report", str(runs["table-spin"]), "--pdf", "-o", str(tmp_path / "r.html")])
    out, err = capsys.readouterr()
    assert code == 2 and "WeasyPrint" in err and "gyrobench[pdf]" in err and "Traceback" not in err
    assert (tmp_path / "r.html").is_file() and not (tmp_path / "r.pdf").exists()
