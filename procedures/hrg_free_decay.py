"""hrg-free-decay: the patent's decay recording identified with the slow-variable model of
Maslov et al. (section 2): frequency split and its axis, damping anisotropy and its axis, tau,
and the Bryan factor from the known table rate (nu = 4 K Omega).

Steps: excite and hold the amplitude (FPGA AGC, PLL, quadrature loop); spin the table; wait for
a stable rate; cut the drive and freeze the reference (PLL off, so the detuning stays constant
through the record); record the FPGA stream; identify with `identify_free_decay`: by default the
output-error (maximum-likelihood) fit, with the paper's equation-error fit (Simpson regressors,
least squares, sandwich intervals) reported beside it under names ending `_ee`; the output-error fit
also fits the wave's turn by the table's angle ripple (once and twice per revolution).  The record
window goes to the `decay_window` stream, so `analysis(data)` re-fits a recorded run with the same code.
"""

from __future__ import annotations

import math

import numpy as np

from bench.analysis.axes import AXIS_PERIOD_DEG, axis_with_interval
from bench.analysis.maslov import derived_ci95, free_param_names, identify_free_decay
from bench.analysis.slow_model import orbit_elements
from bench.engine import Measurement, Param, Procedure, Result, recorded_text, step
from bench.streams import Column, StreamSchema, declare
from drivers.fpga.stream import STREAM_SCHEMA as FPGA

from .hrg_excitation import HrgExcitation

#: the FPGA stream's columns the decay is identified from (read by name, as the stream declares them)
FPGA_TAP = StreamSchema("hrg_free_decay_rows", "fpga",
                        tuple(FPGA.columns[FPGA.index(c)] for c in ("t_s", "cx", "sx", "cy", "sy")))

WINDOW = "decay_window"
WINDOW_COLUMNS = declare(StreamSchema(WINDOW, "hrg-free-decay", (
    Column("t_start_s", "s"), Column("t_end_s", "s"), Column("ref_freq_hz", "Hz"), Column("rate_dps", "deg/s")))).names
#: the orbit elements of the record, declared like a stream: the report's axes take their units here
declare(StreamSchema("hrg-free-decay elements", "hrg-free-decay", (
    Column("t_s", "s", quantity="time t"), Column("energy", "1", quantity="energy E"),
    Column("theta_deg", "deg", quantity="wave angle θ"))))


METHODS = ("output-error", "equation-error")
#: suffix of the paper's (equation-error) measurements reported beside the output-error ones
EE_SUFFIX = "_ee"


def decay_results(
    t_s: np.ndarray, q: np.ndarray, *, rate_dps: float, ref_freq_hz: float, natural_freq_hz: float, model: str,
    method: str = "output-error", table_ripple: bool = True,
) -> tuple[list[Result], object]:
    """Identify the decay with `method`; measurements under the simulator's truth names where they
    exist.  With the output-error fit the paper's equation-error fit is reported beside it, each
    name with the suffix EE_SUFFIX.  table_ripple: the output-error fit also fits the wave's turn by
    the table's angle ripple once and twice per revolution (when the table turns half a revolution or more)."""
    if method not in METHODS:
        raise ValueError(f"method={method!r} is not one of {METHODS}")
    basis = ripple_basis(t_s - t_s[0], rate_dps) if table_ripple and method == "output-error" else None
    out, fit = _method_results(t_s, q, rate_dps=rate_dps, ref_freq_hz=ref_freq_hz,
                               natural_freq_hz=natural_freq_hz, model=model, method=method, rotation_basis=basis)
    if method == "output-error":
        ee, _ = _method_results(t_s, q, rate_dps=rate_dps, ref_freq_hz=ref_freq_hz,
                                natural_freq_hz=natural_freq_hz, model=model, method="equation-error")
        out += [Result(r.name + EE_SUFFIX, r.value, ci95=r.ci95) for r in ee]
    return out, fit


def boxcar(rows: np.ndarray, dec: int) -> np.ndarray:
    """Means of consecutive blocks of dec rows (time stamps become block mid-times): the noise per
    fitted sample falls by sqrt(dec), and for the linear model the block mean of the trajectory is
    again a trajectory (each eigenmode scaled by a constant), so only q0 changes, not the parameters."""
    n = rows.shape[0] // dec
    return rows[: n * dec].reshape(n, dec, rows.shape[1]).mean(axis=1)


#: the shortest table turn over a record (deg) from which the table's angle ripple is fitted: below
#: half a revolution its once- and twice-per-turn terms cannot be told from the wave's own drift
RIPPLE_MIN_TURN_DEG = 180.0


def ripple_basis(t_rel_s: np.ndarray, rate_dps: float) -> np.ndarray | None:
    """cos/sin of one and two table revolutions over the record (the table's angle ripple turns the
    measured wave at these harmonics), or None below RIPPLE_MIN_TURN_DEG of table turn.  Leaving it
    out from 180 to 720 deg of turn biased the damping anisotropy ~2.7 % high at 20 s and 20 deg/s
    (outside its interval in 20 of 20 seeds; benchmarks/truth_flags.py): it is fitted there."""
    if abs(rate_dps) * float(t_rel_s[-1] - t_rel_s[0]) < RIPPLE_MIN_TURN_DEG:
        return None
    w = np.radians(rate_dps) * np.asarray(t_rel_s, dtype=float)
    return np.stack([np.cos(w), np.sin(w), np.cos(2.0 * w), np.sin(2.0 * w)], axis=1)


def _method_results(t_s: np.ndarray, q: np.ndarray, *, rate_dps: float, ref_freq_hz: float, natural_freq_hz: float,
                    model: str, method: str, rotation_basis: np.ndarray | None = None) -> tuple[list[Result], object]:
    extra = {} if method == "equation-error" else {"rotation_basis": rotation_basis}
    fit = identify_free_decay(
        t_s - t_s[0], *q.T, model=model, natural_freq_hz=natural_freq_hz, detuning_hz=ref_freq_hz - natural_freq_hz,
        method=method, **extra,
    )
    d, p, ci = fit.derived, fit.params, fit.ci95
    out = [Result(f"maslov_{n}", v, ci95=ci[n]) for n, v in p.items()]
    gamma_lo, gamma_hi = ci["gamma"]
    out.append(Result("tau_s", 2.0 / p["gamma"], ci95=(2.0 / gamma_hi, 2.0 / gamma_lo)))
    out.append(Result("q_factor", d["Q"], ci95=(2 * math.pi * natural_freq_hz / gamma_hi,
                                                    2 * math.pi * natural_freq_hz / gamma_lo)))
    dci = derived_ci95(fit, natural_freq_hz=natural_freq_hz)
    for name in ("split_hz", "delta_inv_tau_per_s", "damping_anisotropy_per_s", "freq_offset_hz"):
        out.append(Result(name, d[name], ci95=dci[name]))
    for name, key in (("theta_w_deg", "alpha_rad"), ("theta_tau_deg", "beta_rad")):
        value, axis_ci = axis_with_interval(math.degrees(d[key]), tuple(math.degrees(v) for v in dci[key]))
        out.append(Result(name, value, ci95=axis_ci))
    if rate_dps:
        omega = math.radians(rate_dps)
        nu_lo, nu_hi = sorted(ci["nu"])
        k_ci = tuple(sorted((nu_lo / (4 * omega), nu_hi / (4 * omega))))
        out.append(Result("bryan_factor", p["nu"] / (4.0 * omega), ci95=k_ci))
    out.append(Result("residual_sigma", fit.sigma))
    return out, fit


_ALL_PARAMS = free_param_names("quintic")
#: the model parameter's truth key on the simulated station (nu depends on the table rate: none)
_PARAM_TRUTH = {n: n for n in _ALL_PARAMS if n != "nu"}


def _fitted(param: str):
    """The condition that the parameter belongs to the model the procedure fits."""
    if param in free_param_names("linear"):
        return None, ""
    orders = [m for m in ("cubic", "quintic") if param in free_param_names(m)]
    return (lambda proc: proc.model in orders), "model in (" + ", ".join(orders) + ")"


def _with_output_error(when):
    """The condition of an equation-error twin: the output-error method (and the base's condition)."""
    def both(proc) -> bool:
        return proc.method == "output-error" and (when is None or bool(when(proc)))
    return both


def _decay_declarations() -> tuple[Measurement, ...]:
    """The identification's measurements, and their equation-error twins (suffix EE_SUFFIX) with the
    output-error method."""
    base = []
    for n in _ALL_PARAMS:
        when, when_doc = _fitted(n)
        base.append(Measurement(f"maslov_{n}", "1/s", f"slow-variable model coefficient {n}",
                                truth=_PARAM_TRUTH.get(n), when=when, when_doc=when_doc))
    rate_on, rate_doc = (lambda proc: proc.rate_dps != 0), "rate_dps != 0"
    base += [
        Measurement("tau_s", "s", "amplitude decay time 2 / gamma", truth="tau_s"),
        Measurement("q_factor", "", "quality factor w0 / gamma", truth="q_factor"),
        Measurement("split_hz", "Hz", "frequency split", truth="split_hz"),
        Measurement("delta_inv_tau_per_s", "1/s", "damping anisotropy Delta(1/tau)", truth="delta_inv_tau_per_s"),
        Measurement("damping_anisotropy_per_s", "1/s", "damping anisotropy 2 Delta(1/tau)",
                    truth="damping_anisotropy_per_s"),
        Measurement("freq_offset_hz", "Hz", "mean frequency minus the nominal natural frequency",
                    truth="freq_offset_hz"),
        Measurement("theta_w_deg", "deg", "stiffness (frequency) axis in [0, 90)", truth="theta_w_deg",
                    period=AXIS_PERIOD_DEG),
        Measurement("theta_tau_deg", "deg", "damping axis in [0, 90)", truth="theta_tau_deg", period=AXIS_PERIOD_DEG),
        Measurement("bryan_factor", "", "Bryan factor K = nu / (4 Omega) from the table rate", truth="bryan_factor",
                    when=rate_on, when_doc=rate_doc),
        Measurement("residual_sigma", "", "rms residual of the fit (model units)",
                    no_interval="a statistic of this record, not an estimate of a parameter: no interval"),
    ]
    out = list(base)
    for m in base:
        both = _with_output_error(m.when)
        words = "method = output-error" + (f" and {m.when_doc}" if m.when_doc else "")
        out.append(Measurement(m.name + EE_SUFFIX, m.unit, m.doc + " (the paper's equation-error fit)",
                               truth=m.truth, when=both, when_doc=words))
    return tuple(out)


class HrgFreeDecay(HrgExcitation, Procedure):
    """HRG free decay on a rate table, identified with Maslov's slow-variable model."""

    name = "hrg-free-decay"
    #: the identified record's window stream and its columns (its figures read them here)
    window_stream = WINDOW
    window_columns = WINDOW_COLUMNS
    requires = ("table", "fpga")
    kinds = ("hrg",)

    rate_dps = Param(50.0, unit="deg/s", low=-1000.0, high=1000.0, doc="table rate during the decay")
    accel_dps2 = Param(100.0, unit="deg/s^2", low=0.1, high=10000.0, doc="table acceleration")
    record_s = Param(300.0, unit="s", low=1.0, high=100000.0, doc="record duration")
    stream_hz = Param(100.0, unit="Hz", low=0.1, high=1e6, doc="rate of the samples fitted (boxcar-decimated stream)")
    natural_freq_hz = Param(0.0, unit="Hz", low=0.0, high=1e6,
                            doc="nominal natural frequency w/2pi (0: the station's nominal f0)")
    nominal_params = {"natural_freq_hz": "f0_hz"}
    model = Param("linear", choices=("linear", "cubic", "quintic"), doc="slow-variable model")
    method = Param("output-error", choices=METHODS,
                   doc="output-error: maximum likelihood (the Cramer-Rao bound), the paper's fit reported beside "
                       "it with names ending _ee; equation-error: the paper's Simpson least squares only")
    table_ripple = Param(True, doc="output-error: also fit the wave's turn by the table's angle ripple (1x, 2x/rev)")

    measurements = _decay_declarations()
    pause_in_record = "restart"  # the identification takes one continuous decay

    @step("Excite and hold the amplitude", uses=("fpga",))
    def excite(self, ctx):
        ctx.subscribe(ctx.devices.fpga, self._keep_latest)
        self._start_loops(ctx)
        self._hold_amplitude(ctx)

    @step("Spin the table", uses=("table",))
    def spin(self, ctx):
        self._start_spin(ctx)
        self._wait_stable(ctx)

    @step("Cut the drive", uses=("fpga", "frontend"))
    def cut_drive(self, ctx):
        self._cut_drive(ctx)

    @step("Record the decay", uses=("fpga",))
    def record(self, ctx):
        fpga = ctx.devices.fpga
        fpga.sync()
        span = ctx.record_for(self.record_s, "free decay")  # a pause inside restarts it (pause_in_record)
        fpga.sync()
        self._refuse_saturation(span.t_start_s, span.t_end_s, "free decay")
        ref = float(fpga.read_register("PLL_FREQ_HZ"))
        ctx.record(WINDOW, WINDOW_COLUMNS, np.array([[span.t_start_s, span.t_end_s, ref, self.rate_dps]]))
        t = ctx.data().table("fpga")["t_s"]
        ctx.log.info(recorded_text("free decay", t[(t >= span.t_start_s) & (t <= span.t_end_s)], span))

    @step("Identify", uses=())
    def identify(self, ctx):
        results, fit, t, q = self._analyse(ctx.data(), compute=ctx.compute)  # abortable at once
        turn_deg = abs(self.rate_dps) * float(t[-1] - t[0])
        if self.table_ripple and self.method == "output-error" and 0.0 < turn_deg < RIPPLE_MIN_TURN_DEG:
            ctx.log.warning(f"the table turned {turn_deg:.0f} deg over the record, under the "
                            f"{RIPPLE_MIN_TURN_DEG:.0f} deg from which its angle ripple is fitted: the ripple "
                            "is not modelled and may bias the damping terms (a longer record or a higher rate fits it)")
        for res in results:
            ctx.report(res)
        el = orbit_elements(q)
        k = max(1, len(t) // 2000)
        ctx.fit("hrg-free-decay elements", t_s=t[::k], energy=el["E"][::k],
                theta_deg=np.degrees(np.unwrap(4 * el["theta_rad"]) / 4)[::k])
        ctx.log.info("identified %s: sigma %.3g, noise %.3g per channel", fit.model, fit.sigma, fit.noise_sigma)
        # what the Cramer-Rao bound of this record needs (crlb_std): its length, rate, start and noise
        self._bound_inputs = {"duration_s": float(t[-1] - t[0]), "stream_hz": float((len(t) - 1) / (t[-1] - t[0])),
                              "noise_sigma": float(fit.noise_sigma), "q0": np.asarray(q[0], dtype=float),
                              "nu": float(fit.params["nu"])}

    def crlb_std(self, truth: dict[str, float]) -> dict[str, float]:
        """The Cramer-Rao standard deviation of each model coefficient (maslov_*) for this run's record
        at the unit's true parameters (nu, which the table rate sets, and the noise as fitted): the
        bound a campaign divides the scatter by (docs/campaigns.md); {} before a run identified."""
        from bench.analysis.damping_design import crlb_free_decay

        b = getattr(self, "_bound_inputs", None)
        if b is None or self.method != "output-error":
            return {}
        names = free_param_names(self.model)
        params = {n: (b["nu"] if n == "nu" else float(truth[n])) for n in names}
        bound = crlb_free_decay(duration_s=b["duration_s"], stream_hz=b["stream_hz"], noise_sigma=b["noise_sigma"],
                                q0=b["q0"], params=params, model=self.model)
        return {f"maslov_{n}": float(bound.std[n]) for n in names}

    # --- helpers -------------------------------------------------------------------------------
    def _analyse(self, data, compute=None):
        """Identify the recorded window; `compute(fn, *args, **kw)` runs the identification
        (a run's `ctx.compute`, in a worker the engine can end), else it runs here."""
        win = {c: v[-1] for c, v in data.table(WINDOW).items()}
        fpga = data.table("fpga")
        sel = (fpga["t_s"] >= win["t_start_s"]) & (fpga["t_s"] <= win["t_end_s"])
        period = float(np.median(np.diff(fpga["t_s"][sel])))
        dec = max(1, int(round(1.0 / (self.stream_hz * period))))
        rows = boxcar(np.column_stack([fpga[c][sel] for c in FPGA_TAP.names]), dec)
        t_s, q = FPGA_TAP.column(rows, "t_s"), FPGA_TAP.columns_of(rows, "cx", "sx", "cy", "sy")
        run = compute or (lambda fn, *a, **kw: fn(*a, **kw))
        results, fit = run(decay_results, t_s, q, rate_dps=float(win["rate_dps"]),
                           ref_freq_hz=float(win["ref_freq_hz"]), natural_freq_hz=self.natural_freq_hz,
                           model=self.model, method=self.method, table_ripple=self.table_ripple)
        return results, fit, t_s, q

    def analysis(self, data) -> list[Result]:
        """Re-fit a recorded run from its `decay_window` and `fpga` streams."""
        return self._analyse(data)[0]

    def figures(self, data) -> list:
        """The figures this run's results need (procedures.figures.hrg_free_decay): the report and
        `gyrobench analyze --figures` draw these."""
        from procedures.figures.hrg_free_decay import figures

        return figures(self, data)
