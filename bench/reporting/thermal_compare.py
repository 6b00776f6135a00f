"""The thermal-ramp report compared with a thermal-soak of the same unit (`gyrobench report RAMP
--against SOAK`, docs/chamber.md "Ramp against soak"): the bias each method's compensation
leaves at the soak's settled points by thermometer, the simulated times, the issue's target, then
the ramp run's own report (the page extends report.html.j2 through its `certificate` block)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bench.analysis.thermal_compare import (
    RESIDUAL_RATIO_TARGET,
    THERMOMETER_LABELS,
    TIME_RATIO_TARGET,
    ThermalComparison,
    compare_at_soak_points,
)
from bench.analysis.thermal_fit import fit_temperature_polynomial
from bench.figures import ReportFigure, new_figure
from bench.numbers import sig
from bench.pdf import require_weasyprint, write_pdf

from . import TEMPLATES, context, figures_for, procedure_of, with_png_figures

SOAK, RAMP = "thermal-soak", "thermal-ramp"


class CompareRefused(ValueError):
    """Two runs that cannot be compared (not a soak and a ramp, or not the same unit): one line why."""


def unit_of(attrs: dict[str, Any]) -> str:
    """The unit a run measured, as text: its DUT serial(s), else (a simulated station) the station,
    preset and seed that make the simulated unit; '' when a real run names no DUT."""
    duts = [str(d) for d in (attrs.get("duts") or [])]
    if duts:
        return ", ".join(duts)
    if attrs.get("simulated"):
        preset = ((attrs.get("station") or {}).get("simulation") or {}).get("preset", "")
        return f"simulated {attrs.get('station_id', '?')} (preset {preset or '?'}, seed {attrs.get('seed')})"
    return ""


def order_pair(a: dict[str, Any], b: dict[str, Any]) -> tuple[int, int]:
    """(index of the soak, index of the ramp) of two runs' attributes, or CompareRefused."""
    names = [str(x.get("procedure", "")) for x in (a, b)]
    if sorted(names) != [RAMP, SOAK]:
        raise CompareRefused(f"runs {a.get('run_id')} ({names[0] or '?'}) and {b.get('run_id')} ({names[1] or '?'}) "
                             f"are not a {SOAK} and a {RAMP}: nothing to compare")
    units = [unit_of(x) for x in (a, b)]
    if not all(units):
        which = a if not units[0] else b
        raise CompareRefused(f"run {which.get('run_id')} names no unit (run it with --dut SERIAL): "
                             "a comparison needs both runs on the same unit")
    if units[0] != units[1]:
        raise CompareRefused(f"runs {a.get('run_id')} and {b.get('run_id')} are of different units "
                             f"({units[0]} and {units[1]}): the comparison needs the same unit")
    return (0, 1) if names[0] == SOAK else (1, 0)


def compare(soak_data: Any, ramp_data: Any) -> tuple[ThermalComparison, dict[str, Any]]:
    """The comparison of two recorded runs (soak, ramp) and the ramp's scale-factor pairs about
    their line against the frequency thermometer ({} when the ramp turned no table)."""
    soak, ramp = procedure_of(soak_data), procedure_of(ramp_data)
    if soak is None or ramp is None:
        raise CompareRefused("the runs' procedures cannot be rebuilt from their recorded parameters")
    points, soak_fit, _ = soak.fits(soak_data)
    points["air_c"] = np.asarray(soak_data.table(soak.windows_schema.name)["air_c"], dtype=float)
    p, ramp_fits, _, line = ramp.fits(ramp_data)
    cmp = compare_at_soak_points(points, soak_fit, ramp_fits, line, soak_s=float(soak_data.attrs["simulated_s"]),
                                 ramp_s=float(ramp_data.attrs["simulated_s"]))
    sf: dict[str, Any] = {}
    if "sf" in p:
        sf_line = fit_temperature_polynomial(p["frequency_c"], p["sf"], p["sf_se"], max_order=1, min_order=1,
                                             t_ref_c=25.0)
        sf = {"t_c": p["frequency_c"], "residual_ppm": sf_line.residuals / sf_line.coeffs[0] * 1e6,
              "se_ppm": p["sf_se"] / sf_line.coeffs[0] * 1e6, "branch": p["branch"]}
    return cmp, sf


_COLORS = {"soak": "k", "frequency": "C3", "part": "C2", "air": "C0"}


def comparison_figures(cmp: ThermalComparison, sf: dict[str, Any]) -> list[ReportFigure]:
    """The bias left at the soak's points by each compensation against temperature (and the ramp's
    scale factor about its line where it turned the table); the rms and the times against the target."""
    fig, ax = new_figure(1, 2 if sf else 1, height_in=3.4)
    a = ax[0, 0]
    s = cmp.soak
    a.errorbar(s.temperature_c, s.residual_dph, yerr=1.96 * cmp.bias_se_dph, fmt="o", color=_COLORS["soak"],
               markersize=4, capsize=2, label=f"{s.label}: {s.rms_dph:.3g} rms (95 % of each point)")
    for k, c in cmp.ramp.items():
        a.plot(c.temperature_c, c.residual_dph, "s" if k == "frequency" else "^" if k == "part" else "v",
               color=_COLORS[k], markersize=5, label=f"{c.label}: {c.rms_dph:.3g} rms ({c.ratio:.2f}x)")
    a.axhline(0.0, color="0.5", lw=0.8)
    a.set_xlabel("temperature (degC): each compensation's own thermometer")
    a.set_ylabel("bias left at the soak's points (deg/h)")
    a.legend(loc="best", fontsize="x-small")
    if sf:
        a = ax[0, 1]
        heat = sf["branch"] == 0
        for sel, name, c in ((heat, "heating", "C3"), (~heat, "cooling", "C0")):
            a.errorbar(sf["t_c"][sel], sf["residual_ppm"][sel], yerr=1.96 * sf["se_ppm"][sel], fmt="o", color=c,
                       markersize=3, capsize=2, label=f"ramp pairs, {name}")
        a.axhline(0.0, color="0.5", lw=0.8)
        a.set_xlabel("frequency thermometer (degC)")
        a.set_ylabel("scale factor about its line (ppm)")
        a.legend(loc="best", fontsize="x-small")
    residuals = ReportFigure(
        "thermal-compare_residuals", "Bias left at the soak's settled points, by compensation", fig,
        f"Each fit subtracted from the soak's {len(cmp.part_c)} settled biases, at the temperature its thermometer "
        "reads there (the ramp's frequency thermometer reads the soak's frequencies through the ramp's own line)."
        + (" Right: the ramp's scale factor (+-rate pairs) about its straight line; the soak records at rest, "
           "so it has no scale factor to compare." if sf else ""))
    fig, ax = new_figure(1, 2, height_in=2.8)
    a = ax[0, 0]
    rows = [cmp.soak, *cmp.ramp.values()]
    names = ["soak\n(case TC)"] + [f"ramp\n({THERMOMETER_LABELS[k].split()[-1]})" for k in cmp.ramp]
    x = np.arange(len(rows))
    a.bar(x, [r.rms_dph for r in rows], color=[_COLORS["soak"], *(_COLORS[k] for k in cmp.ramp)], alpha=0.8)
    a.set_xticks(x, names)  # categories: one tick each (new_figure's locator would repeat them)
    a.axhline(RESIDUAL_RATIO_TARGET * cmp.soak.rms_dph, color="C1", ls="--", lw=1.0, label="1.5x the soak's")
    a.axhline(cmp.noise_rms_dph, color="0.4", ls=":", lw=1.0, label="the points' own noise")
    a.set_ylabel("rms bias left (deg/h)")
    a.tick_params(axis="x", labelsize="x-small")
    a.legend(loc="best", fontsize="x-small")
    a = ax[0, 1]
    a.bar([0, 1], [cmp.soak_s / 3600.0, cmp.ramp_s / 3600.0], color=["k", "C3"], alpha=0.8)
    a.set_xticks([0, 1], ["soak", "ramp"])
    a.axhline(TIME_RATIO_TARGET * cmp.soak_s / 3600.0, color="C1", ls="--", lw=1.0, label="1/3 of the soak's")
    a.set_ylabel("simulated time (h)")
    a.legend(loc="best", fontsize="x-small")
    target = ReportFigure("thermal-compare_target", "Residual and time against the target", fig,
                          "Issue 34's target: the ramp within 1.5x of the soak's residual in at most a third of its "
                          "simulated time.")
    return [residuals, target]


def comparison_rows(cmp: ThermalComparison) -> list[dict[str, str]]:
    """The table's rows: each compensation's rms and ratio (numbers as the page shows them)."""
    rows = [{"label": cmp.soak.label + " (its own points)", "rms": sig(cmp.soak.rms_dph), "ratio": sig(1.0)}]
    for c in cmp.ramp.values():
        rows.append({"label": c.label, "rms": sig(c.rms_dph), "ratio": sig(c.ratio)})
    return rows


def section_context(cmp: ThermalComparison, soak_attrs: dict[str, Any], ramp_attrs: dict[str, Any]) -> dict[str, Any]:
    """What the comparison section shows, numbers formatted."""
    best = cmp.best
    return {
        "soak_run": soak_attrs.get("run_id"), "ramp_run": ramp_attrs.get("run_id"), "unit": unit_of(ramp_attrs),
        "soak_h": sig(cmp.soak_s / 3600.0), "ramp_h": sig(cmp.ramp_s / 3600.0), "time_ratio": sig(cmp.time_ratio),
        "n_points": len(cmp.part_c), "noise": sig(cmp.noise_rms_dph), "rows": comparison_rows(cmp),
        "best": best.label, "best_ratio": sig(best.ratio),
        "met": cmp.meets_target(), "residual_target": f"{RESIDUAL_RATIO_TARGET:g}", "time_target": "1/3",
        "residual_met": best.ratio <= RESIDUAL_RATIO_TARGET, "time_met": cmp.time_ratio <= TIME_RATIO_TARGET,
    }


def write_comparison(run_file: str | Path, against_file: str | Path, rows: dict[str, dict[str, Any]] | None = None,
                     output: str | Path | None = None, pdf: bool = False) -> list[Path]:
    """The ramp's report with the comparison against the soak first (the two runs in either order),
    beside the ramp's raw file as `<ramp>-vs-<soak>.html` (or output), and with pdf the PDF beside
    it; CompareRefused before anything is written when the pair cannot be compared.  rows: the
    results-store rows by run id (the ramp's is shown)."""
    import jinja2

    from bench.recorder import open_run

    if pdf:
        require_weasyprint()
    with open_run(run_file) as a_data, open_run(against_file) as b_data:
        si, ri = order_pair(a_data.attrs, b_data.attrs)
        soak_data, ramp_data = (a_data, b_data)[si], (a_data, b_data)[ri]
        ramp_file = (run_file, against_file)[ri]
        cmp, sf = compare(soak_data, ramp_data)
        cfigs = comparison_figures(cmp, sf)
        figures = figures_for(ramp_data)
        ctx = context(ramp_data, (rows or {}).get(str(ramp_data.attrs.get("run_id"))), figures)
        section = section_context(cmp, soak_data.attrs, ramp_data.attrs)
        env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True, trim_blocks=True,
                                 lstrip_blocks=True, undefined=jinja2.StrictUndefined)
        page = env.get_template("thermal_compare.html.j2")

        def render(c: dict[str, Any], shown: list[dict[str, Any]]) -> str:
            return page.render(**c, compare=section, compare_figures=shown)

        svg = [{"title": f.title, "svg": f.svg(), "note": f.note, "key": f.key} for f in cfigs]
        out = Path(output or Path(ramp_file).with_name(
            f"{ramp_data.attrs.get('run_id')}-vs-{soak_data.attrs.get('run_id')}.html"))
        out.write_text(render(ctx, svg), encoding="utf-8")
        paths = [out]
        if pdf:
            png = with_png_figures({"figures": svg}, cfigs)["figures"]
            paths.append(write_pdf(render(with_png_figures(ctx, figures[0]), png), out.with_suffix(".pdf")))
    return paths
