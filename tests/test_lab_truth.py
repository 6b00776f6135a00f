"""Issue 31 items 4, 7, 8 and the reports: one axis convention with truth compared across the wrap,
one-sided intervals on a bound, lab limits through the line's judge, truths flagged outside."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.analysis.axes import axis_deg, axis_with_interval
from bench.numbers import error_in_intervals, truth_outside


def test_an_axis_is_reported_in_0_to_90_with_its_interval_shifted():
    assert axis_deg(-30.0) == pytest.approx(60.0)
    assert axis_deg(-1e-17) == 0.0 and axis_deg(90.0) == 0.0 and axis_deg(44.0) == 44.0
    value, ci = axis_with_interval(-0.5, (-1.5, 0.5))
    assert value == pytest.approx(89.5) and ci == pytest.approx((88.5, 90.5))


def test_truth_across_the_wrap_is_inside_the_interval_of_a_periodic_value():
    """89.5 +- 1 deg and a truth of 0.2 deg: 0.7 deg apart modulo 90, inside; without the period
    the comparison would call it 89 deg off."""
    assert truth_outside(89.5, 0.2, (88.5, 90.5), period=90.0) is False
    assert truth_outside(89.5, 0.2, (88.5, 90.5)) is True
    assert error_in_intervals(89.5, 0.2, (88.5, 90.5), period=90.0) == "−0.70"
    assert truth_outside(10.0, 12.5, (9.0, 11.0), period=90.0) is True


def test_a_one_sided_interval_bounds_one_side_only():
    assert truth_outside(0.0, 0.03, (0.0, math.inf)) is False
    assert truth_outside(0.0, 0.03, (0.0, 0.02)) is True
    assert truth_outside(1.0, 2.0, None) is None


def test_every_procedure_declares_its_axis_angles_periodic_in_90_deg():
    from procedures import find_procedure

    for name, meas in (("hrg-free-decay", ("theta_w_deg", "theta_tau_deg")), ("hrg-damping", ("theta_tau_deg",)),
                       ("hrg-selfcal", ("theta_w_deg", "theta_tau_deg")), ("mems-sweep", ("alpha_deg", "beta_deg"))):
        periods = find_procedure(name).truth_periods()
        for m in meas:
            assert periods.get(m) == 90.0, (name, m)


# --- the CLI and the report on one short simulated hrg-free-decay run ------------------------------
LIMITS_TOML = """
[product]
name = "lab-check"
rule = "guard-band"

[limits.tau_s]          # the preset's 300 s: the whole interval inside
low = 250.0
high = 400.0

[limits.split_hz]       # the preset's 5 mHz: wholly above
high = 0.001

[limits.theta_w_deg]    # the preset's 10 deg axis: seed 3's interval straddles it
high = 10.0
"""
FREE_DECAY = ["hrg-free-decay", "--set", "record_s=20", "--set", "rate_dps=20", "--seed", "3"]


@pytest.fixture(scope="module")
def lab_run(tmp_path_factory):
    """The run with --limits --json --report: (exit code, JSON, raw file, report HTML)."""
    import contextlib
    import io
    import json

    from bench.cli import main

    tmp = tmp_path_factory.mktemp("lab")
    (tmp / "limits.toml").write_text(LIMITS_TOML)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["run", *FREE_DECAY, "--runs-dir", str(tmp / "runs"), "--results", str(tmp / "r.sqlite"),
                     "--limits", str(tmp / "limits.toml"), "--json", "--report"])
    js = json.loads(out.getvalue().splitlines()[0])
    html = Path(js["raw_file"]).with_suffix(".html").read_text(encoding="utf-8")
    return code, js, Path(js["raw_file"]), html


def test_run_with_lab_limits_gives_the_lines_verdicts_in_json_and_report(lab_run):
    """ILAC G8 through the line's judge: PASS inside, FAIL wholly outside, MARGINAL (conditional) when
    the interval straddles the limit; the run exits 1 on a FAIL; the report says the same."""
    code, js, _raw, html = lab_run
    verdicts = {n: m.get("verdict") for n, m in js["measurements"].items() if m.get("verdict")}
    assert verdicts == {"tau_s": "PASS", "split_hz": "FAIL", "theta_w_deg": "MARGINAL"}
    assert js["limits"]["outcome"] == "FAIL" and js["limits"]["product"] == "lab-check" and code == 1
    assert js["limits"]["measurements"]["split_hz"]["rule"] == "guard-band"
    assert "MARGINAL (conditional)" in html and ">FAIL<" in html and ">PASS<" in html
    assert "lab-check" in html and "No limits given" not in html


def test_cli_table_shows_verdicts_and_flags_truths(lab_run, capsys):
    """The table printed from the same record: verdicts, the count line and the '!' marks agree."""
    from bench.cli.record_table import print_record, truth_flags

    _code, js, _raw, _html = lab_run
    print_record(js)
    text = capsys.readouterr().out
    flags = truth_flags(js)
    n_out = sum(flags.values())
    assert f"{n_out} of {len(flags)} truths outside their 95 % intervals" in text
    marked = sum(line.endswith(" !") for line in text.splitlines())
    assert marked == n_out == len(js["truth_outside"]["outside"])
    assert "MARGINAL (conditional)" in text and "FAIL" in text and "COMPLETE" not in text.split("\n", 1)[1]


def test_report_flags_each_truth_outside_and_counts_them(lab_run):
    from bench.recorder import open_run
    from bench.reporting import context

    _code, js, raw, html = lab_run
    with open_run(raw) as data:
        ctx = context(data, figures=([], []))
    rows = {r["name"]: r for r in ctx["measurements"]}
    outside = sorted(n for n, r in rows.items() if r["outside"])
    assert outside == js["truth_outside"]["outside"] and ctx["truth_outside"] == (len(outside),
                                                                                   js["truth_outside"]["compared"])
    assert f"{len(outside)} of {js['truth_outside']['compared']} truths outside their 95 % intervals" in html
    assert html.count('class="outside"') == len(outside) and html.count("✗ outside") == len(outside)


def test_a_short_decay_fits_the_tables_ripple_so_its_damping_terms_hold_their_truth(lab_run):
    """20 s at 20 deg/s is 400 deg of table turn: the once- and twice-per-turn angle ripple is fitted
    (it used to be only from 720 deg on, and D then read ~2.7 % high, outside its interval in 20 of
    20 seeds; docs/free_decay_identification.md).  The damping terms' truths now lie inside."""
    _code, js, _raw, _html = lab_run
    outside = set(js["truth_outside"]["outside"])
    assert not outside & {"delta_inv_tau_per_s", "damping_anisotropy_per_s", "maslov_b_s", "maslov_b_c"}
    assert len(outside) <= 4, outside  # of 32 compared: chance, not a model error


def test_without_limits_the_report_says_so_and_an_error_runs_rows_keep_their_own_status(lab_run, tmp_path):
    """No limits: 'No limits given', rows 'measured'; the same run marked ERROR shows no row COMPLETE:
    a fitted row says measured, a declared one never reported NOT_MEASURED."""
    import shutil

    import h5py

    from bench.reporting import write_report

    _code, _js, raw, _html = lab_run
    copy = tmp_path / "error.h5"
    shutil.copy(raw, copy)
    with h5py.File(copy, "a") as f:
        del f.attrs["lab_limits"]
        f.attrs["outcome"], f.attrs["end_reason"] = "ERROR", "link lost: test"
    page = write_report(copy)[0].read_text(encoding="utf-8")
    table = page.split('<table class="measurements">')[1].split("</table>")[0]
    assert "No limits given" in page and "COMPLETE" not in table and ">measured<" in table


def test_pdf_tables_repeat_their_header_on_each_page(lab_run):
    """The report as WeasyPrint lays it out: the measurement table (36 rows) breaks across pages and
    every page holding one of its rows shows its header again."""
    weasyprint = pytest.importorskip("weasyprint")

    _code, _js, _raw, html = lab_run
    texts = [_page_text(p) for p in weasyprint.HTML(string=html).render().pages]
    with_rows = [t for t in texts if "maslov_h_s_ee" in t or "maslov_gamma " in t or "tau_s_ee" in t]
    assert len(with_rows) >= 2, "the table does not break: nothing to check"
    assert all("truth (simulation)" in t for t in with_rows), texts


def _page_text(page) -> str:
    """The text WeasyPrint laid out on one page."""
    out = []

    def walk(box):
        text = getattr(box, "text", None)
        if text:
            out.append(text)
        for child in getattr(box, "children", ()) or ():
            walk(child)
    walk(page._page_box)
    return " ".join(out)


# --- item 5: the drift read from the angle record ----------------------------------------------------
def _precessing_angle(seed: int, drift_dph: float = 30.0, phase_deg: float = 20.0, noise_rad: float = 2e-4):
    """A wave precessing at 2 deg/s for 90 s with a 4 theta drift (wave-angle rad/s) and
    white pickoff noise on the angle, sampled at 200 Hz: (t, theta, command, 4 theta amplitude rad/s)."""
    rng = np.random.default_rng(seed)
    cmd = math.radians(2.0)
    amp = math.radians(drift_dph / 3600.0)
    ph = math.radians(phase_deg)
    dt = 5e-3
    t = np.arange(0.0, 90.0, dt)
    th = np.empty_like(t)
    th[0] = 0.1
    for i in range(1, t.size):  # Heun steps of d theta / dt = cmd + amp sin 4 (theta - ph)
        f0 = cmd + amp * math.sin(4 * (th[i - 1] - ph))
        guess = th[i - 1] + dt * f0
        th[i] = th[i - 1] + 0.5 * dt * (f0 + cmd + amp * math.sin(4 * (guess - ph)))
    return t, th + rng.normal(0.0, noise_rad, t.size), cmd, amp


def test_the_angle_fit_reads_the_drift_with_a_far_tighter_honest_interval_than_block_slopes():
    """Seeded records: the angle-record fit's 4 theta interval covers the truth ~95 % and is over ten
    times narrower than the 1 s block slopes' (fit_angle_drift on block_drift)."""
    from bench.analysis.damping import fit_angle_drift, fit_angle_harmonics
    from procedures.hrg_damping import block_drift

    covered, ratios = 0, []
    for seed in range(20):
        t, th, cmd, amp = _precessing_angle(seed)
        h = fit_angle_harmonics(t, th, cmd, orders=(4, 8, 12)).drift.harmonics[4]
        covered += h.ci95[0] <= amp <= h.ci95[1]
        assert math.degrees(h.phase_rad) == pytest.approx(20.0, abs=1.0)
        mids, rate = block_drift(t, th, 1.0)
        old = fit_angle_drift(mids, rate - cmd).amplitude_ci95
        ratios.append((old[1] - old[0]) / (h.ci95[1] - h.ci95[0]))
    assert covered >= 17 and min(ratios) > 10.0, (covered, ratios)


# --- reports: cvg-allan's y labels ----------------------------------------------------------------
class _AllanData:
    """The two things allan_figure reads: the curve stream and the measurements."""

    def __init__(self, tau, adev):
        self._curve = {"tau_s": tau, "adev_dph": adev, "adev_low_dph": adev * 0.8, "adev_high_dph": adev * 1.25}

    def __contains__(self, name):
        return name == "cvg_allan_curve"

    def table(self, _name):
        return self._curve

    def measurements(self):
        return [{"name": "bias_instability_dph", "value": 0.15, "ci95": [0.12, 0.19]}]


def test_allan_figure_labels_y_ticks_below_1_dph():
    """A curve between 0.1 and 0.6 deg/h (inside one decade): labelled y ticks there, not blank."""
    from procedures.figures.cvg_allan import allan_figure

    tau = np.geomspace(1.0, 1000.0, 10)
    adev = 0.1 + 0.5 / np.sqrt(tau)
    fig = allan_figure(_AllanData(tau, adev))[0].figure
    ax = fig.axes[0]
    fig.canvas.draw()
    lo, hi = ax.get_ylim()
    shown = [t.get_text() for t, v in zip(ax.yaxis.get_ticklabels(), ax.get_yticks(), strict=True)
             if lo <= v <= hi and t.get_text()]
    assert len(shown) >= 2 and all(float(x.replace("−", "-")) < 1.0 for x in shown[:2]), shown


# --- reports: cvg-scale-factor's figure and its nonlinearity use the same points -------------------
def test_scale_factor_figure_draws_the_points_its_nonlinearity_is_read_from():
    """Up then down sweeps with hysteresis: the single windows reach further than their up/down
    mean; the figure's up/down-mean curve peaks exactly at the reported nonlinearity."""
    from types import SimpleNamespace

    from bench.analysis.cvg_rate import fit_scale_factor
    from procedures.cvg_scale_factor import rate_series
    from procedures.figures.cvg import scale_factor_figures

    rate = rate_series(100.0, 4)
    rng = np.random.default_rng(2)
    hysteresis = np.where(np.arange(rate.size) < rate.size // 2, 1.0, -1.0) * 2e-3
    out = -0.277 * rate + 1e-3 * (rate / 100.0) ** 2 * 100.0 + hysteresis + rng.normal(0, 2e-4, rate.size)
    fit = fit_scale_factor(rate, out)
    proc = SimpleNamespace(windows_schema=SimpleNamespace(name="w"), _analyse=lambda _data: fit)
    fig = scale_factor_figures(proc, {"w", "fpga"})[0]
    lines = {ln.get_label(): ln for ln in fig.figure.axes[1].get_lines()}
    means = lines["up/down mean (nonlinearity)"].get_ydata()
    assert np.max(np.abs(means)) == pytest.approx(fit.nonlinearity_ppm, rel=1e-9)
    assert np.max(np.abs(fit.residual_ppm)) > fit.nonlinearity_ppm  # the single windows differ
    assert "up and down" in fig.note


def test_every_hrg_selfcal_measurement_has_an_interval_or_says_why_not():
    """From seeded synthetic cycle and rate tables through the procedure's own analysis: each
    result carries a 95 % interval, or its declaration says why it has none."""
    from procedures import hrg_selfcal as hs

    rng = np.random.default_rng(1)
    n_cyc = 4
    cyc = np.full((n_cyc, len(hs.CYCLE_COLUMNS)), 1e-3)  # standard errors and the rest: small
    col = {n: i for i, n in enumerate(hs.CYCLE_COLUMNS)}
    for c in range(n_cyc):
        cyc[c, col["t_start_s"]], cyc[c, col["t_end_s"]] = 3600.0 * c, 3600.0 * (c + 1)
    for name, value in (("q_factor", 5e6), ("delta_inv_tau_per_s", 1.6e-4), ("theta_tau_deg", 20.0),
                        ("split_hz", 5e-3), ("theta_w_deg", 10.0), ("gain_diff_ppm", 1500.0)):
        cyc[:, col[name]] = value
    t = np.arange(0.0, 4 * 3600.0, 1.0)
    rates = np.column_stack([t, np.degrees(0.01 * t), 20 * np.sin(t / 300.0), 20 * np.sin(t / 300.0),
                             rng.normal(0.0, 0.6, t.size)])
    results = hs._analyse(cyc, rates, 100.0, 1.0, 0.95)
    reasons = hs.HrgSelfcal.no_interval_reasons()
    bare = [r.name for r in results if r.ci95 is None and r.name not in reasons]
    assert bare == [], bare
    arw = next(r for r in results if r.name == "angle_arw_deg_rth")
    assert arw.ci95[0] == 0.0 and arw.ci95[1] >= arw.value


def test_hrg_damping_mean_drift_is_compared_with_no_truth_and_the_report_says_why():
    """The mean verification drift has no simulator truth that one record can be held to (the loops'
    random walk, docs/damping_drift.md): it is neither flagged nor counted, and its row says why."""
    from bench.reporting import _table_rows
    from procedures.hrg_damping import MEAN_DRIFT_NO_TRUTH, HrgDamping

    truth = HrgDamping.truth_for({"drift_before_mean_dph": 0.0, "drift_after_mean_dph": 0.0,
                                  "drift_before_8theta_dph": 0.0})
    assert "drift_before_mean_dph" not in truth and "drift_after_mean_dph" not in truth
    assert truth["drift_before_8theta_dph"] == 0.0  # the harmonics keep theirs
    reasons = HrgDamping.no_truth_reasons()
    assert set(reasons) == {"drift_before_mean_dph", "drift_after_mean_dph"}
    m = {"value": -0.038, "ci95": [-0.048, -0.027], "unit": "deg/h", "outcome": "COMPLETE", "source": "run"}
    known = {"truth": truth, "periods": {}, "lab": {}, "why_not": {}, "why_no_truth": reasons}
    rows = {r["name"]: r for r in _table_rows({"drift_before_mean_dph": m, "drift_before_8theta_dph": m}, known)}
    mean = rows["drift_before_mean_dph"]
    assert not mean["outside"] and not mean["compared"] and mean["truth_why"] == MEAN_DRIFT_NO_TRUTH
    assert rows["drift_before_8theta_dph"]["outside"] and rows["drift_before_8theta_dph"]["truth_why"] == ""
