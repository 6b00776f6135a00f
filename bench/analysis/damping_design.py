"""Cramer-Rao bounds and the experiment design of the HRG free-decay tests
(docs/free_decay_identification.md).

Two bounds for the damping vector (b_c, b_s) = D (cos 4 th_tau, sin 4 th_tau):
* energy-only: the information E(t) carries under var(E) = 4 s^2 E with the wave angle known
  (what the patent's fit of E uses, and what `fit_free_decay` attains);
* four-channel: all of cx, sx, cy, sy under white noise s with the full linear model (initial
  state and all eight coefficients unknown), by sensitivity equations stepped exactly with expm.
The design helper weighs the energy bound (it falls with the table rate, once the record covers
a few turns of 4 theta) against the model error that a frequency split and quadrature leave in the
patent's cos 4 theta model at low rates, and picks the rate and record length.
Pure maths: numpy, scipy and the averaged model; no simulator.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.linalg import expm

from .damping import MODELS, DampingFitError, decay_regressors, fit_free_decay
from .free_decay_oe import Q0_NAMES, linear_sensitivities, trajectory
from .maslov_terms import check_model, free_param_names
from .slow_model import linear_matrix, state_from_elements

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class DecayScenario:
    """A free decay on a rate table, in physical units (the design's input)."""

    tau_s: float
    delta_inv_tau_per_s: float
    noise_sigma: float
    rate_dps: float = 500.0
    duration_s: float = 900.0
    stream_hz: float = 1000.0
    theta_tau_deg: float = 0.0
    theta0_deg: float = 0.0
    amplitude: float = 1.0
    quadrature: float = 0.0
    split_hz: float = 0.0
    theta_w_deg: float = 0.0
    bryan_factor: float = 0.277

    def __post_init__(self) -> None:
        for name in ("tau_s", "noise_sigma", "duration_s", "stream_hz", "amplitude", "bryan_factor"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} must be finite and > 0")
        for name in ("delta_inv_tau_per_s", "split_hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name}={value!r} must be finite and >= 0")
        if self.delta_inv_tau_per_s >= 2.0 / self.tau_s:
            raise ValueError(f"delta_inv_tau_per_s={self.delta_inv_tau_per_s!r} must be < 2/tau_s")

    def zg(self) -> np.ndarray:
        """Linear model coefficients (gamma, nu, b_c, b_s, c_m, n, h_c, h_s)."""
        d, th = self.delta_inv_tau_per_s, math.radians(self.theta_tau_deg)
        dw, thw = TWO_PI * self.split_hz, math.radians(self.theta_w_deg)
        nu = 4.0 * self.bryan_factor * math.radians(self.rate_dps)
        return np.array(
            [2.0 / self.tau_s, nu, d * math.cos(4 * th), d * math.sin(4 * th), 0.0, 0.0,
             dw * math.cos(4 * thw), dw * math.sin(4 * thw)]
        )

    def initial_state(self) -> np.ndarray:
        return state_from_elements(self.amplitude, self.quadrature, math.radians(self.theta0_deg), 0.0)

    def grid_step(self) -> tuple[float, int]:
        """(dt, m): a grid of m stream samples per step, at least 20 steps per fastest turn."""
        spin = abs(4.0 * self.bryan_factor * math.radians(self.rate_dps))
        fast = spin + 4.0 * TWO_PI * self.split_hz + 4.0 / self.tau_s
        m = max(1, int(math.floor(self.stream_hz * TWO_PI / (20.0 * fast))))
        return m / self.stream_hz, m


def _propagate(a: np.ndarray, x0: np.ndarray, n: int, dt: float, block: int = 256) -> np.ndarray:
    """x(k dt), k = 1..n, for dx/dt = a x, by exact steps (powers of expm(a dt) in blocks)."""
    phi = expm(a * dt)
    b = min(block, n)
    powers = np.empty((b,) + phi.shape)
    powers[0] = phi
    for k in range(1, b):
        powers[k] = powers[k - 1] @ phi
    out = np.empty((n, x0.size))
    x = x0
    for start in range(0, n, b):
        take = min(b, n - start)
        out[start : start + take] = powers[:take] @ x
        x = out[start + take - 1]
    return out


def noise_free_decay(sc: DecayScenario) -> tuple[np.ndarray, np.ndarray, int]:
    """The true slow variables on the design grid: (t_s from 0, q (n, 4), stream samples per step)."""
    dt, m = sc.grid_step()
    n = int(sc.duration_s / dt)
    q0 = sc.initial_state()
    q = np.vstack([q0, _propagate(linear_matrix(sc.zg()), q0, n, dt)])
    return dt * np.arange(n + 1), q, m


@dataclass(frozen=True)
class DampingBound:
    """Standard deviations (1 sigma) at the Cramer-Rao bound, and the bound's covariance."""

    kind: str  # "energy" or "four-channel"
    std_theta_tau_deg: float
    std_delta_inv_tau_per_s: float
    std_tau_s: float
    std_b_per_s: float  # sqrt(var b_c + var b_s): the damping vector's scatter
    covariance: np.ndarray = field(repr=False)
    names: tuple[str, ...] = ()


def _std_from_cov(cov: np.ndarray, i_gamma: int, i_bc: int, zg: np.ndarray) -> tuple[float, float, float, float]:
    gamma, b_c, b_s = zg[0], zg[2], zg[3]
    d = math.hypot(b_c, b_s)
    cb = cov[np.ix_([i_bc, i_bc + 1], [i_bc, i_bc + 1])]
    if d > 0:
        g_d = np.array([b_c, b_s]) / d
        g_th = np.array([-b_s, b_c]) * 0.25 / d**2
        sd_d = math.sqrt(max(float(g_d @ cb @ g_d), 0.0))
        sd_th = math.degrees(math.sqrt(max(float(g_th @ cb @ g_th), 0.0)))
    else:
        sd_d = math.sqrt(max(0.5 * float(np.trace(cb)), 0.0))
        sd_th = math.inf
    sd_tau = 2.0 / gamma**2 * math.sqrt(max(float(cov[i_gamma, i_gamma]), 0.0))
    return sd_th, sd_d, sd_tau, math.sqrt(max(float(np.trace(cb)), 0.0))


def _cumulative_energy_info(t: np.ndarray, q: np.ndarray, noise_sigma: float, m: int, model: str) -> np.ndarray:
    """Cumulative Fisher information of (ln E0, gamma, b_c, b_s) from E, shape (n, 4, 4)."""
    reg = decay_regressors(t, q[:, 0], q[:, 1], q[:, 2], q[:, 3], model=model)
    x = reg.x
    w = reg.energy / (4.0 * noise_sigma**2) * m
    return np.cumsum(w[:, None, None] * x[:, :, None] * x[:, None, :], axis=0)


def energy_bound(sc: DecayScenario, *, model: str = "exact") -> DampingBound:
    """Cramer-Rao bound from the energy alone (the wave angle taken as measured, noise-free)."""
    if model not in MODELS:
        raise ValueError(f"model={model!r} is not one of {MODELS}")
    t, q, m = noise_free_decay(sc)
    info = _cumulative_energy_info(t, q, sc.noise_sigma, m, model)[-1]
    cov = np.linalg.inv(info)
    sd = _std_from_cov(cov, 1, 2, sc.zg())
    return DampingBound("energy", *sd, covariance=cov, names=("ln_e0", "gamma", "b_c", "b_s"))


FOUR_CHANNEL_NAMES = ("q1_0", "p1_0", "q2_0", "p2_0", "gamma", "nu", "b_c", "b_s", "c_m", "n", "h_c", "h_s")


def four_channel_bound(sc: DecayScenario, *, unknown: tuple[str, ...] = FOUR_CHANNEL_NAMES) -> DampingBound:
    """Cramer-Rao bound from all four slow variables under white noise (full linear model)."""
    bad = set(unknown) - set(FOUR_CHANNEL_NAMES)
    if bad or not {"gamma", "b_c", "b_s"} <= set(unknown):
        raise ValueError(f"unknown={unknown!r}: names from {FOUR_CHANNEL_NAMES}, gamma, b_c and b_s included")
    names = tuple(nm for nm in FOUR_CHANNEL_NAMES if nm in unknown)
    dt, m = sc.grid_step()
    n = int(sc.duration_s / dt)
    zg = sc.zg()
    info = _fisher_information(zg, sc.initial_state(), n + 1, dt, names, "linear") * (m / sc.noise_sigma**2)
    cov = np.linalg.inv(info)
    sd = _std_from_cov(cov, names.index("gamma"), names.index("b_c"), zg)
    return DampingBound("four-channel", *sd, covariance=cov, names=names)


def _fisher_information(z: np.ndarray, q0: np.ndarray, n: int, dt: float, names: tuple[str, ...],
                        model: str, cuts: tuple[int, ...] | None = None, ripple_rad_s: float = 0.0) -> np.ndarray:
    """sum over n samples (t = k dt) of S^T S, S = d q / d(names) (unit noise): exact sensitivities
    of the linear model (powers of expm of the augmented system), integrated ones otherwise.
    With cuts: the sums over the first c samples for each c in cuts, stacked.  ripple_rad_s != 0
    appends the four nuisance columns of an output rotation at one and two table turns (what
    hrg-free-decay fits, free_decay_oe.output_error_fit's rotation_basis), last."""
    all_names = Q0_NAMES + free_param_names(model)
    bad = set(names) - set(all_names)
    if bad:
        raise ValueError(f"unknown parameter(s) {sorted(bad)} for model={model!r}: names from {all_names}")
    if model == "linear":
        zidx = tuple(all_names.index(nm) - 4 for nm in names if nm not in Q0_NAMES)
        traj, phi, sens = linear_sensitivities(z, q0, n, dt, params=zidx)
        cols, zi = [], 0
        for nm in names:
            if nm in Q0_NAMES:
                cols.append(phi[:, :, Q0_NAMES.index(nm)])
            else:
                cols.append(sens[:, :, zi])
                zi += 1
        jac = np.stack(cols, axis=-1)
    else:
        traj, full = trajectory(dt * np.arange(n), q0, z, model)
        jac = full[:, :, [all_names.index(nm) for nm in names]]
    if ripple_rad_s:
        w = ripple_rad_s * dt * np.arange(n)
        basis = np.stack([np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)], axis=1)
        gq = traj[:, [2, 3, 0, 1]] * np.array([-1.0, -1.0, 1.0, 1.0])  # d/dpsi of the rotated output
        jac = np.concatenate([jac, gq[:, :, None] * basis[:, None, :]], axis=-1)
    if cuts is None:
        return np.einsum("nap,naq->pq", jac, jac)
    edges = (0,) + tuple(int(c) for c in cuts)
    parts = [np.einsum("nap,naq->pq", jac[a:b], jac[a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return np.cumsum(np.stack(parts), axis=0)


@dataclass(frozen=True)
class FreeDecayBound:
    """Cramer-Rao bound of a free-decay identification: 1-sigma std of every parameter (initial
    state q1_0..p2_0 and the model's coefficients) and of D, theta_tau and tau, with the covariance."""

    names: tuple[str, ...]
    std: Mapping[str, float]
    std_delta_inv_tau_per_s: float
    std_theta_tau_deg: float
    std_tau_s: float
    covariance: np.ndarray = field(repr=False)


def crlb_free_decay(*, duration_s: float, stream_hz: float, noise_sigma: float, q0: np.ndarray,
                    params: Mapping[str, float], model: str = "linear") -> FreeDecayBound:
    """Cramer-Rao bound of all parameters of a free decay (samples at t = k / stream_hz from 0 to
    duration_s, white noise noise_sigma on each slow variable, initial state q0, true params by
    the names of maslov_terms.free_param_names(model)); the output-error fit attains it."""
    check_model(model)
    for name, value in (("duration_s", duration_s), ("stream_hz", stream_hz), ("noise_sigma", noise_sigma)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name}={value!r} must be finite and > 0")
    z_names = free_param_names(model)
    missing = set(z_names) - set(params)
    if missing:
        raise ValueError(f"params lacks {sorted(missing)} of model={model!r}")
    z = np.array([float(params[nm]) for nm in z_names])
    q0 = np.asarray(q0, dtype=float)
    if q0.shape != (4,) or not np.all(np.isfinite(q0)) or not np.any(q0):
        raise ValueError(f"q0={q0!r} must be 4 finite slow variables, not all zero")
    n = int(round(duration_s * stream_hz)) + 1
    names = Q0_NAMES + z_names
    info = _fisher_information(z, q0, n, 1.0 / stream_hz, names, model) / noise_sigma**2
    cov = np.linalg.inv(info)
    sd_th, sd_d, sd_tau, _ = _std_from_cov(cov, 4, 6, z)
    std = {nm: math.sqrt(max(float(cov[i, i]), 0.0)) for i, nm in enumerate(names)}
    return FreeDecayBound(names, std, sd_d, sd_th, sd_tau, covariance=cov)


def model_bias(sc: DecayScenario, *, model: str = "patent") -> tuple[float, float, float]:
    """Bias of the weighted log-linear fit on noise-free data: (D error 1/s, theta_tau error deg,
    damping-vector error |b_hat - b| 1/s)."""
    t, q, _ = noise_free_decay(sc)
    fit = fit_free_decay(t, q[:, 0], q[:, 1], q[:, 2], q[:, 3], model=model)
    zg = sc.zg()
    err_b = math.hypot(fit.b_c_per_s - zg[2], fit.b_s_per_s - zg[3])
    dth = (fit.theta_tau_deg - sc.theta_tau_deg + 45.0) % 90.0 - 45.0
    return fit.delta_inv_tau_per_s - sc.delta_inv_tau_per_s, dth, err_b


# ----------------------------------------------------------------------------------------------
# Design


@dataclass(frozen=True)
class DesignPoint:
    """Predicted errors of one (rate, length) choice, relative to D (bias: worst over the split axis)."""

    rate_dps: float
    duration_s: float
    crlb_rel: float  # sqrt(var b_c + var b_s) / D at the energy bound
    bias_rel: float  # |b_hat - b| / D on noise-free data (model error)
    total_rel: float  # sqrt(crlb^2 + bias^2)
    std_delta_inv_tau_per_s: float
    std_theta_tau_deg: float


@dataclass(frozen=True)
class DampingDesign:
    """The experiment design: the grid, the recommendation and the patent's point for comparison."""

    scenario: DecayScenario
    model: str
    points: tuple[DesignPoint, ...]
    recommended: DesignPoint
    patent: DesignPoint
    four_channel_recommended: DampingBound
    lock_rate_dps: float

    @property
    def gain_vs_patent(self) -> float:
        """How many times smaller the total error is at the recommended point than at the patent's."""
        return self.patent.total_rel / self.recommended.total_rel

    def summary(self) -> str:
        sc = self.scenario
        lines = [
            "HRG damping experiment design (free decay on a rate table, docs/free_decay_identification.md)",
            f"  resonator: tau {sc.tau_s:g} s, Delta(1/tau) {sc.delta_inv_tau_per_s:.3g} 1/s, K {sc.bryan_factor:g}, "
            f"split {sc.split_hz:g} Hz, quadrature {sc.quadrature:g}, noise {sc.noise_sigma:g} at amplitude "
            f"{sc.amplitude:g}, stream {sc.stream_hz:g} Hz; fit model '{self.model}'",
            f"  the wave locks onto the damping axis below {self.lock_rate_dps:.3g} deg/s (K Omega < D/4)",
            "  rate_dps  length_s  CRLB std(b)/D  model bias/D  total/D   std D (1/s)  std th_tau (deg)",
        ]
        best_len = self.recommended.duration_s
        for p in self.points:
            if p.duration_s == best_len:
                lines.append(
                    f"  {p.rate_dps:8.3g}  {p.duration_s:8.0f}  {p.crlb_rel:13.3e}  {p.bias_rel:12.3e}  "
                    f"{p.total_rel:8.3e}  {p.std_delta_inv_tau_per_s:11.3e}  {p.std_theta_tau_deg:16.3e}"
                )
        r, pt = self.recommended, self.patent
        fc = self.four_channel_recommended
        lines += [
            f"  recommended: table rate {r.rate_dps:.3g} deg/s, record {r.duration_s:.0f} s: "
            f"total error {r.total_rel:.3%} of D (std {r.crlb_rel:.3%}, bias {r.bias_rel:.3%})",
            f"  patent ({pt.rate_dps:g} deg/s, same record): total error {pt.total_rel:.3%} of D -> recommended is "
            f"{self.gain_vs_patent:.1f}x better",
            f"  four-channel bound at the recommended point: std D {fc.std_delta_inv_tau_per_s:.3e} 1/s, "
            f"std th_tau {fc.std_theta_tau_deg:.3e} deg (energy bound: {r.std_delta_inv_tau_per_s:.3e}, "
            f"{r.std_theta_tau_deg:.3e})",
        ]
        return "\n".join(lines)


def _points_for_rate(sc: DecayScenario, lengths_s: tuple[float, ...], model: str) -> list[DesignPoint]:
    long = replace(sc, duration_s=max(lengths_s))
    t, q, m = noise_free_decay(long)
    info = _cumulative_energy_info(t, q, sc.noise_sigma, m, "exact")
    zg = sc.zg()
    d = sc.delta_inv_tau_per_s
    variants = [(t, q)]
    if sc.split_hz > 0:
        for off in (22.5, 45.0, 67.5):
            tv, qv, _ = noise_free_decay(replace(long, theta_w_deg=sc.theta_w_deg + off))
            variants.append((tv, qv))
    out = []
    for length in lengths_s:
        k = min(int(round(length / t[1])) , t.size - 1)
        cov = np.linalg.inv(info[k])
        sd_th, sd_d, _, sd_b = _std_from_cov(cov, 1, 2, zg)
        bias = 0.0
        for tq in variants:  # the split axis is unknown in advance: the worst of four
            try:
                fit = fit_free_decay(tq[0][: k + 1], *tq[1][: k + 1].T, model=model)
            except DampingFitError:  # the wave degenerates (a ~ k: no angle to follow): infeasible
                bias = math.inf
                break
            bias = max(bias, math.hypot(fit.b_c_per_s - zg[2], fit.b_s_per_s - zg[3]))
        crlb_rel, bias_rel = sd_b / d, bias / d
        out.append(DesignPoint(sc.rate_dps, float(length), crlb_rel, bias_rel, math.hypot(crlb_rel, bias_rel), sd_d,
                               sd_th))
    return out


def design_hrg_damping(
    *,
    tau_s: float,
    delta_inv_tau_per_s: float,
    noise_sigma: float,
    stream_hz: float = 1000.0,
    bryan_factor: float = 0.277,
    split_hz: float = 0.0,
    quadrature: float = 0.0,
    amplitude: float = 1.0,
    theta_tau_deg: float = 0.0,
    theta_w_deg: float = 0.0,
    model: str = "exact",
    rates_dps: tuple[float, ...] | None = None,
    lengths_tau: tuple[float, ...] = (1.0, 2.0, 3.0, 4.0),
    patent_rate_dps: float = 500.0,
    length_tolerance: float = 0.1,
) -> DampingDesign:
    """Table rate and record length minimising the predicted error of (b_c, b_s) for a fit model.

    For each rate and length: energy CRLB (std of the damping vector, relative to D) and the
    noise-free model bias of `model` ("exact": quadrature-aware, the procedure's default fit;
    "patent": cos 4 theta, biased by split x quadrature at low rates, so its optimum is faster).
    The recommendation is the rate with the least total error
    at the shortest length whose total error is within `length_tolerance` of the grid's best,
    above three times the highest rate where the wave degenerates (split with no quadrature loop)."""
    if model not in MODELS:
        raise ValueError(f"model={model!r} is not one of {MODELS}")
    if delta_inv_tau_per_s <= 0:
        raise ValueError(f"delta_inv_tau_per_s={delta_inv_tau_per_s!r} must be > 0 to design for it")
    if not lengths_tau or min(lengths_tau) <= 0:
        raise ValueError(f"lengths_tau={lengths_tau!r} must be positive multiples of tau")
    base = DecayScenario(
        tau_s=tau_s, delta_inv_tau_per_s=delta_inv_tau_per_s, noise_sigma=noise_sigma, stream_hz=stream_hz,
        bryan_factor=bryan_factor, split_hz=split_hz, quadrature=quadrature, amplitude=amplitude,
        theta_tau_deg=theta_tau_deg, theta_w_deg=theta_w_deg, duration_s=max(lengths_tau) * tau_s,
    )
    lock_dps = math.degrees(delta_inv_tau_per_s / 4.0 / bryan_factor)
    if rates_dps is None:
        lo = max(4.0 * lock_dps, 1e-3)
        rates_dps = tuple(float(r) for r in np.geomspace(lo, 1000.0, 28))
    if min(rates_dps) <= lock_dps:
        raise ValueError(
            f"rates_dps must stay above the locking rate {lock_dps:.3g} deg/s (min given {min(rates_dps)})"
        )
    lengths_s = tuple(float(f * tau_s) for f in sorted(lengths_tau))
    points: list[DesignPoint] = []
    for rate in sorted(set(rates_dps)):
        points += _points_for_rate(replace(base, rate_dps=rate), lengths_s, model)
    # a rate where the wave degenerates (infinite model error) bars every rate below three times it
    bad = [p.rate_dps for p in points if not math.isfinite(p.total_rel)]
    floor_dps = 3.0 * max(bad) if bad else 0.0
    ok = [p for p in points if p.rate_dps > floor_dps and math.isfinite(p.total_rel)]
    if not ok:
        raise ValueError("no feasible table rate in rates_dps: the wave degenerates at every one of them")
    best_total = min(p.total_rel for p in ok)
    length = min(p.duration_s for p in ok if p.total_rel <= (1.0 + length_tolerance) * best_total)
    rec = min((p for p in ok if p.duration_s == length), key=lambda p: p.total_rel)
    patent = _points_for_rate(replace(base, rate_dps=patent_rate_dps), (length,), model)[0]
    fc = four_channel_bound(replace(base, rate_dps=rec.rate_dps, duration_s=length))
    return DampingDesign(base, model, tuple(points), rec, patent, fc, lock_dps)


# ----------------------------------------------------------------------------------------------
# Design of hrg-free-decay (the output-error fit of the full linear model)


@dataclass(frozen=True)
class FreeDecayDesignPoint:
    """CRLB (1 sigma) of the quantities hrg-free-decay reports, at one (rate, length)."""

    rate_dps: float
    duration_s: float
    std_delta_inv_tau_per_s: float
    std_theta_tau_deg: float
    std_tau_s: float
    std_split_hz: float
    std_bryan_factor: float

    @property
    def rel_delta(self) -> float:
        return math.inf if not self.std_delta_inv_tau_per_s else self.std_delta_inv_tau_per_s


@dataclass(frozen=True)
class FreeDecayDesign:
    """Table rate and record length for hrg-free-decay and the precision they give at the bound."""

    scenario: DecayScenario
    points: tuple[FreeDecayDesignPoint, ...]
    recommended: FreeDecayDesignPoint
    lock_rate_dps: float

    def summary(self) -> str:
        sc, r = self.scenario, self.recommended
        d = sc.delta_inv_tau_per_s
        lines = [
            "hrg-free-decay experiment design (output-error fit of the slow-variable model, "
            "docs/free_decay_identification.md)",
            f"  resonator: tau {sc.tau_s:g} s, Delta(1/tau) {d:.3g} 1/s, K {sc.bryan_factor:g}, "
            f"split {sc.split_hz:g} Hz, quadrature {sc.quadrature:g}, noise {sc.noise_sigma:.3g} per fitted sample "
            f"at amplitude {sc.amplitude:g}, stream {sc.stream_hz:g} Hz",
            f"  the wave locks onto the damping axis below {self.lock_rate_dps:.3g} deg/s (K Omega < D/4)",
            "  rate_dps  length_s   std D/D      std th_tau (deg)  std tau (s)  std split (Hz)  std K",
        ]
        for p in self.points:
            if p.duration_s == r.duration_s:
                lines.append(f"  {p.rate_dps:8.3g}  {p.duration_s:8.0f}  {p.std_delta_inv_tau_per_s / d:10.3e}  "
                             f"{p.std_theta_tau_deg:16.3e}  {p.std_tau_s:11.3e}  {p.std_split_hz:14.3e}  "
                             f"{p.std_bryan_factor:9.3e}")
        lines += [
            f"  recommended: table rate {r.rate_dps:.3g} deg/s, record {r.duration_s:.0f} s, "
            f"stream {sc.stream_hz:g} Hz: std D {r.std_delta_inv_tau_per_s:.3e} 1/s "
            f"({r.std_delta_inv_tau_per_s / d:.3%} of D), "
            f"std th_tau {r.std_theta_tau_deg:.3e} deg, std tau {r.std_tau_s:.3e} s",
            f"  run it: gyrobench run hrg-free-decay --set rate_dps={r.rate_dps:.4g} --set record_s={r.duration_s:.0f} "
            f"--set stream_hz={sc.stream_hz:g}",
        ]
        return "\n".join(lines)


def _free_decay_points(sc: DecayScenario, lengths_s: tuple[float, ...]) -> list[FreeDecayDesignPoint]:
    """CRLB of the full linear model (q0, all eight coefficients and the table-ripple nuisance that
    hrg-free-decay fits) at each length, one trajectory."""
    long = replace(sc, duration_s=max(lengths_s))
    dt, m = long.grid_step()
    n = int(long.duration_s / dt) + 1
    cuts = tuple(min(n, int(round(length / dt)) + 1) for length in lengths_s)
    zg = sc.zg()
    infos = _fisher_information(zg, sc.initial_state(), n, dt, FOUR_CHANNEL_NAMES, "linear", cuts,
                                ripple_rad_s=math.radians(sc.rate_dps))
    infos = infos * (m / sc.noise_sigma**2)
    omega = math.radians(sc.rate_dps)
    out = []
    for length, info in zip(lengths_s, infos, strict=True):
        cov = np.linalg.inv(info)
        sd_th, sd_d, sd_tau, _ = _std_from_cov(cov, 4, 6, zg)
        split = math.hypot(zg[6], zg[7])
        if split > 0:
            g = np.array([zg[6], zg[7]]) / split
            sd_split = math.sqrt(max(float(g @ cov[10:12, 10:12] @ g), 0.0)) / TWO_PI
        else:
            sd_split = math.sqrt(max(0.5 * float(np.trace(cov[10:12, 10:12])), 0.0)) / TWO_PI
        sd_k = math.sqrt(max(float(cov[5, 5]), 0.0)) / (4.0 * abs(omega)) if omega else math.inf
        out.append(FreeDecayDesignPoint(sc.rate_dps, float(length), sd_d, sd_th, sd_tau, sd_split, sd_k))
    return out


def design_hrg_free_decay(
    *,
    tau_s: float,
    delta_inv_tau_per_s: float,
    noise_sigma: float,
    stream_hz: float = 100.0,
    bryan_factor: float = 0.277,
    split_hz: float = 0.0,
    quadrature: float = 0.0,
    amplitude: float = 1.0,
    theta_tau_deg: float = 0.0,
    theta_w_deg: float = 0.0,
    rates_dps: tuple[float, ...] | None = None,
    lengths_tau: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 3.0),
    length_tolerance: float = 0.1,
    min_turns: float = 2.0,
) -> FreeDecayDesign:
    """Table rate and record length for hrg-free-decay: the rate with the least CRLB of D at the
    shortest record whose CRLB is within `length_tolerance` of the grid's best (the output-error
    fit carries split, quadrature and rate, so there is no model bias to weigh); noise_sigma is
    per fitted (stream_hz) sample.  The table must turn min_turns times in the record: the
    procedure fits the table's angle ripple (once and twice per turn) only then, and the CRLB
    alone would pick the slowest rate (the damping drift is observable without a sweep)."""
    if delta_inv_tau_per_s <= 0:
        raise ValueError(f"delta_inv_tau_per_s={delta_inv_tau_per_s!r} must be > 0 to design for it")
    if not lengths_tau or min(lengths_tau) <= 0:
        raise ValueError(f"lengths_tau={lengths_tau!r} must be positive multiples of tau")
    base = DecayScenario(
        tau_s=tau_s, delta_inv_tau_per_s=delta_inv_tau_per_s, noise_sigma=noise_sigma, stream_hz=stream_hz,
        bryan_factor=bryan_factor, split_hz=split_hz, quadrature=quadrature, amplitude=amplitude,
        theta_tau_deg=theta_tau_deg, theta_w_deg=theta_w_deg, duration_s=max(lengths_tau) * tau_s,
    )
    lock_dps = math.degrees(delta_inv_tau_per_s / 4.0 / bryan_factor)
    if rates_dps is None:
        rates_dps = tuple(float(r) for r in np.geomspace(max(4.0 * lock_dps, 1e-3), 1000.0, 16))
    if min(rates_dps) <= lock_dps:
        raise ValueError(f"rates_dps must stay above the locking rate {lock_dps:.3g} deg/s "
                         f"(min given {min(rates_dps)})")
    lengths_s = tuple(float(f * tau_s) for f in sorted(lengths_tau))
    points: list[FreeDecayDesignPoint] = []
    for rate in sorted(set(rates_dps)):
        points += [p for p in _free_decay_points(replace(base, rate_dps=rate), lengths_s)
                   if abs(p.rate_dps) * p.duration_s >= 360.0 * min_turns]
    if not points:
        raise ValueError(f"no (rate, length) in the grid turns the table {min_turns:g} times in the record")
    best = min(p.std_delta_inv_tau_per_s for p in points)
    length = min(p.duration_s for p in points if p.std_delta_inv_tau_per_s <= (1.0 + length_tolerance) * best)
    rec = min((p for p in points if p.duration_s == length), key=lambda p: p.std_delta_inv_tau_per_s)
    return FreeDecayDesign(base, tuple(points), rec, lock_dps)
