"""Whole-angle self-calibration (CETC paper; docs/selfcal.md): least squares on the amplitude and
frequency control channels over forced-precession cycles give the X/Y gain difference, the damping
and stiffness anisotropy and Q; the precession channel's rate with the identified drift and gain
terms removed is the compensated input rate.  Pure analysis: arrays in, results out."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .axes import axis_deg


def _stats():
    """scipy.stats, imported on first use: a process that only loads the procedures (the line's
    limits, `gyrobench list`) never pays its ~0.4 s (issue 36)."""
    from scipy import stats

    return stats


#: amplitude-channel regressors (docs/selfcal.md): 1, cos 4th, sin 4th, thdot sin 4th, thdot cos 4th
AMP_TERMS = ("gamma", "beta_c", "beta_s", "two_dg", "nuisance_c")
#: with the 8 theta model (fit_cycle(model_8theta=True)) also cos 8th, sin 8th, thdot sin 8th, thdot cos 8th:
#: the amplitude pattern of the pickoffs' capacitive nonlinearity (docs/selfcal.md section 8)
AMP_TERMS_8 = ("beta8_c", "beta8_s", "k8_s", "k8_c")
#: frequency-channel regressors: 1, cos 4th, sin 4th (the FM averages out over bins of whole FM periods)
FREQ_TERMS = ("f_mean_hz", "h_c_hz", "h_s_hz")
#: with the frequency-control force's square wave m = +-1 (FM_FORCE_HZ F): also m F, m F cos 4th, m F sin 4th,
#: whose coefficients are the loop gain 1 + s_m + s_d cos 4th + s_s sin 4th the force meets (docs/selfcal.md)
FM_TERMS = ("fm_gain", "fm_gain_c", "fm_gain_s")
#: the square wave's switching transient left out of the fit (the PLL settles in about 1 s)
FM_SETTLE_S = 5.0


@dataclass(frozen=True)
class Estimate:
    """A value with its standard error and the two-sided interval at the fit's level."""

    value: float
    se: float
    ci: tuple[float, float]


@dataclass(frozen=True)
class CycleFit:
    """The parameters identified over one forced-precession cycle (docs/selfcal.md, section 3)."""

    t_start_s: float
    t_end_s: float
    amp_coef: np.ndarray  # AMP_TERMS (1/s; two_dg dimensionless)
    amp_cov: np.ndarray
    freq_coef: np.ndarray  # FREQ_TERMS (Hz)
    freq_cov: np.ndarray
    dof: int
    level: float
    f0_hz: float

    def _est(self, value: float, grad: np.ndarray, cov: np.ndarray, grad_f: np.ndarray | None = None) -> Estimate:
        """value with the delta method's standard error: grad over the amplitude channel's
        coefficients (cov), grad_f over the frequency channel's (independent of them)."""
        var = grad @ cov @ grad
        if grad_f is not None:
            var += grad_f @ self.freq_cov @ grad_f
        se = float(math.sqrt(max(0.0, var)))
        t = float(_stats().t.ppf(0.5 + self.level / 2.0, self.dof))
        return Estimate(float(value), se, (float(value - t * se), float(value + t * se)))

    @property
    def has_fm_force(self) -> bool:
        """The frequency channel carries the frequency-control force's response (FM_TERMS)."""
        return len(self.freq_coef) == len(FREQ_TERMS) + len(FM_TERMS)

    @property
    def has_8theta(self) -> bool:
        """The amplitude channel carries the 8 theta terms (AMP_TERMS_8)."""
        return len(self.amp_coef) == len(AMP_TERMS) + len(AMP_TERMS_8)

    def _amp_grad(self, *values: float) -> np.ndarray:
        """A gradient over the amplitude coefficients: values on the first terms, 0 on the rest."""
        g = np.zeros(len(self.amp_coef))
        g[: len(values)] = values
        return g

    def _fm_grad(self, j: int) -> np.ndarray:
        g = np.zeros(len(self.freq_coef))
        g[len(FREQ_TERMS) + j] = 1.0
        return g

    @property
    def loop_gain_cm(self) -> Estimate:
        """s_m: the common-mode loop gain error (pickoff x forcer) the frequency-control force meets,
        which scales the commanded precession by 1 + s_m (the paper's delta of its eq. 11); 0 with
        no frequency-control force (not identified)."""
        if not self.has_fm_force:
            return Estimate(0.0, 0.0, (0.0, 0.0))
        z = np.zeros(len(self.amp_coef))
        return self._est(self.freq_coef[len(FREQ_TERMS)] - 1.0, z, self.amp_cov, self._fm_grad(0))

    @property
    def loop_gain_diff(self) -> Estimate:
        """s_d: the X/Y difference of the loop gain (pickoff and forcer: g_x - g_y over 2 of each,
        summed), the cos 4 theta term of the force's response; 0 with no frequency-control force."""
        if not self.has_fm_force:
            return Estimate(0.0, 0.0, (0.0, 0.0))
        z = np.zeros(len(self.amp_coef))
        return self._est(self.freq_coef[len(FREQ_TERMS) + 1], z, self.amp_cov, self._fm_grad(1))

    @property
    def loop_skew(self) -> Estimate:
        """s_s: the loop's X/Y non-orthogonality, the pickoff and the forcer electrodes' e_x - e_y (radians)
        summed: a gain difference along axes 22.5 deg off the electrodes', the sin 4 theta term of the
        force's response (docs/readout_phase.md); 0 with no frequency-control force."""
        if not self.has_fm_force:
            return Estimate(0.0, 0.0, (0.0, 0.0))
        z = np.zeros(len(self.amp_coef))
        return self._est(self.freq_coef[len(FREQ_TERMS) + 2], z, self.amp_cov, self._fm_grad(2))

    def _gamma(self) -> tuple[float, np.ndarray, np.ndarray]:
        """The mean damping gamma (1/s): the amplitude channel reads gamma / (1 + s_m) (the AGC's
        force meets the loop gain), put back with the frequency-control force's s_m when there is one."""
        gam = float(self.amp_coef[0])
        g = np.zeros(len(self.amp_coef))
        if not self.has_fm_force:
            g[0] = 1.0
            return gam, g, np.zeros(len(self.freq_coef))
        gain = float(self.freq_coef[len(FREQ_TERMS)])  # 1 + s_m
        g[0] = gain
        return gam * gain, g, gam * self._fm_grad(0)

    @property
    def gain_diff(self) -> Estimate:
        """Delta g = g_x - g_y, the X/Y pickoff gain difference (dimensionless)."""
        g = np.zeros(len(self.amp_coef))
        g[3] = 0.5
        return self._est(0.5 * self.amp_coef[3], g, self.amp_cov)

    @property
    def q_factor(self) -> Estimate:
        """Q = w0 / gamma."""
        gam, g_a, g_f = self._gamma()
        k = -2 * math.pi * self.f0_hz / gam**2
        return self._est(2 * math.pi * self.f0_hz / gam, k * g_a, self.amp_cov, k * g_f)

    def _b(self) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The damping anisotropy's (b_c, b_s) with the gains' share of the cos term put back:
        b_c = beta_c + gamma s_d (beta_c is the amplitude channel's 4 theta cos term; s_d the
        frequency-control force's loop gain difference, pickoff and forcer), or, with no
        frequency-control force, beta_c + gamma Delta g / 2 (the pickoff's difference alone).
        Returns b_c, b_s and their gradients over the amplitude and the frequency coefficients."""
        gam, bc_app, bs, two_dg = self.amp_coef[:4]
        nf = len(self.freq_coef)
        g_bs, g_bs_f = self._amp_grad(0.0, 0.0, 1.0), np.zeros(nf)
        if self.has_fm_force:  # the skew s_s tilts the amplitude force along sin 4 theta as s_d along cos
            sd, ss = float(self.freq_coef[len(FREQ_TERMS) + 1]), float(self.freq_coef[len(FREQ_TERMS) + 2])
            bc, bs_true = bc_app + gam * sd, bs + gam * ss
            return (float(bc), float(bs_true), self._amp_grad(sd, 1.0), self._amp_grad(ss, 0.0, 1.0),
                    gam * self._fm_grad(1), gam * self._fm_grad(2))
        bc = bc_app + gam * two_dg / 4.0
        g_bc = self._amp_grad(two_dg / 4.0, 1.0, 0.0, gam / 4.0)
        return float(bc), float(bs), g_bc, g_bs, np.zeros(nf), g_bs_f

    @property
    def delta_inv_tau(self) -> Estimate:
        """D = Delta(1/tau) = hypot(b_c, b_s) (1/s)."""
        bc, bs, g_bc, g_bs, f_bc, f_bs = self._b()
        d = math.hypot(bc, bs)
        return self._est(d, (bc * g_bc + bs * g_bs) / d, self.amp_cov, (bc * f_bc + bs * f_bs) / d)

    @property
    def theta_tau_deg(self) -> Estimate:
        """The damping axis: (1/4) atan2(b_s, b_c), degrees, in [0, 90) (bench.analysis.axes)."""
        bc, bs, g_bc, g_bs, f_bc, f_bs = self._b()
        r2 = bc * bc + bs * bs
        k = math.degrees(1.0) / 4.0 / r2
        return self._est(axis_deg(math.degrees(math.atan2(bs, bc)) / 4.0), k * (bc * g_bs - bs * g_bc), self.amp_cov,
                         k * (bc * f_bs - bs * f_bc))

    @property
    def split_hz(self) -> Estimate:
        """Frequency split: the frequency channel's 4 theta term is (split/2) cos 4(theta - theta_w)."""
        hc, hs = self.freq_coef[1:3]
        r = math.hypot(hc, hs)
        g = np.zeros(len(self.freq_coef))
        g[1], g[2] = 2 * hc / r, 2 * hs / r
        return self._est(2 * r, g, self.freq_cov)

    @property
    def theta_w_deg(self) -> Estimate:
        """The stiffness axis: (1/4) atan2(h_s, h_c), degrees, in [0, 90) (bench.analysis.axes)."""
        hc, hs = self.freq_coef[1:3]
        r2 = hc * hc + hs * hs
        g = np.zeros(len(self.freq_coef))
        g[1], g[2] = -hs / r2, hc / r2
        return self._est(axis_deg(math.degrees(math.atan2(hs, hc)) / 4.0), g * math.degrees(1.0) / 4.0,
                         self.freq_cov)

    def drift_rad_s(self, theta_rad: np.ndarray, cmd_rad_s: np.ndarray, *, gain_removed: bool = False) -> np.ndarray:
        """The wave's drift (rad/s of measured wave angle) these parameters predict at measured angle
        theta under precession command cmd: (beta_c sin 4th - beta_s cos 4th) / 4 (damping, with the
        amplitude force's gain tilt in it) + cmd (s_m - s_d cos 4th - s_s sin 4th) (the loop gain the
        precession force meets and the pickoff's angle pattern; s_s the electrodes' non-orthogonality,
        the same pattern 22.5 deg on; with no frequency-control force s_m = s_s = 0 and s_d = Delta g / 2,
        the pickoff's).
        gain_removed: the pickoff gain difference has since been trimmed out (FPGA gain trims): its
        tilt of the amplitude force goes back into beta_c and its share of s_d goes."""
        gam, bc_app, bs, two_dg = self.amp_coef[:4]
        s4, c4 = np.sin(4 * theta_rad), np.cos(4 * theta_rad)
        dg_half = two_dg / 4.0  # the pickoff's g_x - g_y over 2, seen by the amplitude channel
        if self.has_fm_force:
            sm, sd = self.loop_gain_cm.value, self.loop_gain_diff.value
            ss = self.loop_skew.value
        else:
            sm, sd, ss = 0.0, dg_half, 0.0
        if gain_removed:
            bc_app, sd = bc_app + gam * dg_half, sd - dg_half
        drift = 0.25 * (bc_app * s4 - bs * c4) + cmd_rad_s * (sm - sd * c4 - ss * s4)
        return drift + self.drift_8theta_rad_s(theta_rad, cmd_rad_s)

    def drift_8theta_rad_s(self, theta_rad: np.ndarray, cmd_rad_s: np.ndarray) -> np.ndarray:
        """The 8 theta drift of a measured-amplitude pattern c8 cos 8(theta - phi) (the pickoffs'
        capacitive nonlinearity; docs/selfcal.md section 8), the 4 theta law carried over: the AGC's
        force, applied along the measured wave, turns it at (beta8_c sin 8th - beta8_s cos 8th) / 4, and
        under the command the drift is -1/4 of the amplitude channel's thdot pattern times the command,
        -(cmd / 4) (k8_s cos 8th - k8_c sin 8th) (at 4 theta: -(cmd / 4) 4 s_d cos 4th); k8 = 8 c8
        (cos 8 phi, -sin 8 phi), the thdot sin / cos 8th terms.  0 without the 8 theta terms."""
        if not self.has_8theta:
            return np.zeros_like(np.asarray(theta_rad, dtype=float))
        b8c, b8s, k8s, k8c = self.amp_coef[len(AMP_TERMS):]
        s8, c8 = np.sin(8 * theta_rad), np.cos(8 * theta_rad)
        return 0.25 * (b8c * s8 - b8s * c8) - 0.25 * cmd_rad_s * (k8s * c8 - k8c * s8)


def _ols(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Ordinary least squares: coefficients, their covariance s^2 (X'X)^-1, degrees of freedom."""
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    dof = len(y) - x.shape[1]
    if dof < 1:
        raise ValueError(f"{len(y)} points for {x.shape[1]} parameters: need more data in the cycle")
    s2 = float(np.sum((y - x @ coef) ** 2) / dof)
    return coef, s2 * np.linalg.inv(x.T @ x), dof


def bin_means(t_s: np.ndarray, bin_s: float, *ys: np.ndarray) -> list[np.ndarray]:
    """Means over consecutive bins of bin_s (the loops' filtered outputs are correlated over a few
    seconds; bin means tens of seconds long are close to independent, so OLS intervals hold)."""
    t = np.asarray(t_s, dtype=float)
    idx = np.floor((t - t[0]) / bin_s).astype(int)
    n = np.bincount(idx)
    keep = n > 0
    out = [np.bincount(idx, weights=np.asarray(y, dtype=float))[keep] / n[keep] for y in (t, *ys)]
    return out


def fm_square(t_s: np.ndarray, fm_rate_hz: float) -> np.ndarray:
    """The frequency-control force's square wave (+-1) at times t_s, as the FPGA makes it."""
    return np.where(np.sin(2.0 * math.pi * fm_rate_hz * np.asarray(t_s, dtype=float)) >= 0.0, 1.0, -1.0)


def fit_fm_force(t_s: np.ndarray, theta_rad: np.ndarray, freq_ctrl_hz: np.ndarray, *, fm_force_hz: float,
                 fm_rate_hz: float, settle_s: float = FM_SETTLE_S) -> tuple[np.ndarray, np.ndarray, int]:
    """The frequency channel under the frequency-control force (the paper's FM): means over each half
    period of the square wave with its switching transient (settle_s) left out, regressed on
    (1, cos 4th, sin 4th, m F, m F cos 4th, m F sin 4th) (FREQ_TERMS + FM_TERMS)."""
    t = np.asarray(t_s, dtype=float)
    half = 0.5 / fm_rate_hz
    since = np.mod(t, half)
    keep = (since >= settle_s) & (since < half - 1e-9)
    idx = np.floor(t / half).astype(np.int64)
    idx = idx - idx.min()
    m = fm_square(t, fm_rate_hz) * fm_force_hz
    c4, s4 = np.cos(4 * theta_rad), np.sin(4 * theta_rad)
    cols = [np.asarray(freq_ctrl_hz, dtype=float), c4, s4, m, m * c4, m * s4]
    n = np.bincount(idx[keep])
    ok = n > 0
    means = [np.bincount(idx[keep], weights=c[keep])[ok] / n[ok] for c in cols]
    x = np.column_stack([np.ones_like(means[0]), *means[1:]])
    return _ols(x, means[0])


def fit_cycle(t_s: np.ndarray, theta_rad: np.ndarray, thdot_rad_s: np.ndarray, amp_ctrl: np.ndarray,
              freq_ctrl_hz: np.ndarray, *, amplitude: float, f0_hz: float, bin_s: float = 20.0,
              fm_rate_hz: float = 0.0, fm_force_hz: float = 0.0, level: float = 0.95,
              model_8theta: bool = False) -> CycleFit:
    """Identify one cycle: amp_ctrl / amplitude on (1, cos 4th, sin 4th, thdot sin 4th, thdot cos 4th),
    freq_ctrl on (1, cos 4th, sin 4th) over bins of whole FM periods (which average the FM out) or,
    with the frequency-control force (fm_force_hz > 0), also on its square wave (fit_fm_force);
    theta the measured wave angle (rad), thdot its rate (rad/s).  Fits bin means of bin_s seconds.
    model_8theta: the amplitude channel also on (cos 8th, sin 8th, thdot sin 8th, thdot cos 8th)
    (AMP_TERMS_8), which the drift model then uses (CycleFit.drift_8theta_rad_s)."""
    t_s = np.asarray(t_s, dtype=float)
    if len(t_s) < 8:
        raise ValueError(f"a cycle of {len(t_s)} samples is too short to identify")
    f = np.asarray(freq_ctrl_hz, dtype=float)
    s4, c4 = np.sin(4 * theta_rad), np.cos(4 * theta_rad)
    extra = []
    if model_8theta:
        s8, c8 = np.sin(8 * theta_rad), np.cos(8 * theta_rad)
        extra = [c8, s8, thdot_rad_s * s8, thdot_rad_s * c8]
    tb, ab, c4b, s4b, tsb, tcb, *xb = bin_means(t_s, bin_s, np.asarray(amp_ctrl) / amplitude, c4, s4,
                                                thdot_rad_s * s4, thdot_rad_s * c4, *extra)
    one = np.ones_like(tb)
    amp_coef, amp_cov, dof = _ols(np.column_stack([one, c4b, s4b, tsb, tcb, *xb]), ab)
    if fm_force_hz > 0 and fm_rate_hz > 0:
        freq_coef, freq_cov, _ = fit_fm_force(t_s, theta_rad, f, fm_force_hz=fm_force_hz, fm_rate_hz=fm_rate_hz)
    elif fm_rate_hz > 0:
        # the FM's period is short against a bin: fit the frequency channel over bins of whole FM periods
        fm_bin = max(1.0, round(bin_s * fm_rate_hz)) / fm_rate_hz
        tf, fb, c4f, s4f = bin_means(t_s, fm_bin, f, c4, s4)
        freq_coef, freq_cov, _ = _ols(np.column_stack([np.ones_like(tf), c4f, s4f]), fb)
    else:
        freq_coef, freq_cov, _ = _ols(np.column_stack([one, c4b, s4b]), bin_means(t_s, bin_s, f)[1])
    return CycleFit(float(t_s[0]), float(t_s[-1]), amp_coef, amp_cov, freq_coef, freq_cov, dof, level, f0_hz)


def cycle_bounds(cmd_dps: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [i0, i1) of whole cycles (forward then back) in a precession command record:
    a cycle starts where the command turns positive after being negative (or at the start)."""
    sgn = np.sign(np.asarray(cmd_dps, dtype=float))
    starts = [0] + [i for i in range(1, len(sgn)) if sgn[i] > 0 and sgn[i - 1] < 0]
    return [(a, b) for a, b in zip(starts, starts[1:], strict=False)]


def rate_dph(theta_rad: np.ndarray, t_s: np.ndarray, cmd_rad_s: np.ndarray, bryan_factor: float,
             drift_rad_s: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input rate (deg/h) between samples from the precession channel: -(thdot - cmd - drift) / K,
    with the angle, command and drift taken at the midpoints; returns (t_mid, theta_mid, rate)."""
    dt = np.diff(t_s)
    thdot = np.diff(theta_rad) / dt
    th_mid = 0.5 * (theta_rad[1:] + theta_rad[:-1])
    cmd_mid = cmd_rad_s[1:]
    d = 0.0 if drift_rad_s is None else drift_rad_s
    rate = -(thdot - cmd_mid - d) / bryan_factor
    return 0.5 * (t_s[1:] + t_s[:-1]), th_mid, np.degrees(rate) * 3600.0


def bias_stability_dph(rate_dph_: np.ndarray, sample_s: float, smooth_s: float = 100.0) -> float:
    """Bias stability: the standard deviation (1 sigma) of the rate's means over consecutive
    smooth_s windows (the paper's 100 s smoothing)."""
    m = max(1, int(round(smooth_s / sample_s)))
    n = len(rate_dph_) // m
    if n < 2:
        raise ValueError(f"a record of {len(rate_dph_) * sample_s:.0f} s holds fewer than two {smooth_s:g} s windows")
    means = np.asarray(rate_dph_[: n * m]).reshape(n, m).mean(axis=1)
    return float(np.std(means, ddof=1))


def bias_stability_interval(value: float, n_windows: int, level: float = 0.95) -> tuple[float, float]:
    """Chi-squared interval of a standard deviation from n_windows independent means."""
    k = n_windows - 1
    lo = value * math.sqrt(k / _stats().chi2.ppf(0.5 + level / 2, k))
    hi = value * math.sqrt(k / _stats().chi2.ppf(0.5 - level / 2, k))
    return lo, hi


def mean_since_start_dph(rate_dph_: np.ndarray) -> np.ndarray:
    """The mean bias since the start at every sample (the paper's figure 7)."""
    r = np.asarray(rate_dph_, dtype=float)
    return np.cumsum(r) / np.arange(1, len(r) + 1)


def integrated_angle_deg(rate_dph_: np.ndarray, sample_s: float, true_rate_dph: float = 0.0) -> np.ndarray:
    """The integrated angle error (deg) of the rate against the true input rate."""
    return np.cumsum(np.asarray(rate_dph_, dtype=float) - true_rate_dph) * sample_s / 3600.0


def gain_trend(t_h: np.ndarray, values: np.ndarray, se: np.ndarray, level: float = 0.95) -> tuple[Estimate, Estimate]:
    """Weighted straight line through the cycles' gain differences: (value at t = 0, slope per hour)."""
    w = 1.0 / np.asarray(se, dtype=float) ** 2
    x = np.column_stack([np.ones_like(t_h), t_h])
    cov = np.linalg.inv(x.T @ (w[:, None] * x))
    coef = cov @ (x.T @ (w * values))
    dof = max(1, len(values) - 2)
    chi2 = float(np.sum(w * (values - x @ coef) ** 2) / dof)
    cov = cov * max(1.0, chi2)  # the scatter, if larger than the stated errors
    t = float(_stats().t.ppf(0.5 + level / 2, dof))
    out = []
    for j in range(2):
        se_j = math.sqrt(cov[j, j])
        out.append(Estimate(float(coef[j]), se_j, (float(coef[j] - t * se_j), float(coef[j] + t * se_j))))
    return out[0], out[1]


@dataclass(frozen=True)
class AngleErrorModel:
    """The integrated angle error's spread, fitted to its increments: D(L) = E[(e(t + L) - e(t))^2] =
    arw2_deg2_s L + 2 bounded_var_deg2 (1 - exp(-L / tau_c_s)): an angle random walk (white rate
    noise, N^2 in deg^2/s) plus a bounded (stationary) angle error of variance s^2 and correlation
    time tau_c (docs/selfcal.md, section 4).  Flicker or a rate random walk would bend D(L) upward
    faster than this model allows: `worst_rel_misfit` says how well it holds."""

    arw2_deg2_s: float
    bounded_var_deg2: float
    tau_c_s: float
    worst_rel_misfit: float
    #: one-sided 95 % upper bound on arw2_deg2_s: D(L) >= N^2 L at every lag (the bounded term is
    #: >= 0), each lag's D(L) taken at its chi-square bound, Bonferroni over the lags (NaN: not fitted)
    arw2_upper_deg2_s: float = math.nan

    def arw_deg_rth(self) -> tuple[float, tuple[float, float]]:
        """The angle random walk N (deg/sqrt(h)) and its one-sided 95 % interval [0, upper]: the
        bounded angle error can take up any share of D(L), so the data bound N from above only."""
        n = math.sqrt(self.arw2_deg2_s) * 60.0
        return n, (0.0, max(n, math.sqrt(self.arw2_upper_deg2_s) * 60.0))

    def increment_var_deg2(self, lag_s: np.ndarray | float) -> np.ndarray:
        lag = np.asarray(lag_s, dtype=float)
        return self.arw2_deg2_s * lag + 2.0 * self.bounded_var_deg2 * (1.0 - np.exp(-lag / self.tau_c_s))

    def mean_sd_dph(self, t_s: float) -> float:
        """Standard deviation of the mean bias since start after t_s: sqrt(D(t)) / t."""
        return float(np.sqrt(self.increment_var_deg2(t_s)) / t_s * 3600.0)


def increment_var_deg2(angle_deg: np.ndarray, sample_s: float, lags_s: np.ndarray) -> np.ndarray:
    """D(L): the mean square of the angle error's increments over each lag (overlapping)."""
    e = np.asarray(angle_deg, dtype=float)
    out = np.empty(len(lags_s))
    for i, lag in enumerate(lags_s):
        k = max(1, int(round(lag / sample_s)))
        d = e[k:] - e[:-k]
        out[i] = float(np.mean(d * d))
    return out


def fit_angle_error(angle_deg: np.ndarray, sample_s: float, min_lag_s: float = 10.0,
                    max_lag_fraction: float = 0.25) -> AngleErrorModel:
    """Fit AngleErrorModel to the record's increment variances at lags from min_lag_s to a quarter of
    the record (geometric, 8 a factor of ten): tau_c on a log grid, the two variances >= 0 by
    non-negative least squares on relative errors, the best tau_c kept."""
    from scipy.optimize import nnls

    n = len(angle_deg)
    t_rec = (n - 1) * sample_s
    hi = max_lag_fraction * t_rec
    if hi <= min_lag_s:
        raise ValueError(f"a record of {t_rec:.0f} s is too short to fit its angle error over lags of "
                         f"{min_lag_s:g} s and up")
    lags = np.unique(np.round(np.geomspace(min_lag_s, hi, int(8 * math.log10(hi / min_lag_s)) + 2) / sample_s))
    lags = lags * sample_s
    d = increment_var_deg2(angle_deg, sample_s, lags)
    w = np.sqrt(t_rec / lags)  # a relative error of D(L) grows as sqrt(L / T): weigh by its inverse
    best: AngleErrorModel | None = None
    best_cost = math.inf
    for tau_c in np.geomspace(min_lag_s / 3.0, hi / 4.0, 50):  # a bounded error saturates inside the lags
        a = np.column_stack([lags, 2.0 * (1.0 - np.exp(-lags / tau_c))]) / d[:, None] * w[:, None]
        coef, _ = nnls(a, w)
        cost = float(np.sum((a @ coef - w) ** 2))
        if cost < best_cost:
            best_cost = cost
            best = AngleErrorModel(float(coef[0]), float(coef[1]), float(tau_c), 0.0)
    assert best is not None
    misfit = float(np.max(np.abs(best.increment_var_deg2(lags) / d - 1.0)))
    return AngleErrorModel(best.arw2_deg2_s, best.bounded_var_deg2, best.tau_c_s, misfit,
                           arw2_upper_bound(d, lags, t_rec))


def arw2_upper_bound(d_deg2: np.ndarray, lags_s: np.ndarray, t_rec_s: float, level: float = 0.95) -> float:
    """One-sided upper bound on N^2 (deg^2/s) from the increment variances: N^2 <= D(L) / L at every
    lag; D(L) from T/L independent increments is chi-square with that many degrees of freedom, so
    each lag bounds N^2 by D(L) (T/L) / chi2_{alpha/n}(T/L) / L; the least bound, with the level
    split over the n lags (Bonferroni), holds at `level` or more."""
    alpha = (1.0 - level) / len(lags_s)
    dof = np.maximum(1.0, np.floor(t_rec_s / lags_s))
    return float(np.min(d_deg2 * dof / _stats().chi2.ppf(alpha, dof) / lags_s))
