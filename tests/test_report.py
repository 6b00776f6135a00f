"""The run report (issue 15): numbers as a calibration file writes them, the figure helpers
against known answers, each procedure's figures and page from short simulated runs, the CLI's
`report --pdf` and `analyze --figures`, and the page loaded in Debian's headless Chromium (no
console message, every figure shown; under CI=true a missing browser fails the test)."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.figures import NO_UNIT, envelope
from bench.numbers import error_in_intervals, limits, plain, pretty_unit, sig, with_interval
from bench.recorder import open_run
from bench.reporting import figures_for, render_html
from bench.reporting.browser import chromium, load, screenshot
from procedures.figures.hrg_damping import drift_model
from procedures.figures.hrg_free_decay import trajectory
from tests.needs import need

#: short runs, seconds each (the report, not the physics, is under test here)
RUNS = {
    "hrg-damping": ("sim-hrg", {"rate_dps": 20.0, "record_s": 20.0, "stream_hz": 100.0, "verify_rate_dps": 8.0,
                                "verify_s": 15.0, "verify_settle_s": 1.0}),
    "hrg-free-decay": ("sim-hrg", {"record_s": 20.0, "rate_dps": 20.0}),
    "mems-sweep": ("sim-mems", {"n_points": 9}),
    "table-spin": ("sim-hrg", {"hold_s": 0.5}),
}


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
    # rounding that carries into the next decade keeps four significant digits, not five or three
    assert sig(99.9988) == "100.0" and sig(9.99951e6) == "1.000e7" and sig(-0.0099999) == "−0.01000"


def test_the_table_angle_is_unwrapped_with_the_rate_readings():
    """At 500 deg/s read every 0.39 s the angle moves 195 deg a reading: the angle alone cannot be
    unwrapped (np.unwrap gets it wrong), with the rate readings it comes back exactly."""
    from bench.figures import unwrap_angle_deg

    t = np.arange(0.0, 40.0, 0.39)
    rate = np.clip(t * 200.0, 0.0, 500.0)  # 200 deg/s^2 up to 500 deg/s
    true = np.where(t < 2.5, 100.0 * t ** 2, 625.0 + 500.0 * (t - 2.5))
    read = true % 360.0
    assert np.max(np.abs(unwrap_angle_deg(t, read, rate) - true)) < 1e-9
    assert np.max(np.abs(np.degrees(np.unwrap(np.radians(read))) - true)) > 360.0


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
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
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
            out[name] = (page, figs, notes, {m["name"]: m for m in data.measurements()}, ctx)
    return out


def declared_units(data) -> set[str]:
    """Every unit the run declared: its streams' columns, its fits' curves, its measurements."""
    units = {u for s in data.streams() for _, u in data.declared(s).values()}
    units |= {u for f in data.fits() for _, u in data.declared(f).values()}
    units = (units | {m.get("unit") or "1" for m in data.measurements()}) - {""}
    return {pretty_unit(u) for u in units}  # as printed: deg/s^2 as deg/s²


def undeclared_axes(figs, data) -> list[tuple[str, str]]:
    """(figure, label) of every axis label whose unit (the last parenthesis) is missing or is not a
    unit the run declared."""
    units, bad = declared_units(data), []
    for f in figs:
        for ax in f.figure.axes:
            for text in (ax.get_xlabel(), ax.get_ylabel()):
                if not text:
                    continue
                found = re.search(r"\(([^()]*)\)\s*$", text)
                if found is None or found.group(1) == NO_UNIT or found.group(1) not in units:
                    bad.append((f.key, text))
    return bad


@pytest.mark.parametrize("name", list(RUNS))
def test_each_procedure_names_its_figures_and_the_page_shows_them(pages, name):
    page, figs, notes, meas, ctx = pages[name]
    html = page.read_text(encoding="utf-8")
    assert [f.key for f in figs] == EXPECTED_FIGURES[name] and notes == []
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
        assert "mean + 4θ + 8θ + 12θ" in html and "<td>8θ</td>" in html and "rest rms" in html
        assert "drift_&lt;record&gt;_mean_dph" in html  # text is escaped, never read as markup


@pytest.mark.parametrize("name", list(RUNS))
def test_every_axis_has_a_unit_the_run_declared(runs, name):
    """Every axis of every figure names a unit the run's declarations give (stream columns, fit
    curves, measurements); none is looked up from a name."""
    with open_run(runs[name]) as data:
        figs, _ = figures_for(data)
        n_axes = sum(1 for f in figs for ax in f.figure.axes for t in (ax.get_xlabel(), ax.get_ylabel()) if t)
        assert n_axes >= 4 and undeclared_axes(figs, data) == []


def _copy(raw: Path, tmp_path: Path) -> Path:
    out = tmp_path / raw.name
    shutil.copy(raw, out)
    return out


def test_an_axis_follows_the_declared_unit_and_a_missing_one_is_caught(runs, tmp_path):
    """Change the units the raw file declares: the axes follow; take one away: the check above
    names that axis."""
    import h5py

    raw = _copy(runs["table-spin"], tmp_path)
    with h5py.File(raw, "r+") as f:
        hold = f["streams/hold"]
        hold.attrs["units"] = np.array(["s", "rad/s"], dtype=h5py.string_dtype())
        hold.attrs["quantities"] = np.array(["time t", "spin rate ω"], dtype=h5py.string_dtype())
        del f["streams/table"].attrs["units"]  # a file whose table stream declares no units
    with open_run(raw) as data:
        figs, _ = figures_for(data)
        labels = {(f.key, ax.get_ylabel()) for f in figs for ax in f.figure.axes}
        assert ("table-spin_rate", "spin rate ω (rad/s)") in labels
        assert undeclared_axes(figs, data) == [("table", f"table rate Ω ({NO_UNIT})"), ("table", f"time t ({NO_UNIT})"),
                                               ("table", f"table angle, unwrapped ({NO_UNIT})")]
    raw = _copy(runs["hrg-damping"], tmp_path)
    with h5py.File(raw, "r+") as f:  # a fit's curve declared in another unit
        for name in ("before", "after"):
            f[f"fits/hrg-damping drift {name}/drift_dph"].attrs["units"] = "deg/s"
    with open_run(raw) as data:
        figs, _ = figures_for(data)
        drift = next(f for f in figs if f.key == "hrg-damping_drift")
        assert drift.figure.axes[0].get_ylabel() == "drift, output-referred (deg/s)"


def test_the_drift_figure_draws_the_model_the_run_reported(runs):
    """The drawn model is the run's own (mean and 4, 8, 12 theta terms from its measurements): the
    points minus it have exactly the rest rms the run reported."""
    with open_run(runs["hrg-damping"]) as data:
        fits = data.fits()
        for name in ("before", "after"):
            c, model = fits[f"hrg-damping drift {name}"], drift_model(data, name)
            rms = np.sqrt(np.mean((c["drift_dph"] - model["model"](c["theta_deg"])) ** 2))
            assert rms == pytest.approx(model["rest"]["value"], rel=1e-9)
            assert sorted(model["terms"]) == [4, 8, 12]


def test_drift_phase_interval_covers_the_true_phase():
    """The 4 theta phase's 95 % interval covers the true phase in about 95 % of seeded records."""
    from bench.analysis.damping import fit_drift_harmonics

    rng = np.random.default_rng(5)
    th = np.linspace(0, math.pi / 2, 90, endpoint=False)
    hits = 0
    for _ in range(400):
        y = 0.3 + 1.0 * np.sin(4 * (th - 0.2)) + rng.normal(0, 1.5, th.size)
        lo, hi = fit_drift_harmonics(th, y).harmonics[4].phase_ci95
        period = math.pi / 2
        hits += any(lo <= 0.2 + k * period <= hi for k in (-1, 0, 1))
    assert 0.92 <= hits / 400 <= 0.98


@pytest.mark.parametrize("name", list(RUNS))
def test_every_table_row_is_written_as_a_calibration_file_writes_it(pages, name):
    """Each measurement to two significant digits of its interval's half-width (four without one),
    with its unit; on a simulated run each declared truth shown with the error in units of the
    interval; each numeric parameter with its unit."""
    from procedures import find_procedure

    _, _, _, meas, ctx = pages[name]
    cls = find_procedure(name)
    truth = {r["name"]: r for r in ctx["measurements"]}
    for row in ctx["measurements"]:
        m = meas[row["name"]]
        assert (row["value"], row["interval"]) == with_interval(m["value"], m.get("ci95")), row
        assert row["unit"], row
    truths = {spec.name for spec in cls.measurements if spec.truth is not None}
    shown = [r for r in ctx["measurements"] if r["name"] in truths and r["truth"] != "—"]
    assert ctx["truth_shown"] == (name != "table-spin")
    for r in shown:
        assert r["error"] != "—" or r["interval"] == "—", r
    missing = [r["name"] for r in ctx["measurements"] if r["name"] in truths and r["truth"] == "—"]
    assert missing == [], missing
    for p in ctx["params"]:
        assert p["unit"] or not re.match(r"^[−\d.]", p["value"]), p
    if name == "hrg-free-decay":  # the model coefficients are matched to the simulator's truth
        assert truth["maslov_gamma"]["truth"] != "—" and truth["maslov_h_c"]["error"] != "—"


def test_hrg_free_decay_model_trajectory_follows_the_record(runs):
    """The identified model integrated from the first sample stays on the measured slow variables:
    residual rms below 1 % of the amplitude over the record."""
    from procedures.figures.hrg_free_decay import _params, _record
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


def test_the_printed_page_shows_each_figure_as_a_png_of_the_same_layout(runs):
    """The PDF's page: every figure an <img> of a PNG at PRINT_DPI (the figure's inches x dpi, in
    the layout the SVG had), everything else the HTML page's text."""
    import base64
    import struct

    from bench.figures import PRINT_DPI
    from bench.reporting import context, with_png_figures

    with open_run(runs["table-spin"]) as data:
        figs, notes = figures_for(data)
        ctx = context(data, None, (figs, notes))
        positions = [[ax.get_position().bounds for ax in f.figure.axes] for f in figs]
        printed = render_html(data, None, with_png_figures(ctx, figs))
        html = render_html(data, None, ctx)
    pngs = re.findall(r'<img class="figure" alt="[^"]*" src="data:image/png;base64,([^"]+)">', printed)
    assert len(pngs) == len(figs) == 2 and "<svg" not in printed
    for b64, f, before in zip(pngs, figs, positions, strict=True):
        png = base64.b64decode(b64)
        width, height = struct.unpack(">II", png[16:24])  # the IHDR chunk
        w_in, h_in = f.figure.get_size_inches()
        assert (width, height) == (round(w_in * PRINT_DPI), round(h_in * PRINT_DPI))
        assert [ax.get_position().bounds for ax in f.figure.axes] == before  # not laid out again
    strip = re.compile(r"<figure id=.*?</figure>", re.S)
    assert strip.sub("", printed) == strip.sub("", html)


# --- in a real browser -------------------------------------------------------------------------
def _chromium() -> str | None:
    return chromium()


def browse(page: Path, profile: Path, screenshot_png: Path | None = None) -> tuple[str, list[str]]:
    """(DOM after load, console messages) of a page in headless Chromium."""
    dom, console = load(page, profile)
    if screenshot_png is not None:
        screenshot(page, screenshot_png, profile, full_page=True)
    return dom, console


def test_the_console_check_sees_an_error(tmp_path):
    """The check below is not blind: a page that throws shows up."""
    need(_chromium() is not None, "Debian's chromium is not installed (apt-get install chromium)")
    page = tmp_path / "bad.html"
    page.write_text("<html><body><svg width='4' height='4'></svg><script>missing();</script></body></html>")
    dom, console = browse(page, tmp_path / "profile")
    assert dom.count("<svg") == 1 and any("missing is not defined" in c for c in console)


@pytest.mark.parametrize("name", list(RUNS))
def test_report_loads_in_headless_chromium_with_every_figure(pages, name, tmp_path):
    """No console message at all (the page has no script) and one <svg> a figure in the DOM.  (The
    screenshots in docs/ are of full default runs: docs/make_report_screenshots.py.)"""
    need(_chromium() is not None, "Debian's chromium is not installed (apt-get install chromium)")
    dom, console = browse(pages[name][0], tmp_path / "profile")
    assert console == []
    assert dom.count("<svg") == len(EXPECTED_FIGURES[name])
    assert dom.count("<figcaption>") == len(EXPECTED_FIGURES[name])


def test_report_pdf_without_weasyprint_writes_the_html_and_says_why(runs, tmp_path, monkeypatch, capsys):
    """One clear message naming the missing library and the extra, no traceback; exit code 2."""
    from bench.cli import main

    monkeypatch.setitem(sys.modules, "weasyprint", None)  # import fails as if not installed
    code = main(["report", str(runs["table-spin"]), "--pdf", "-o", str(tmp_path / "r.html")])
    out, err = capsys.readouterr()
    assert code == 2 and "WeasyPrint" in err and "gyrobench[pdf]" in err and "Traceback" not in err
    assert (tmp_path / "r.html").is_file() and not (tmp_path / "r.pdf").exists()


def test_a_certificate_page_fills_the_report_templates_block(runs, tmp_path, monkeypatch):
    """The extension point for the production line's certificate (#17): a template that extends
    report.html.j2 and fills its `certificate` block is rendered before the report, with its own
    variables, and the report below it is unchanged."""
    import bench.reporting as reporting

    shutil.copy(reporting.TEMPLATES / "report.html.j2", tmp_path / "report.html.j2")
    (tmp_path / "cert.html.j2").write_text('{% extends "report.html.j2" %}{% block certificate %}'
                                           '<section id="cert">Certificate {{ serial }}</section>{% endblock %}')
    with open_run(runs["table-spin"]) as data:
        plain_page = render_html(data)
        monkeypatch.setattr(reporting, "TEMPLATES", tmp_path)
        page = render_html(data, template="cert.html.j2", extra={"serial": "SN-0042 <A>"})
    assert '<section id="cert">Certificate SN-0042 &lt;A&gt;</section>' in page
    assert page.index('id="cert"') < page.index("<h1>")
    def text(html: str) -> str:  # the figures' clip-path ids are drawn afresh each time
        return re.sub(r"<svg.*?</svg>", "", html, flags=re.S)

    assert text(page.replace('<section id="cert">Certificate SN-0042 &lt;A&gt;</section>', "")) == text(plain_page)


def test_table_spin_reports_its_mean_rate_with_an_interval_that_covers_the_true_rate():
    """The mean of the held readings comes with a Student t 95 % interval (so the table prints it
    to two digits of that interval): it covers the true rate in about 95 % of seeded holds."""
    from procedures.examples.table_spin import TableSpin

    class Hold:
        def __init__(self, rate):
            self.rate = rate

        def table(self, stream):
            return {"rate_dps": self.rate}

    rng, proc, hits = np.random.default_rng(7), TableSpin({}), 0
    for _ in range(400):
        (res,) = proc.analysis(Hold(100.0 + rng.normal(0.0, 0.003, 10)))
        hits += res.ci95[0] <= 100.0 <= res.ci95[1]
    assert 0.92 <= hits / 400 <= 0.98
