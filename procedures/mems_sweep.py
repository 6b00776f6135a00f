"""mems-sweep: forced-oscillation identification of a MEMS ring (Maslov et al. sections 3-4).

Drive both channels through the front end, sweep the drive (= lock-in reference) frequency up
across the resonance and back down (a nonlinear resonator shows its hysteresis there), and at each
point wait for the steady state, then average the lock-in's slow variables over a window.  The
wait comes from the time constant: settle_tau x tau_s for the resonator plus 5 lock-in time
constants; the point is accepted when the two halves of the averaging window agree (no trend
left), else it waits two more time constants (up to three times, then logs a warning).
Identify the linear, cubic and quintic models, choose the simplest one that the next richer one
does not beat by more than `improvement` in residual sigma, and report sigma of each, the chosen
model's parameters with intervals and the derived quantities; plots: amplitude and phase
against frequency (measured points, modelled curves) and the polar amplitude-phase plot of each
channel (the paper's figures 2-3).

Units: the lock-in reads pickoff_gain_v volts per model unit, so dividing by it gives the slow
variables in model units and xi in the simulator's units (the paper normalised to the largest
amplitude instead; that rescales xi and u only).
"""

from __future__ import annotations

import math

import numpy as np

from bench.analysis.axes import AXIS_PERIOD_DEG, axis_with_interval
from bench.analysis.maslov import (
    PAPER_NATURAL_FREQ_HZ,
    choose_model,
    derived_ci95,
    forced_param_names,
    identify_forced,
)
from bench.engine import Demand, Measurement, Param, Procedure, Result, step
from bench.streams import Column, StreamSchema, declare

SWEEP = declare(StreamSchema("sweep", "mems-sweep", (
    Column("t_s", "s", quantity="time t"), Column("freq_hz", "Hz", quantity="drive frequency f"),
    Column("direction", "1", "i1", legend={1: "up", -1: "down"}),
    # slow variables, model units
    Column("q1", "1", quantity="in-phase q1"), Column("p1", "1", quantity="quadrature p1"),
    Column("q2", "1", quantity="in-phase q2"), Column("p2", "1", quantity="quadrature p2"),
    Column("amplitude", "1", quantity="amplitude A"), Column("phase_deg", "deg", quantity="phase φ"),
    Column("amplitude_y", "1", quantity="amplitude B"), Column("phase_y_deg", "deg", quantity="phase ψ"),
    Column("settled", "1", "u1", legend={0: "not settled", 1: "settled"}))))
SWEEP_COLUMNS = SWEEP.names
#: a steady state of both pickoffs (lock-in X1, Y1, X2, Y2 over the pickoff gain; the model's
#: q1, p1, q2, p2): the sweep's columns of that name, the lock-in reads and a model's response
STATE = StreamSchema("mems_sweep_state", "frontend",
                     tuple(SWEEP.columns[SWEEP.index(c)] for c in ("q1", "p1", "q2", "p2")))
MODEL_ORDER = {"linear": 1, "cubic": 3, "quintic": 5}
#: a point that overloads is taken again this many times while the front end steps a range up
MAX_RETAKES = 4
#: the derived quantities of the chosen model: unit, what it is
DERIVED = {
    "Q": ("", "quality factor w0 / gamma"),
    "split_hz": ("Hz", "frequency split"),
    "damping_anisotropy_per_s": ("1/s", "damping anisotropy"),
    "alpha_deg": ("deg", "stiffness axis (Maslov's alpha), in [0, 90)"),
    "beta_deg": ("deg", "damping axis (Maslov's beta), in [0, 90)"),
    "freq_offset_hz": ("Hz", "mean frequency minus the model's characteristic frequency"),
    "zero_rate_dps": ("deg/s", "zero-rate output nu_offset / 4K"),
}
_AXES = ("alpha_deg", "beta_deg")
#: the chosen model's parameters that the simulated station knows (nu and the drives u1..u4 it does not)
_PARAM_TRUTH = ("gamma", "b_c", "b_s", "c_m", "n", "h_c", "h_s", "xi", "kappa")


def _chosen_in(orders: tuple[str, ...]):
    """The condition that the chosen model is one of `orders`."""
    def when(proc) -> bool:
        return proc.chosen_model in orders
    return when


def _declarations() -> tuple[Measurement, ...]:
    """sigma of each model, the chosen model, its parameters (xi from cubic up, kappa quintic only),
    the derived quantities and the hysteresis."""
    out = [Measurement(f"sigma_{m}", "", f"residual sigma of the {m} model (model units)") for m in MODEL_ORDER]
    out.append(Measurement("chosen_model_order", "", "order of the model chosen: 1 linear, 3 cubic, 5 quintic"))
    for name in forced_param_names("quintic"):
        orders = tuple(m for m in MODEL_ORDER if name in forced_param_names(m))
        conditional = "linear" not in orders
        out.append(Measurement(name, "1/s", f"chosen model's coefficient {name}",
                               truth=name if name in _PARAM_TRUTH else None,
                               when=_chosen_in(orders) if conditional else None,
                               when_doc="chosen model in (" + ", ".join(orders) + ")" if conditional else ""))
    for name, (unit, doc) in DERIVED.items():
        out.append(Measurement(name, unit, doc, truth=name, period=AXIS_PERIOD_DEG if name in _AXES else None))
    out.append(Measurement("hysteresis_max_amplitude", "", "largest amplitude difference between the up and down "
                           "sweeps at one frequency (model units)", when=lambda proc: proc.both_directions,
                           when_doc="both_directions"))
    return tuple(out)


def sweep_analysis(
    freq_hz: np.ndarray,
    q: np.ndarray,
    direction: np.ndarray,
    *,
    natural_freq_hz: float,
    bryan_factor: float,
    improvement: float,
) -> tuple[list[Result], dict[str, dict[str, np.ndarray]], dict]:
    """Identify the three models on the steady states; (results, plot curves, fits by model)."""
    fits = {
        m: identify_forced(freq_hz, *q.T, natural_freq_hz=natural_freq_hz, model=m, bryan_factor=bryan_factor)
        for m in MODEL_ORDER
    }
    sigmas = {m: f.sigma for m, f in fits.items()}
    chosen = choose_model(sigmas, improvement)
    best = fits[chosen]
    results = [Result(f"sigma_{m}", s) for m, s in sigmas.items()]
    results.append(Result("chosen_model_order", float(MODEL_ORDER[chosen])))
    for name, value in best.params.items():
        results.append(Result(name, value, ci95=best.ci95[name]))
    dci = derived_ci95(best, natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor)
    rad_ci = {"alpha_deg": "alpha_rad", "beta_deg": "beta_rad"}
    for name in DERIVED:
        value, lo_hi = best.derived[name], dci[rad_ci[name]] if name in rad_ci else dci[name]
        if name in rad_ci:  # the axes in [0, 90), as every procedure reports them
            value, lo_hi = axis_with_interval(value, (math.degrees(lo_hi[0]), math.degrees(lo_hi[1])))
        results.append(Result(name, value, ci95=lo_hi))
    # hysteresis: largest amplitude difference between the up and down sweeps at one frequency
    amp = np.hypot(STATE.column(q, "q1"), STATE.column(q, "p1"))
    up, down = direction > 0, direction < 0
    if up.any() and down.any():
        common = np.intersect1d(np.round(freq_hz[up], 9), np.round(freq_hz[down], 9))
        gaps = [abs(amp[up][np.round(freq_hz[up], 9) == f].mean() - amp[down][np.round(freq_hz[down], 9) == f].mean())
                for f in common]
        results.append(Result("hysteresis_max_amplitude", float(max(gaps)) if gaps else 0.0))

    lo, hi = float(freq_hz.min()), float(freq_hz.max())
    grid = np.linspace(lo, hi, 241)
    curves: dict[str, dict[str, np.ndarray]] = {}
    for m in ("linear", chosen):
        r = fits[m].response(grid)
        curves[f"sweep_model_{m}"] = {
            "freq_hz": grid,
            "amplitude": r.amp_x,
            "phase_deg": np.degrees(r.phase_x_rad),
            "amplitude_y": r.amp_y,
            "phase_y_deg": np.degrees(r.phase_y_rad),
        }
        curves[f"polar_ch1_model_{m}"] = {c: STATE.column(r.q, c) for c in ("q1", "p1")}
        curves[f"polar_ch2_model_{m}"] = {c: STATE.column(r.q, c) for c in ("q2", "p2")}
    curves["sweep_model"] = curves[f"sweep_model_{chosen}"]  # the one the live plot overlays
    order = np.argsort(freq_hz[up] if up.any() else freq_hz)
    sel = q[up][order] if up.any() else q[order]
    curves["polar_ch1_measured"] = {c: STATE.column(sel, c) for c in ("q1", "p1")}
    curves["polar_ch2_measured"] = {c: STATE.column(sel, c) for c in ("q2", "p2")}
    return results, curves, {"fits": fits, "chosen": chosen}


class MemsSweep(Procedure):
    """Forced sweep of a MEMS ring up and down the resonance; linear, cubic, quintic identification."""

    name = "mems-sweep"
    requires = ("frontend",)
    kinds = ("mems-ring",)
    start_hz = Param(PAPER_NATURAL_FREQ_HZ + 1.94 - 12.0, unit="Hz", low=1.0, high=200_000.0, doc="sweep start")
    stop_hz = Param(PAPER_NATURAL_FREQ_HZ + 1.94 + 12.0, unit="Hz", low=1.0, high=200_000.0, doc="sweep end")
    n_points = Param(61, low=5, high=2001, doc="frequencies per direction")
    both_directions = Param(True, doc="sweep back down as well (exposes hysteresis)")
    natural_freq_hz = Param(0.0, unit="Hz", low=0.0, high=200_000.0,
                            doc="characteristic frequency w/2pi of the model (lam = 2 pi (f - this)); "
                                "0: the station's nominal f0")
    drive1_v = Param(0.888, unit="V", low=0.0, high=10.0, doc="channel 1 drive amplitude")
    drive1_phase_deg = Param(46.43, unit="deg", low=-360.0, high=360.0, doc="channel 1 drive phase")
    drive2_v = Param(0.0308, unit="V", low=0.0, high=10.0, doc="channel 2 drive amplitude")
    drive2_phase_deg = Param(113.15, unit="deg", low=-360.0, high=360.0, doc="channel 2 drive phase")
    tau_s = Param(0.05, unit="s", low=1e-4, high=1000.0, doc="assumed amplitude time constant 2/gamma")
    settle_tau = Param(8.0, low=1.0, high=100.0, doc="wait at each point, in time constants")
    lockin_tc_s = Param(0.005, unit="s", low=0.0, high=10.0, doc="lock-in time constant")
    window_s = Param(0.05, unit="s", low=1e-3, high=100.0, doc="averaging window at each point")
    reads = Param(10, low=2, high=1000, doc="lock-in readings per window")
    pickoff_gain_v = Param(1.0, unit="V", low=1e-9, high=1e6, doc="lock-in volts per model unit")
    bryan_factor = Param(0.0, low=0.0, high=1.0, doc="K, for the zero-rate output (0: the station's nominal K)")
    nominal_params = {"natural_freq_hz": "f0_hz", "bryan_factor": "bryan_factor"}
    improvement = Param(0.05, low=0.0, high=0.9, doc="sigma reduction that justifies the richer model")

    measurements = _declarations()

    def __init__(self, params=None) -> None:
        super().__init__(params)
        if self.stop_hz <= self.start_hz:
            from bench.engine.params import ParamError
            from bench.validation import not_above

            message = not_above("stop_hz", self.stop_hz, self.start_hz, "Hz") + " (start_hz)"
            raise ParamError("stop_hz", self.stop_hz, f"above start_hz = {self.start_hz}", message)
        self.rows: list[np.ndarray] = []
        self.chosen_model = "linear"  # set by the identification; the declared parameters follow it

    def demands(self) -> list[Demand]:
        """Both drive amplitudes, against the front end's `max_amplitude_v`."""
        return [
            Demand("frontend", "max_amplitude_v", "drive1_v", self.drive1_v, "V"),
            Demand("frontend", "max_amplitude_v", "drive2_v", self.drive2_v, "V"),
        ]

    # --- steps ---------------------------------------------------------------------------------
    @step("Set up the drive", uses=("frontend",))
    def set_up(self, ctx):
        fe = ctx.devices.frontend
        fe.lockin_tc_s = self.lockin_tc_s
        fe.set_drive(1, amplitude_v=self.drive1_v, frequency_hz=self.start_hz, phase_deg=self.drive1_phase_deg)
        fe.set_drive(2, amplitude_v=self.drive2_v, frequency_hz=self.start_hz, phase_deg=self.drive2_phase_deg)
        fe.set_drive(1, output_on=True)
        fe.set_drive(2, output_on=True)
        ctx.log.info("drive on at %.4f Hz; settling %.3f s per point", self.start_hz, self.settle_time_s())
        ctx.sleep(3.0 * self.settle_time_s())

    @step("Sweep up", uses=("frontend",))
    def sweep_up(self, ctx):
        self._sweep(ctx, self.frequencies(), +1.0)

    @step("Sweep down", uses=("frontend",))
    def sweep_down(self, ctx):
        if self.both_directions:
            self._sweep(ctx, self.frequencies()[::-1], -1.0)

    @step("Drive off", uses=("frontend",))
    def drive_off(self, ctx):
        fe = ctx.devices.frontend
        fe.set_drive(1, output_on=False)
        fe.set_drive(2, output_on=False)

    @step("Identify", uses=())
    def identify(self, ctx):
        rows = np.array(self.rows)
        results, curves, _ = self._analyse(rows, compute=ctx.compute)  # abortable at once
        for res in results:
            ctx.report(res)
        for name, c in curves.items():
            ctx.fit(name, **c)

    # --- helpers -------------------------------------------------------------------------------
    def frequencies(self) -> np.ndarray:
        return np.linspace(self.start_hz, self.stop_hz, self.n_points)

    def settle_time_s(self) -> float:
        """The steady-state wait: settle_tau resonator time constants plus 5 lock-in ones."""
        return self.settle_tau * self.tau_s + 5.0 * self.lockin_tc_s

    def _window(self, ctx) -> np.ndarray:
        fe = ctx.devices.frontend
        dt = self.window_s / self.reads
        out = []
        t0 = ctx.clock.now()
        for k in range(1, self.reads + 1):  # absolute deadlines: a slow read does not stretch the window
            ctx.sleep_until(t0 + k * dt)
            out.append(fe.lockin_all())
        return np.array(out) / self.pickoff_gain_v

    def _sweep(self, ctx, freqs: np.ndarray, direction: float) -> None:
        fe = ctx.devices.frontend
        overload = getattr(fe, "lockin_overload", None)  # front ends that report overloads
        for j, f_asked in enumerate(freqs):
            # the frequency in use as the front end reads it back (the SR865 keeps 6 digits)
            used = fe.set_frequency_hz(float(f_asked))
            f = float(used) if used is not None else float(f_asked)
            ctx.sleep(self.settle_time_s())
            for _take in range(1 + MAX_RETAKES):
                if overload is not None:
                    overload(act=False)  # forget what the settling latched: only the window counts
                win, settled, drift = self._settled_window(ctx)
                over = overload() if overload is not None else None
                if not (over and over.changed):
                    break
                ctx.log.warning("%.4f Hz: overload (%s): taking the point again", f, over)
                ctx.sleep(self.settle_time_s())
            if over:
                ctx.log.warning("%.4f Hz: taken in overload (%s): refused, not fitted", f, over)
                ctx.progress((j + 1) / len(freqs), f"{'up' if direction > 0 else 'down'} {f:.3f} Hz  overload")
                continue
            if not settled:
                ctx.log.warning("%.4f Hz: not settled after 3 extra waits (drift %s)", f, np.array2string(drift))
            q1, p1, q2, p2 = (float(v) for v in STATE.columns_of(win.mean(axis=0), "q1", "p1", "q2", "p2"))
            amp_x = math.hypot(q1, p1)
            row = SWEEP.row(t_s=ctx.clock.now(), freq_hz=f, direction=direction, q1=q1, p1=p1, q2=q2, p2=p2,
                            amplitude=amp_x, phase_deg=math.degrees(math.atan2(p1, q1)),
                            amplitude_y=math.hypot(q2, p2), phase_y_deg=math.degrees(math.atan2(p2, q2)),
                            settled=float(settled))
            self.rows.append(row)
            ctx.record("sweep", SWEEP_COLUMNS, np.array(row))
            ctx.progress((j + 1) / len(freqs), f"{'up' if direction > 0 else 'down'} {f:.3f} Hz  A={amp_x:.4f}")

    def _settled_window(self, ctx) -> tuple[np.ndarray, bool, np.ndarray]:
        """One averaging window, taken again (after 2 tau) while its halves disagree, up to 3 times."""
        settled = False
        for _attempt in range(4):
            win = self._window(ctx)
            half = len(win) // 2
            drift = np.abs(win[half:].mean(axis=0) - win[:half].mean(axis=0))
            scatter = win.std(axis=0, ddof=1) / math.sqrt(max(half, 1))
            tol = 5.0 * scatter + 2e-3 * np.max(np.abs(win.mean(axis=0)))
            if np.all(drift <= tol):
                settled = True
                break
            ctx.sleep(2.0 * self.tau_s)
        return win, settled, drift

    def _analyse(self, rows: np.ndarray, compute=None):
        """Identify the sweep rows; with `compute` (a run's `ctx.compute`) in a worker the engine can end."""
        run = compute or (lambda fn, *a, **kw: fn(*a, **kw))
        results, curves, info = run(
            sweep_analysis, SWEEP.column(rows, "freq_hz"), SWEEP.columns_of(rows, "q1", "p1", "q2", "p2"),
            SWEEP.column(rows, "direction"), natural_freq_hz=self.natural_freq_hz,
            bryan_factor=self.bryan_factor, improvement=self.improvement,
        )
        self.chosen_model = info["chosen"]  # the declared parameters follow it
        return results, curves, info

    def analysis(self, data) -> list[Result]:
        """Re-fit a recorded run from its `sweep` stream."""
        tab = data.table("sweep")
        rows = np.column_stack([tab[c] for c in SWEEP_COLUMNS])
        results, _, _ = self._analyse(rows)
        return results

    def figures(self, data) -> list:
        """The figures this run's results need (procedures.figures.mems_sweep): the report and
        `gyrobench analyze --figures` draw these."""
        from procedures.figures.mems_sweep import figures

        return figures(self, data)
