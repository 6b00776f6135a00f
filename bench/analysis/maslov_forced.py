"""Forced-oscillation identification (Maslov et al. sections 3-4): steady states at N drive
detunings, D_j z = 2 lam_j (p1, -q1, p2, -q2), stacked and solved by least squares; and the
steady-state response of an identified model (for the amplitude-phase plots).

Intervals: the paper's eq. 2.11 assumes i.i.d. equation errors.  Here the error of block j is
the measurement noise e_j of the four slow variables mapped through the model:
r_j = -M_j e_j with M_j = d(D(q) z - y(q))/dq at q_j, so blocks are heteroscedastic (|M_j|
grows with |lam_j|: about 12x in variance across the paper's sweep) and the four equations of a
block are correlated.  `ci95` uses the sandwich covariance C (sum X_j^T M_j M_j^T X_j) C s^2,
with s^2 the noise variance per slow variable estimated from the M-whitened residuals; the
textbook interval is kept in `ci95_textbook`.  Monte-Carlo coverage: benchmarks/maslov_coverage.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.analysis.maslov_result import (
    TWO_PI,
    Identification,
    check_finite_arrays,
    derived_quantities,
    intervals,
    t_quantile,
)
from bench.analysis.maslov_terms import (
    check_model,
    forced_param_names,
    forced_regressor,
    forced_rhs,
    numeric_jacobian,
)
from bench.analysis.slow_model import detuning_term, linear_matrix


@dataclass(frozen=True)
class ForcedResponse:
    """Steady-state slow variables against drive frequency, with the paper's amplitudes and phases:
    A = |(q1, p1)|, B = |(q2, p2)|, phi = atan2(p1, q1), psi = atan2(p2, q2) (x = A cos(wt - phi))."""

    freq_hz: np.ndarray
    q: np.ndarray
    converged: np.ndarray

    @property
    def amp_x(self) -> np.ndarray:
        return np.hypot(self.q[:, 0], self.q[:, 1])

    @property
    def amp_y(self) -> np.ndarray:
        return np.hypot(self.q[:, 2], self.q[:, 3])

    @property
    def phase_x_rad(self) -> np.ndarray:
        return np.arctan2(self.q[:, 1], self.q[:, 0])

    @property
    def phase_y_rad(self) -> np.ndarray:
        return np.arctan2(self.q[:, 3], self.q[:, 2])


@dataclass(frozen=True)
class ForcedIdentification(Identification):
    """Identification from forced steady states; `response(freq_hz)` evaluates the identified model."""

    natural_freq_hz: float = float("nan")
    mu: float = 0.0

    def response(self, freq_hz: np.ndarray, *, q_start: np.ndarray | None = None) -> ForcedResponse:
        """Steady states of the identified model (nonlinear included) at freq_hz, solved in the
        given order by continuation: an upward and a downward list trace the two branches of a
        hysteresis."""
        return steady_states(
            freq_hz, self.vector(), natural_freq_hz=self.natural_freq_hz, model=self.model, mu=self.mu, q_start=q_start
        )


#: bounds on the settling integrations of one `steady_states` call: a model identified from data it
#: does not describe fails Newton almost everywhere (mems-sweep on an HRG ran for 15 minutes)
MAX_SETTLES = 20
MAX_SETTLE_EVALUATIONS = 20_000


class ForcedFitError(ValueError):
    """The identified forced model has no steady state the data support (data it cannot fit)."""


class _Budget:
    """Counts right-hand-side evaluations of one settling integration; raises past the bound."""

    def __init__(self, fun, limit: int, where: str) -> None:
        self.fun, self.left, self.where = fun, limit, where

    def __call__(self, _t: float, x: np.ndarray) -> np.ndarray:
        self.left -= 1
        if self.left < 0:
            raise ForcedFitError(f"{self.where}: the slow dynamics did not settle within {MAX_SETTLE_EVALUATIONS} "
                                 "model evaluations; the data do not fit the forced model")
        return 0.5 * self.fun(x)


def detuning_rad_s(freq_hz: np.ndarray, natural_freq_hz: float) -> np.ndarray:
    """lam = 2 pi (drive - natural) in rad/s (the paper's lam = w0 - w)."""
    return TWO_PI * (np.asarray(freq_hz, dtype=float) - natural_freq_hz)


def steady_states(
    freq_hz: np.ndarray,
    z: np.ndarray,
    *,
    natural_freq_hz: float,
    model: str,
    mu: float = 0.0,
    q_start: np.ndarray | None = None,
    tol: float = 1e-13,
) -> ForcedResponse:
    """Solve 2 dq/dt = 0 of the forced model at each drive frequency, continuing from the previous
    point (the first starts from q_start or the linear solution).  A point where Newton fails is
    settled by integrating the slow dynamics for 30 time constants first, as a real sweep would."""
    from scipy.integrate import solve_ivp  # on first use: loading the procedures skips them (issue 36)
    from scipy.optimize import root

    check_model(model)
    z = np.asarray(z, dtype=float)
    freqs = np.atleast_1d(np.asarray(freq_hz, dtype=float))
    lams = detuning_rad_s(freqs, natural_freq_hz)
    gamma = max(abs(z[0]), 1e-9)
    out = np.empty((freqs.size, 4))
    ok = np.zeros(freqs.size, dtype=bool)
    q = None if q_start is None else np.asarray(q_start, dtype=float)
    settles = 0
    for j, lam in enumerate(lams):

        def fun(x: np.ndarray, lam: float = lam) -> np.ndarray:
            return forced_rhs(x, z, lam, model, mu)

        def jac(x: np.ndarray, fun=fun) -> np.ndarray:
            return numeric_jacobian(fun, x)

        if q is None:
            a2 = 2.0 * linear_matrix(z[:8], lam)
            q = np.linalg.solve(a2, -z[8:12])
        sol = root(fun, q, jac=jac, method="hybr", tol=tol)
        if not sol.success or np.max(np.abs(fun(sol.x))) > 1e-9 * max(1.0, np.max(np.abs(z[8:12]))):
            settles += 1
            if settles > MAX_SETTLES or not (math.isfinite(z[0]) and z[0] > 0):
                raise ForcedFitError(
                    f"the identified model (gamma = {z[0]:.4g} 1/s) has no steady state Newton finds at "
                    f"{settles} of {freqs.size} frequencies (bound {MAX_SETTLES}); the data do not fit the "
                    f"{model} forced model (another kind of gyro, or a sweep that misses the resonance?)"
                )
            rhs = _Budget(fun, MAX_SETTLE_EVALUATIONS, f"{freqs[j]:.6g} Hz")
            settle = solve_ivp(rhs, (0.0, 30.0 / gamma), q, method="LSODA", rtol=1e-8)
            sol = root(fun, settle.y[:, -1], jac=jac, method="hybr", tol=tol)
        q = sol.x
        out[j] = q
        ok[j] = bool(sol.success)
    return ForcedResponse(freq_hz=freqs, q=out, converged=ok)


def identify_forced(
    drive_freq_hz: np.ndarray,
    q1: np.ndarray,
    p1: np.ndarray,
    q2: np.ndarray,
    p2: np.ndarray,
    *,
    natural_freq_hz: float,
    model: str = "cubic",
    mu: float = 0.0,
    bryan_factor: float | None = None,
    level: float = 0.95,
) -> ForcedIdentification:
    """Identify (gamma, nu, b_c, b_s, c_m, n, h_c, h_s, u1..u4[, xi[, kappa]]) from forced steady
    states (eq. 3.4-3.5), least squares as in the paper; mu is the known electrostatic actuator
    nonlinearity (0 for magnetoelectric actuators, the paper's case)."""
    check_model(model)
    n_points = check_finite_arrays(drive_freq_hz=drive_freq_hz, q1=q1, p1=p1, q2=q2, p2=p2)
    try:
        f_nat = float(natural_freq_hz)  # numpy scalars welcome
    except (TypeError, ValueError):
        f_nat = math.nan
    if not (math.isfinite(f_nat) and f_nat > 0):
        raise ValueError(f"natural_freq_hz={natural_freq_hz!r} must be a finite frequency > 0")
    natural_freq_hz = f_nat
    if not math.isfinite(mu):
        raise ValueError(f"mu={mu!r} must be finite")
    if not 0 < level < 1:
        raise ValueError(f"level={level!r} must be in (0, 1)")
    names = forced_param_names(model)
    k = len(names)
    if 4 * n_points <= k:
        raise ValueError(f"{n_points} steady states give {4 * n_points} equations; need more than {k} for {model!r}")
    q = np.stack([q1, p1, q2, p2], axis=-1).astype(float)
    lam = detuning_rad_s(drive_freq_hz, natural_freq_hz)
    x_blocks = forced_regressor(q, model, mu)  # (N, 4, k)
    y_blocks = 2.0 * lam[:, None] * detuning_term(q)  # (N, 4)
    x = x_blocks.reshape(-1, k)
    y = y_blocks.reshape(-1)
    z, *_ = np.linalg.lstsq(x, y, rcond=None)
    resid = (y - x @ z).reshape(-1, 4)
    n_eq = y.size
    dof = n_eq - k
    sigma = math.sqrt(float(resid.ravel() @ resid.ravel()) / dof)
    c = np.linalg.inv(x.T @ x)
    s_p = t_quantile(dof, level)
    se_text = sigma * np.sqrt(np.diag(c))

    # sandwich: r_j = -M_j e_j, e_j ~ N(0, s^2 I)
    m = numeric_jacobian(lambda qq: forced_rhs(qq, z, lam, model, mu), q)  # (N, 4, 4)
    mmt = m @ np.swapaxes(m, -1, -2)
    white = np.linalg.solve(mmt, resid[..., None])[..., 0]
    noise_var = float(np.einsum("ij,ij->", resid, white)) / dof
    xm = np.swapaxes(x_blocks, -1, -2) @ m  # (N, k, 4)
    meat = np.einsum("nka,nla->kl", xm, xm)
    cov = noise_var * c @ meat @ c
    se = np.sqrt(np.diag(cov))

    params = {nm: float(v) for nm, v in zip(names, z, strict=True)}
    return ForcedIdentification(
        model=model,
        method="forced",
        params=params,
        sigma=sigma,
        ci95=intervals(names, z, se, s_p),
        ci95_textbook=intervals(names, z, se_text, s_p),
        sigma_params={nm: float(s) for nm, s in zip(names, se, strict=True)},
        derived=derived_quantities(params, natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor),
        residuals=resid,
        n_equations=n_eq,
        covariance=cov,
        noise_sigma=math.sqrt(noise_var),
        extras={"lam_rad_s": lam, "level": level},
        natural_freq_hz=float(natural_freq_hz),
        mu=float(mu),
    )
