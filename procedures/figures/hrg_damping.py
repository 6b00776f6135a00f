"""hrg-damping figures: ln E with its fit and residuals, the wave angle and quadrature, the drift
against the wave angle before and after compensation with the model the run reported (mean and
harmonics, from its measurements) and the residuals, the table's rate and angle, and the FPGA's
slow variables.  Every axis takes its quantity and unit from the run's declarations."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from bench.figures import (
    ReportFigure,
    axis_label,
    declared,
    fit_with_residuals,
    log_label,
    measurement,
    new_figure,
    plot_record,
    stream_figure,
    table_figure,
)
from bench.numbers import with_interval

HARMONICS = (4, 8, 12)
#: grids of axes with titles and a legend above: laid out in one pass (bench.figure_layout, issue 36)
LAYOUT = "measured"
_ENERGY, _RESIDUALS, _THETA, _QUAD = ("hrg-damping energy", "hrg-damping residuals", "hrg-damping theta",
                                      "hrg-damping quadrature")


def drift_model(data: Any, record: str) -> dict[str, Any] | None:
    """The drift model the run reported for a record ("before", "after"): its mean and each harmonic
    present (amplitude sin m(theta - phase)) from the recorded measurements drift_<record>_mean_dph,
    _<m>theta_dph and _<m>theta_phase_deg, with the rms the fit left; None when the run did not
    record them (a run older than the phase measurements, or without compensation)."""
    mean = measurement(data, f"drift_{record}_mean_dph")
    if mean is None:
        return None
    terms = {}
    for m in HARMONICS:
        amp = measurement(data, f"drift_{record}_{m}theta_dph")
        phase = measurement(data, f"drift_{record}_{m}theta_phase_deg")
        if amp is None or phase is None or amp.get("value") is None or phase.get("value") is None:
            return None
        terms[m] = (amp, phase)
    rest = measurement(data, f"drift_{record}_rest_rms_dph")

    def model(theta_deg: np.ndarray) -> np.ndarray:
        th = np.radians(np.asarray(theta_deg, dtype=float))
        y = np.full_like(th, float(mean["value"]))
        for m, (amp, phase) in terms.items():
            y += float(amp["value"]) * np.sin(m * (th - math.radians(float(phase["value"]))))
        return y

    return {"mean": mean, "terms": terms, "rest": rest, "model": model}


def energy_figure(data: Any) -> list[ReportFigure]:
    fits = data.fits()
    e = fits.get(_ENERGY)
    if not e:
        return []
    t, energy, efit = e["t_s"], e["energy"], e["energy_fit"]
    ok = (energy > 0) & (efit > 0)
    res = fits.get(_RESIDUALS, {}).get("residual_ln_e")
    res = res[ok] if res is not None and len(res) == len(t) else None
    e_unit = declared(data, _ENERGY, "energy")[1]
    fig = fit_with_residuals(t[ok], np.log(energy[ok]), np.log(efit[ok]), xlabel=axis_label(data, _ENERGY, "t_s"),
                             ylabel=log_label("E", e_unit), fit_label="free-decay fit", residual=res,
                             residual_label=axis_label(data, _RESIDUALS, "residual_ln_e"), layout=LAYOUT)
    tau = measurement(data, "tau_s")
    note = "Energy E = cx² + sx² + cy² + sy² of the decay record and the fitted free-decay model."
    if tau:
        v, ci = with_interval(tau["value"], tau.get("ci95"))
        note += f" τ = {v} {tau.get('unit') or ''}, 95 % interval {ci} {tau.get('unit') or ''}."
    return [ReportFigure("hrg-damping_energy", "Free decay: ln E with the fit and residuals", fig, note)]


def _decay_elements(proc: Any, data: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(t_s, theta_deg unwrapped, k/a) at every FPGA sample of the decay window, or None when the
    run recorded no window (the live curves are thinned by dropping samples, which aliases the 4θ
    pumping of the quadrature; the report reduces the full record by envelopes instead)."""
    from bench.analysis.slow_model import orbit_elements
    windows, decay = proc.windows_stream, proc.decay_kind
    if windows not in data or "fpga" not in data:
        return None
    win = data.table(windows)
    sel = win["kind"] == decay
    if not sel.any():
        return None
    fpga = data.table("fpga")
    t = fpga["t_s"]
    rows = (t > win["t_start_s"][sel][-1]) & (t <= win["t_end_s"][sel][-1])
    if rows.sum() < 8:
        return None
    el = orbit_elements(np.column_stack([fpga[c][rows] for c in ("cx", "sx", "cy", "sy")]).astype(float))
    theta = np.degrees(np.unwrap(4 * el["theta_rad"]) / 4)
    return t[rows], theta, el["k"] / np.maximum(el["a"], 1e-300)


def theta_figure(proc: Any, data: Any) -> list[ReportFigure]:
    fits = data.fits()
    th = fits.get(_THETA)
    if not th:
        return []
    quad = fits.get(_QUAD)
    full = _decay_elements(proc, data)
    if full is not None:
        t, theta, k = full
        th, quad = {"t_s": t, "theta_deg": theta}, {"t_s": t, "quadrature_rel": k}
    rows = 2 if quad else 1
    fig, ax = new_figure(rows, 1, height_in=1.4 + 1.3 * rows, sharex=True, layout=LAYOUT)
    plot_record(ax[0, 0], th["t_s"], th["theta_deg"], color="C0")
    ax[0, 0].set_ylabel(axis_label(data, _THETA, "theta_deg"))
    if quad:
        plot_record(ax[1, 0], quad["t_s"], quad["quadrature_rel"], color="C2")
        ax[1, 0].set_ylabel(axis_label(data, _QUAD, "quadrature_rel"))
    ax[-1, 0].set_xlabel(axis_label(data, _THETA, "t_s"))
    how = (f"every one of the {len(th['t_s'])} FPGA samples of the decay record, drawn as min/max envelopes"
           if full is not None else "the run's thinned curves")
    return [ReportFigure("hrg-damping_theta", "Free decay: wave angle θ(t) and quadrature", fig,
                         f"Wave angle (unwrapped) and relative quadrature k/a during the decay record ({how}).")]


def _fmt(m: dict[str, Any] | None) -> str:
    if m is None:
        return "—"
    v, ci = with_interval(m.get("value"), m.get("ci95"))
    return v + (f" {ci}" if ci != "—" else "")


def drift_figure(data: Any) -> list[ReportFigure]:
    """Drift against the wave angle before and after compensation: the points, the model the run
    reported (mean and 4θ, 8θ, 12θ harmonics, from its measurements) drawn over them, and the
    residual (points minus that model) beneath."""
    fits = data.fits()
    curves = {n: fits.get(f"hrg-damping drift {n}") for n in ("before", "after")}
    curves = {n: c for n, c in curves.items() if c and len(c.get("theta_deg", ())) >= 8}
    if not curves:
        return []
    fig, ax = new_figure(2, len(curves), height_in=4.6, sharex=True, sharey="row",
                         gridspec_kw={"height_ratios": [3, 1.3]}, layout=LAYOUT)
    rows, rest_text = [], []
    grid = np.linspace(-45.0, 45.0, 361)
    for j, (name, c) in enumerate(curves.items()):
        src = f"hrg-damping drift {name}"
        # the harmonics repeat every 90 deg: the unwrapped angle folded into [-45, 45)
        th, y = (np.asarray(c["theta_deg"]) + 45.0) % 90.0 - 45.0, np.asarray(c["drift_dph"])
        model = drift_model(data, name)
        top, bottom = ax[0, j], ax[1, j]
        top.plot(th, y, ".", color="C0", markersize=3, label="measured (per block)")
        top.set_title(f"compensation {'off' if name == 'before' else 'on'} ({name})")
        bottom.set_xlabel(axis_label(data, src, "theta_deg", quantity="wave angle θ, folded"))
        if j == 0:
            top.set_ylabel(axis_label(data, src, "drift_dph"))
            bottom.set_ylabel(axis_label(data, src, "drift_dph", quantity="measured − model"))
        if model is None:
            top.text(0.5, 0.95, "the run recorded no drift model for this record", transform=top.transAxes,
                     ha="center", va="top", fontsize=7.5)
            continue
        rest = model["rest"]
        rest_words = f"rest rms {_fmt(rest)} {rest.get('unit', '')}" if rest else "rest rms not recorded"
        fitted = " + ".join(["mean", *(f"{m}θ" for m in model["terms"])])
        top.plot(grid, model["model"](grid), color="C3", label=f"fit of the angle record: {fitted}")
        top.text(0.02, 0.03, rest_words, transform=top.transAxes, fontsize=7.5, va="bottom",
                 bbox={"facecolor": "white", "edgecolor": "0.8", "alpha": 0.85, "pad": 2})
        rest_text.append(f"{name}: {rest_words}")
        bottom.plot(th, y - model["model"](th), ".", color="C0", markersize=3)
        bottom.axhline(0.0, color="C3", linewidth=0.8)
        mean = model["mean"]
        rows.append([name, "mean", *with_interval(mean["value"], mean.get("ci95")), "—", mean.get("unit", "")])
        for m, (amp, phase) in model["terms"].items():
            rows.append([name, f"{m}θ", *with_interval(amp["value"], amp.get("ci95")),
                         " ".join(with_interval(phase["value"], phase.get("ci95"))) + f" {phase.get('unit', '')}",
                         amp.get("unit", "")])
        if rest:
            rows.append([name, "rest rms", *with_interval(rest["value"], rest.get("ci95")), "—", rest.get("unit", "")])
    handles, labels = [], []
    for a in ax[0]:
        for h, lab in zip(*a.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="outside upper center", ncols=2)
    ratio = measurement(data, "drift_reduction_ratio")
    note = ("The drift is read from the wave-angle record itself: a linear least-squares fit of θ(t) − command·t "
            "with the mean drift and the harmonics fitted (4θ, 8θ and 12θ, each amplitude · sin m(θ − phase)) "
            "integrated along the recorded angle; their intervals are that fit's. The line is that model, from the "
            "measurements drift_<record>_mean_dph, drift_<record>_<m>theta_dph and drift_<record>_<m>theta_phase_deg; "
            "the points are the drift rate over blocks of drift_block_s of the same record against the wave angle "
            "(folded into one 90° period), referred to the gyro output (÷ K), for comparison; beneath, the rest: "
            "the points minus the model (noise and any harmonic not fitted)"
            + (f" ({'; '.join(rest_text)})" if rest_text else "") + ".")
    if ratio:
        note += f" drift_reduction_ratio (4θ before / 4θ after) = {with_interval(ratio['value'], None)[0]}."
    header = ["record", "term", "amplitude", "95 % interval", "phase [95 % interval]", "unit"]
    return [ReportFigure("hrg-damping_drift", "Drift against the wave angle, before and after compensation", fig,
                         note, (header, rows))]


def fpga_figure(data: Any) -> list[ReportFigure]:
    """The FPGA's slow variables against time (envelopes of the full record)."""
    if "fpga" not in data:
        return []
    fig = stream_figure(data, "fpga", ["cx", "sx", "cy", "sy"], title="FPGA stream: slow variables",
                        key="hrg-damping_fpga", layout=LAYOUT)
    return [fig] if fig is not None else []


def figure_parts(proc: Any) -> list[Callable[[Any], list[ReportFigure]]]:
    """The figures in the report's order as independent parts, each a function of the run's data:
    a report builds and draws them in parallel processes (bench.reporting.drawing)."""
    return [energy_figure, partial(theta_figure, proc), drift_figure, partial(table_figure, layout=LAYOUT), fpga_figure]


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure an hrg-damping run's results need, in the report's order."""
    return [f for part in figure_parts(proc) for f in part(data)]
