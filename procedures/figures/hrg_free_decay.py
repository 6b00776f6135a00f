"""hrg-free-decay figures: the slow variables and the orbit elements (E, theta) measured, with the
identified model's trajectory integrated forward from the identified parameters and the first
sample of the record, and the residuals."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.figures import (
    ReportFigure,
    axis_label,
    declared,
    log_label,
    measurement,
    new_figure,
    plot_record,
    table_figure,
    unit_text,
)

_NAMES = ("cx", "sx", "cy", "sy")
_ELEMENTS = "hrg-free-decay elements"  # the fit whose declaration gives E's and theta's units


def _params(proc: Any, data: Any, t: np.ndarray, q: np.ndarray) -> tuple[dict[str, float], str]:
    """The identified parameters: from the run's measurements (maslov_<name>), else identified again."""
    from bench.analysis.maslov_terms import free_param_names

    names = free_param_names(proc.model)
    found = {n: measurement(data, f"maslov_{n}") for n in names}
    if all(found.values()):
        return {n: float(m["value"]) for n, m in found.items()}, "the run's measurements"
    _, fit, _, _ = proc._analyse(data)
    return dict(fit.params), "identified again from the record"


def trajectory(t_s: np.ndarray, q0: np.ndarray, params: dict[str, float], lam_rad_s: float) -> np.ndarray:
    """The slow-variable model integrated forward from q0 at the times t_s (linear: exactly, by the
    eigen-decomposition of its matrix; with xi or kappa: by an adaptive integrator)."""
    from bench.analysis.slow_model import LINEAR_PARAM_NAMES, linear_matrix, slow_rhs

    zg = np.array([params[n] for n in LINEAR_PARAM_NAMES])
    xi, kappa = params.get("xi", 0.0), params.get("kappa", 0.0)
    tau = np.asarray(t_s, dtype=float) - t_s[0]
    if not xi and not kappa:
        w, v = np.linalg.eig(linear_matrix(zg, lam_rad_s))
        c = np.linalg.solve(v, q0.astype(complex))
        return np.real((v[None, :, :] * (np.exp(np.outer(tau, w)) * c)[:, None, :]).sum(axis=2))
    from scipy.integrate import solve_ivp

    sol = solve_ivp(lambda _t, x: slow_rhs(x, zg, xi=xi, kappa=kappa, lam=lam_rad_s), (0.0, tau[-1]), q0,
                    t_eval=tau, method="DOP853", rtol=1e-9, atol=1e-12)
    return sol.y.T


def _record(proc: Any, data: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_s, q, window row in the order of the procedure's window_columns) of the identified record, decimated as the
    procedure's analysis does; columns by name."""
    window = data.table(proc.window_stream)
    win = np.array([window[c][-1] for c in proc.window_columns])
    fpga = data.table("fpga")
    sel = (fpga["t_s"] >= window["t_start_s"][-1]) & (fpga["t_s"] <= window["t_end_s"][-1])
    period = float(np.median(np.diff(fpga["t_s"][sel])))
    dec = max(1, int(round(1.0 / (proc.stream_hz * period))))
    q = np.column_stack([fpga[c][sel][::dec] for c in ("cx", "sx", "cy", "sy")])
    return fpga["t_s"][sel][::dec], q, win


def figures(proc: Any, data: Any) -> list[ReportFigure]:
    """Every figure an hrg-free-decay run's results need, in the report's order."""
    from bench.analysis.slow_model import orbit_elements
    out: list[ReportFigure] = []
    if proc.window_stream in data and "fpga" in data:
        t, q, win = _record(proc, data)
        if len(t) >= 8:
            params, source = _params(proc, data, t, q)
            lam = 2.0 * math.pi * (float(win[2]) - proc.natural_freq_hz)
            model = trajectory(t, q[0], params, lam)
            out += [_slow_figure(data, t, q, model, source, proc.model),
                    _elements_figure(data, t, q, model, orbit_elements)]
    return out + table_figure(data)


def _slow_figure(data: Any, t: np.ndarray, q: np.ndarray, model: np.ndarray, source: str, name: str) -> ReportFigure:
    fig, ax = new_figure(4, 2, height_in=5.4, sharex=True, gridspec_kw={"width_ratios": [1.6, 1]})
    for i, n in enumerate(_NAMES):
        plot_record(ax[i, 0], t, q[:, i], color="C0", label="measured")
        ax[i, 0].plot(t, model[:, i], "--", color="C3", label="identified model")
        ax[i, 0].set_ylabel(axis_label(data, "fpga", n, short=True))
        plot_record(ax[i, 1], t, q[:, i] - model[:, i], color="C0")
        ax[i, 1].axhline(0.0, color="C3", linewidth=0.8)
        ax[i, 1].set_ylabel(f"residual {n}\n({unit_text(declared(data, 'fpga', n)[1])})")
    ax[0, 0].legend(loc="upper right", ncols=2)
    ax[0, 0].set_title("measured and model")
    ax[0, 1].set_title("measured − model")
    for j in (0, 1):
        ax[-1, j].set_xlabel(axis_label(data, "fpga", "t_s"))
    return ReportFigure("hrg-free-decay_slow", "Slow variables with the identified model's trajectory", fig,
                        f"The {name} slow-variable model integrated forward from the first sample of the record with "
                        f"the identified parameters ({source}); residuals on the right.")


def _elements_figure(data: Any, t: np.ndarray, q: np.ndarray, model: np.ndarray, orbit_elements: Any) -> ReportFigure:
    em, en = orbit_elements(q), orbit_elements(model)
    fig, ax = new_figure(2, 2, height_in=3.8, sharex=True, gridspec_kw={"width_ratios": [1.6, 1]})
    ok = (em["E"] > 0) & (en["E"] > 0)
    ln_m, ln_n = np.log(em["E"][ok]), np.log(en["E"][ok])
    th_m = np.degrees(np.unwrap(4 * em["theta_rad"]) / 4)
    th_n = np.degrees(np.unwrap(4 * en["theta_rad"]) / 4)
    th_n += 90.0 * np.round((th_m[0] - th_n[0]) / 90.0)
    e_unit, th_unit = declared(data, _ELEMENTS, "energy")[1], declared(data, _ELEMENTS, "theta_deg")[1]
    labels = ((log_label("E", e_unit), f"residual ln E\n({unit_text(e_unit and '1')})"),
              (axis_label(data, _ELEMENTS, "theta_deg"), f"residual θ\n({unit_text(th_unit)})"))
    for i, (ym, yn, (name, res_name)) in enumerate(((ln_m, ln_n, labels[0]), (th_m, th_n, labels[1]))):
        tt = t[ok] if i == 0 else t
        plot_record(ax[i, 0], tt, ym, color="C0", label="measured")
        ax[i, 0].plot(tt, yn, "--", color="C3", label="identified model")
        ax[i, 0].set_ylabel(name)
        plot_record(ax[i, 1], tt, ym - yn, color="C0")
        ax[i, 1].axhline(0.0, color="C3", linewidth=0.8)
        ax[i, 1].set_ylabel(res_name)
    ax[0, 0].legend(loc="best")
    for j in (0, 1):
        ax[-1, j].set_xlabel(axis_label(data, "fpga", "t_s"))
    return ReportFigure("hrg-free-decay_elements", "Energy and wave angle with the identified model", fig,
                        "Orbit elements of the measured and modelled slow variables.")
