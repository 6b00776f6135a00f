"""Resonator parameters in physical units, the presets, and every unit conversion in one place.

Physical parameters (Hz, s, deg, 1/s) are what a lab engineer reads off a data sheet; the model
coefficients (gamma, nu, b_c, ... in 1/s and rad/s) are what the averaged equations use.
`ResonatorParams.coefficients()` is the only place the two meet.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from bench.analysis.axes import axis_deg

TWO_PI = 2.0 * math.pi


class ParameterError(ValueError):
    """A resonator parameter is missing, non-finite or outside its physical range."""


@dataclass(frozen=True)
class ModelCoefficients:
    """Coefficients of the averaged model (PHYSICS.md section 2), SI units (1/s, rad/s)."""

    w0_rad_s: float
    gamma: float
    b_c: float
    b_s: float
    c_m: float
    n: float
    h_c: float
    h_s: float
    nu_offset: float
    bryan_factor: float
    xi: float
    kappa: float

    def zg(self, rate_rad_s: float) -> np.ndarray:
        """The linear parameter vector (gamma, nu, b_c, b_s, c_m, n, h_c, h_s) at a case rate."""
        nu = 4.0 * self.bryan_factor * rate_rad_s + self.nu_offset
        return np.array([self.gamma, nu, self.b_c, self.b_s, self.c_m, self.n, self.h_c, self.h_s])


@dataclass(frozen=True)
class ResonatorParams:
    """A two-mode (n = 2) Coriolis vibratory resonator in physical units.

    f0_hz: nominal natural frequency (the model's w = 2 pi f0_hz).
    tau_s: amplitude decay time constant (a ~ exp(-t/tau), E ~ exp(-2t/tau)); Q = pi f0 tau.
    delta_inv_tau_per_s: damping anisotropy D = 1/tau1 - 1/tau2 >= 0; theta_tau_deg its most
        damped axis (physical degrees in the case frame).
    split_hz: frequency split between the two principal axes; theta_w_deg the high-frequency axis.
    freq_offset_hz: mean mistuning of the natural frequency from f0_hz (c_m / 2 in rad/s).
    circulatory_per_s: the circulatory positional term n.
    nu_offset_per_s: a rotation-like term present at zero case rate (the MEMS ring's zero-rate
        output); 0 for an ideal resonator.
    bryan_factor: K, the wave's precession relative to the case is -K Omega.
    xi_per_s, kappa_per_s: cubic and quintic nonlinearity (per unit amplitude^2 and ^4).
    noise_sigma: white measurement noise on each of cx, sx, cy, sy (signal units).
    """

    f0_hz: float
    tau_s: float
    delta_inv_tau_per_s: float = 0.0
    theta_tau_deg: float = 0.0
    split_hz: float = 0.0
    theta_w_deg: float = 0.0
    freq_offset_hz: float = 0.0
    circulatory_per_s: float = 0.0
    nu_offset_per_s: float = 0.0
    bryan_factor: float = 0.277
    xi_per_s: float = 0.0
    kappa_per_s: float = 0.0
    noise_sigma: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(f"resonator parameter {f.name}={value!r} must be a finite number")
        positive = {"f0_hz": self.f0_hz, "tau_s": self.tau_s}
        for name, value in positive.items():
            if value <= 0:
                raise ParameterError(f"resonator parameter {name}={value!r} must be > 0")
        nonneg = {
            "delta_inv_tau_per_s": self.delta_inv_tau_per_s,
            "split_hz": self.split_hz,
            "noise_sigma": self.noise_sigma,
        }
        for name, value in nonneg.items():
            if value < 0:
                raise ParameterError(f"resonator parameter {name}={value!r} must be >= 0")
        if not 0 < self.bryan_factor <= 1:
            raise ParameterError(f"resonator parameter bryan_factor={self.bryan_factor!r} must be in (0, 1]")
        # both principal damping rates must stay positive: 2/tau -/+ D > 0
        if self.delta_inv_tau_per_s >= 2.0 / self.tau_s:
            raise ParameterError(
                f"resonator parameter delta_inv_tau_per_s={self.delta_inv_tau_per_s!r} must be < 2/tau_s "
                f"= {2.0 / self.tau_s:.6g} (one axis would have negative damping)"
            )

    # --- alternative constructors and derived quantities -------------------------------------
    @classmethod
    def from_q(cls, f0_hz: float, q_factor: float, **kwargs: float) -> ResonatorParams:
        """Build from a quality factor instead of tau (Q = pi f0 tau)."""
        if not (isinstance(q_factor, (int, float)) and math.isfinite(q_factor) and q_factor > 0):
            raise ParameterError(f"resonator parameter q_factor={q_factor!r} must be a finite number > 0")
        return cls(f0_hz=f0_hz, tau_s=tau_from_q(q_factor, f0_hz), **kwargs)

    @property
    def q_factor(self) -> float:
        return q_from_tau(self.tau_s, self.f0_hz)

    def coefficients(self) -> ModelCoefficients:
        """Physical units -> model coefficients.  The only conversion point."""
        d = self.delta_inv_tau_per_s
        th_tau = math.radians(self.theta_tau_deg)
        dw = TWO_PI * self.split_hz
        th_w = math.radians(self.theta_w_deg)
        return ModelCoefficients(
            w0_rad_s=TWO_PI * self.f0_hz,
            gamma=2.0 / self.tau_s,
            b_c=d * math.cos(4 * th_tau),
            b_s=d * math.sin(4 * th_tau),
            c_m=2.0 * TWO_PI * self.freq_offset_hz,
            n=self.circulatory_per_s,
            h_c=dw * math.cos(4 * th_w),
            h_s=dw * math.sin(4 * th_w),
            nu_offset=self.nu_offset_per_s,
            bryan_factor=self.bryan_factor,
            xi=self.xi_per_s,
            kappa=self.kappa_per_s,
        )

    def truth(self) -> dict[str, float]:
        """Ground truth under the names the procedures' measurements use: the physical names of
        the HRG procedures, and the model coefficients, Q and axes (Maslov's alpha = stiffness
        axis, beta = damping axis, both in [0, 90) deg as every procedure reports an axis,
        bench.analysis.axes) of the identification."""
        th = ((self.theta_tau_deg % 90.0) + 90.0) % 90.0
        c = self.coefficients()
        model = {
            "gamma": c.gamma,
            "b_c": c.b_c,
            "b_s": c.b_s,
            "c_m": c.c_m,
            "n": c.n,
            "h_c": c.h_c,
            "h_s": c.h_s,
            "xi": c.xi,
            "kappa": c.kappa,
            "Q": c.w0_rad_s / c.gamma,
            "split_rad_s": TWO_PI * self.split_hz,
            "alpha_deg": axis_deg(math.degrees(0.25 * math.atan2(c.h_s, c.h_c))),
            "beta_deg": axis_deg(math.degrees(0.25 * math.atan2(c.b_s, c.b_c))),
            "zero_rate_dps": math.degrees(c.nu_offset / (4.0 * c.bryan_factor)),
            # the damping drift (D/4) sin 4(theta - th_tau) referred to the gyro output (/K)
            "drift_predicted_dph": rad_s_to_dph(self.delta_inv_tau_per_s / 4.0 / self.bryan_factor),
        }
        # the whole-angle drift against the angle with ideal loops: the damping drift's 4 theta term
        # before compensation, and nothing else (no mean, no 8 or 12 theta term) before or after; the
        # mean is the ideal loops' only (hrg-damping compares it with no truth: docs/damping_drift.md)
        model["drift_before_dph"] = model["drift_before_4theta_dph"] = model["drift_predicted_dph"]
        for name in ("before", "after"):
            for term in ("mean", "8theta", "12theta"):
                model[f"drift_{name}_{term}_dph"] = 0.0
        return model | {
            "tau_s": self.tau_s,
            "q_factor": self.q_factor,
            "theta_tau_deg": th,
            "delta_inv_tau_per_s": self.delta_inv_tau_per_s,
            "damping_anisotropy_per_s": 2.0 * self.delta_inv_tau_per_s,
            "split_hz": self.split_hz,
            "theta_w_deg": ((self.theta_w_deg % 90.0) + 90.0) % 90.0,
            "freq_offset_hz": self.freq_offset_hz,
            "bryan_factor": self.bryan_factor,
            "f0_hz": self.f0_hz,
        }

    def with_(self, **changes: float) -> ResonatorParams:
        return replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def tau_from_q(q_factor: float, f0_hz: float) -> float:
    """tau = 2 Q / w (amplitude time constant)."""
    return 2.0 * q_factor / (TWO_PI * f0_hz)


def q_from_tau(tau_s: float, f0_hz: float) -> float:
    return math.pi * f0_hz * tau_s


def dps_to_rad_s(rate_dps: float) -> float:
    return math.radians(rate_dps)


def rad_s_to_dph(rate_rad_s: float) -> float:
    """rad/s -> deg/h."""
    return math.degrees(rate_rad_s) * 3600.0


def from_coefficients(w0_rad_s: float, *, gamma: float, b_c: float = 0.0, b_s: float = 0.0,
                      c_m: float = 0.0, n: float = 0.0, h_c: float = 0.0, h_s: float = 0.0,
                      nu: float = 0.0, bryan_factor: float = 0.277, xi: float = 0.0,
                      kappa: float = 0.0, noise_sigma: float = 0.0) -> ResonatorParams:
    """Model coefficients (as identified, e.g. Maslov's table) -> physical parameters."""
    return ResonatorParams(
        f0_hz=w0_rad_s / TWO_PI,
        tau_s=2.0 / gamma,
        delta_inv_tau_per_s=math.hypot(b_c, b_s),
        theta_tau_deg=math.degrees(0.25 * math.atan2(b_s, b_c)),
        split_hz=math.hypot(h_c, h_s) / TWO_PI,
        theta_w_deg=math.degrees(0.25 * math.atan2(h_s, h_c)),
        freq_offset_hz=c_m / (2.0 * TWO_PI),
        circulatory_per_s=n,
        nu_offset_per_s=nu,
        bryan_factor=bryan_factor,
        xi_per_s=xi,
        kappa_per_s=kappa,
        noise_sigma=noise_sigma,
    )


#: Maslov et al. (2022) identified cubic model of a MEMS ring, w = 85732 1/s, amplitudes
#: normalised to the largest.  The forcing u1..u4 they identified is a drive setting, not a
#: resonator property: see MASLOV_FORCING.
MASLOV_W_RAD_S = 85732.0
MASLOV_FORCING = (32.159, 30.597, 1.415, -0.605)

PRESETS: dict[str, ResonatorParams] = {
    # A navigation-grade HRG (PHYSICS.md section 6 and the CETC paper): Q ~ 5e6 at 5.5 kHz,
    # tau 300 s, D 1.6e-4 1/s (58 deg/h p-p drift at K 0.277), a trimmed split of 5 mHz.
    "hrg": ResonatorParams(
        f0_hz=5500.0,
        tau_s=300.0,
        delta_inv_tau_per_s=1.6e-4,
        theta_tau_deg=20.0,
        split_hz=0.005,
        theta_w_deg=10.0,
        bryan_factor=0.277,
        noise_sigma=1e-4,
    ),
    "mems": from_coefficients(
        MASLOV_W_RAD_S,
        gamma=43.029,
        nu=2.029,
        b_c=1.332,
        b_s=-1.389,
        c_m=24.358,
        n=1.173,
        h_c=-12.797,
        h_s=11.588,
        bryan_factor=0.4,
        xi=18.217,
        noise_sigma=1e-3,
    ),
}

#: The HRG without damping anisotropy, split or pickoff noise: whatever drift a whole-angle run shows
#: on it comes from the loops or the measurement (tests/test_wa_drift.py holds it under 0.1 deg/h).
PRESETS["hrg-ideal"] = replace(PRESETS["hrg"], delta_inv_tau_per_s=0.0, split_hz=0.0, noise_sigma=0.0)
#: The HRG as a rate sensor in whole-angle mode (sim-hrg-wa): damping compensated down to a residual
#: drift of 0.02 deg/h, quieter pickoffs (their white angle noise stays under the angle random walk
#: at 0.1 s and up); its drift-rate noise and slow drifts are simulators.physics.noise.NOISE_PRESETS.
PRESETS["hrg-wa"] = replace(PRESETS["hrg"], delta_inv_tau_per_s=1e-7, noise_sigma=1e-6)
#: The CETC self-calibration paper's gyro (sim-hrg-selfcal, docs/selfcal.md): the hrg's Q 5.2e6 and
#: damping anisotropy (58 deg/h drift peak to peak), quiet pickoffs; its noise floor and X/Y gain
#: errors are simulators.physics.noise.NOISE_PRESETS["hrg-selfcal"].
PRESETS["hrg-selfcal"] = replace(PRESETS["hrg"], noise_sigma=1e-6)
#: The same gyro with the loop gain errors the self-calibration's FM identifies (docs/selfcal.md):
#: its pickoff and forcer chains' errors are simulators.physics.errors.ERROR_PRESETS["hrg-selfcal-gains"].
PRESETS["hrg-selfcal-gains"] = PRESETS["hrg-selfcal"]

#: The realistic HRG (sim-hrg-realistic, docs/error_sources.md): the hrg's resonator as one unit of a
#: lot differs from its design: K 0.9 % under the design's 0.277, f0 3.2 Hz over 5500 Hz; quieter
#: pickoffs; its chain errors are simulators.physics.errors.ERROR_PRESETS["hrg-realistic"].
PRESETS["hrg-realistic"] = replace(PRESETS["hrg"], f0_hz=5503.2, bryan_factor=0.2745, noise_sigma=1e-5)
#: The realistic MEMS ring (sim-mems-realistic): Maslov's ring with K 2 % under the thin ring's 0.4
#: and f0 3 Hz over the paper's; its chain errors are ERROR_PRESETS["mems-realistic"].
PRESETS["mems-realistic"] = replace(PRESETS["mems"], f0_hz=PRESETS["mems"].f0_hz + 3.0, bryan_factor=0.392)


def preset(name: str, **overrides: float) -> ResonatorParams:
    """A named preset ("hrg", "mems"), optionally with some parameters changed."""
    try:
        base = PRESETS[name]
    except KeyError:
        raise ParameterError(f"unknown resonator preset {name!r}; known presets: {sorted(PRESETS)}") from None
    unknown = set(overrides) - {f.name for f in fields(ResonatorParams)}
    if unknown:
        raise ParameterError(f"unknown resonator parameter(s) {sorted(unknown)} for preset {name!r}")
    return replace(base, **overrides)
