"""Output-error (maximum-likelihood) identification of a free decay: fit the slow-variable model's
trajectory q(t; q0, z) to the samples (docs/free_decay_identification.md).

Under white pickoff noise of one std s on each slow variable the likelihood is maximised by the
least squares of the samples minus the trajectory, over the initial state q0 and the parameters z
(gamma, nu, b_c, b_s, c_m, n, h_c, h_s[, xi[, kappa]]).  The linear model has the closed form
q(t) = expm(A t) q0 (A = linear_matrix(z), which holds the 1/2 of 2 dq/dt); its Jacobian comes
exactly from the augmented system d/dt (q, dq/dz_j) = [[A, 0], [B_j, A]] (q, dq/dz_j), whose
exponential carries the Frechet derivative of expm, stepped exactly with powers of its expm at the
sample step (uniform samples).  The nonlinear models integrate the same sensitivity equations with
J(q) = d(dq/dt)/dq.  Levenberg-Marquardt from the equation-error estimate, bounded iterations;
intervals from the Fisher information at the optimum (or a Newey-West sandwich for coloured noise).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy.linalg import expm

from bench.analysis.free_decay_rk import rk4_sensitivities, substeps_for
from bench.analysis.maslov_result import Identification, derived_quantities, intervals, t_quantile
from bench.analysis.maslov_terms import check_model, free_param_names
from bench.analysis.slow_model import linear_matrix

Q0_NAMES = ("q1_0", "p1_0", "q2_0", "p2_0")
COVARIANCES = ("fisher", "sandwich")
_POWERS_BLOCK = 512  # samples per block of the exact linear propagation
_ROT_INDEX = np.array([2, 3, 0, 1])  # G q = (-q2, -p2, q1, p1): d/dpsi of simulators' rotate_wave at 0
_ROT_SIGN = np.array([-1.0, -1.0, 1.0, 1.0])
_B = np.stack([linear_matrix(np.eye(8)[j]) for j in range(8)])  # dA/dz_j, (8, 4, 4)


class FreeDecayFitError(ValueError):
    """The output-error fit did not converge (or its model could not be integrated)."""


def _powers(phi: np.ndarray, n: int) -> np.ndarray:
    """phi^1 .. phi^n, shape (n, m, m), by doubling."""
    out = np.empty((n,) + phi.shape)
    out[0] = phi
    have = 1
    while have < n:
        take = min(have, n - have)
        out[have : have + take] = out[:take] @ out[have - 1]
        have += take
    return out


def linear_sensitivities(z: np.ndarray, q0: np.ndarray, n: int, dt_s: float,
                         params: tuple[int, ...] = tuple(range(8))) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact trajectory of dq/dt = A(z) q at t = k dt, k = 0..n-1, and its sensitivities.

    Returns (q (n, 4), dq/dq0 = Phi(t) (n, 4, 4), dq/dz_j (n, 4, len(params))) for the linear
    coefficients indexed by `params`, from powers of expm(big dt), big = [[A, 0], [B_j, A]]."""
    a = linear_matrix(np.asarray(z, dtype=float)[:8])
    p = len(params)
    dim = 4 * (p + 1)
    big = np.zeros((dim, dim))
    for b in range(p + 1):
        big[4 * b : 4 * b + 4, 4 * b : 4 * b + 4] = a
    for j, idx in enumerate(params):
        big[4 * (j + 1) : 4 * (j + 2), 0:4] = _B[idx]
    step = expm(big * dt_s)
    blk = max(1, min(_POWERS_BLOCK, n - 1))
    pw = np.concatenate([np.eye(dim)[None], _powers(step, blk)])  # P^0 .. P^blk
    x = np.zeros(dim)
    x[:4] = q0
    phi = np.eye(4)
    out_x = np.empty((n, dim))
    out_phi = np.empty((n, 4, 4))
    flat = pw[:blk].reshape(blk * dim, dim)
    top = np.ascontiguousarray(pw[:blk, :4, :4]).reshape(blk * 4, 4)
    for start in range(0, n, blk):
        take = min(blk, n - start)
        out_x[start : start + take] = (flat[: take * dim] @ x).reshape(take, dim)
        out_phi[start : start + take] = (top[: take * 4] @ phi).reshape(take, 4, 4)
        x = pw[take] @ x
        phi = pw[take, :4, :4] @ phi
    sens = out_x[:, 4:].reshape(n, p, 4).transpose(0, 2, 1)
    return out_x[:, :4], out_phi, sens


_DA = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, -1], [0, 0, 1, 0]], dtype=float)  # a = DA q
_DB = np.array([[0, 0, -1, 0], [0, 0, 0, -1], [1, 0, 0, 0], [0, 1, 0, 0]], dtype=float)  # b = DB q


def nonlinear_parts(q: np.ndarray, xi: float, kappa: float, quintic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N(q) (4, m), N(q) z_nl, d(N(q) z_nl)/dq (4, 4)) for one state, m = 1 (xi) or 2 (xi, kappa).

    slow_model.k_cubic = a e + b X/2 and k_quintic = a s + b c with a = DA q, b = DB q, E = |q|^2,
    X = p2 q1 - p1 q2, e = 3E/4, s = 5E^2/8 - X^2/2, c = X E/2 (scalar closed form, per RHS call)."""
    q1, p1, q2, p2 = q
    a, b = _DA @ q, _DB @ q
    energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
    x = p2 * q1 - p1 * q2
    dx = np.array([p2, -q2, -p1, q1])
    cols = [a * (0.75 * energy) + b * (0.5 * x)]
    ca, cb = xi * 0.75 * energy, xi * 0.5 * x  # N z_nl = a ca + b cb
    ga, gb = (1.5 * xi) * q, (0.5 * xi) * dx  # their gradients
    if quintic:
        s5, c5 = 0.625 * energy * energy - 0.5 * x * x, 0.5 * x * energy
        cols.append(a * s5 + b * c5)
        ca, cb = ca + kappa * s5, cb + kappa * c5
        ga = ga + kappa * (2.5 * energy * q - x * dx)
        gb = gb + kappa * (0.5 * energy * dx + x * q)
    return np.array(cols).T, a * ca + b * cb, np.outer(a, ga) + ca * _DA + np.outer(b, gb) + cb * _DB


def _uniform(t: np.ndarray) -> bool:
    """The sample times are equally spaced (to 1e-9 of a step)."""
    d = np.diff(t)
    return bool(d[0] > 0 and np.max(np.abs(d - d[0])) <= 1e-9 * d[0])


def nonlinear_sensitivities(z: np.ndarray, q0: np.ndarray, t_s: np.ndarray, model: str, *,
                            jac: bool = True, rtol: float = 1e-9) -> tuple[np.ndarray, np.ndarray | None]:
    """Integrated trajectory of dq/dt = A q + N(q) z_nl / 2 at t_s (t_s[0] = start) and, with
    jac, its sensitivities (n, 4, 4 + k) to (q0, z) by the sensitivity equations
    dS/dt = J(q) S + df/dtheta, S(0) = [I | 0]: compiled fixed-step RK4 on a uniform grid
    (`free_decay_rk`), DOP853 at rtol otherwise."""
    z = np.asarray(z, dtype=float)
    a = linear_matrix(z[:8])
    z_nl = z[8:]
    k = z.size
    p = 4 + k

    xi = float(z_nl[0])
    quintic = model == "quintic"
    kappa = float(z_nl[1]) if quintic else 0.0
    b_t = np.ascontiguousarray(_B.transpose(1, 0, 2)).reshape(32, 4)  # rows (a, j): (B_j q)_a = b_t q

    a_half = 0.5 * xi
    k_half = 0.5 * kappa

    def parts(q: np.ndarray) -> tuple[list, list, np.ndarray]:
        """nonlinear_parts in Python scalars (the RHS is called ~1e4 times per integration):
        (columns N(q) as rows [a][c], N z_nl / 2, J = A + d(N z_nl / 2)/dq)."""
        q1, p1, q2, p2 = q.tolist()
        av = (-p1, q1, -p2, q2)
        bv = (-q2, -p2, q1, p1)
        energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
        x = p2 * q1 - p1 * q2
        dx = (p2, -q2, -p1, q1)
        qv = (q1, p1, q2, p2)
        e3, x2 = 0.75 * energy, 0.5 * x
        ca, cb = a_half * e3, a_half * x2
        ga = [1.5 * a_half * v for v in qv]
        gb = [0.5 * a_half * v for v in dx]
        cols = [[av[i] * e3 + bv[i] * x2] for i in range(4)]
        if quintic:
            s5, c5 = 0.625 * energy * energy - 0.5 * x * x, 0.5 * x * energy
            for i in range(4):
                cols[i].append(av[i] * s5 + bv[i] * c5)
            ca, cb = ca + k_half * s5, cb + k_half * c5
            ga = [g + k_half * (2.5 * energy * qv[j] - x * dx[j]) for j, g in enumerate(ga)]
            gb = [g + k_half * (0.5 * energy * dx[j] + x * qv[j]) for j, g in enumerate(gb)]
        nz = [av[i] * ca + bv[i] * cb for i in range(4)]
        jm = a + np.array([[av[i] * ga[j] + bv[i] * gb[j] for j in range(4)] for i in range(4)])
        jm += ca * _DA + cb * _DB
        return cols, nz, jm

    def rhs_q(_t: float, q: np.ndarray) -> np.ndarray:
        return a @ q + 0.5 * nonlinear_parts(q, xi, kappa, quintic)[1]

    def rhs_full(_t: float, y: np.ndarray) -> np.ndarray:
        q = y[:4]
        cols, nz, jm = parts(q)
        out = np.empty_like(y)
        out[:4] = a @ q
        out[:4] += nz
        ds = jm @ y[4:].reshape(4, p)
        ds[:, 4:12] += (b_t @ q).reshape(4, 8)
        ds[:, 12:] += 0.5 * np.array(cols)
        out[4:] = ds.ravel()
        return out

    t = np.asarray(t_s, dtype=float)
    if t.size > 1 and _uniform(t):
        dt = float(t[1] - t[0])
        steps = substeps_for(a, xi, kappa, np.asarray(q0, dtype=float), dt)
        q, s = rk4_sensitivities(a, _B, xi, kappa, quintic, np.asarray(q0, dtype=float), t.size, dt, steps, jac)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
            raise FreeDecayFitError(f"model={model!r} could not be integrated over the record (non-finite state)")
        return q, (s if jac else None)
    scale = float(np.max(np.abs(q0))) or 1.0
    if jac:
        y0 = np.concatenate([q0, np.hstack([np.eye(4), np.zeros((4, k))]).ravel()])
        fun = rhs_full
    else:
        y0 = np.asarray(q0, dtype=float)
        fun = rhs_q
    from scipy.integrate import solve_ivp  # on first use: loading the procedures skips it (issue 36)

    sol = solve_ivp(fun, (t[0], t[-1]), y0, t_eval=t, method="DOP853", rtol=rtol, atol=1e-13 * scale,
                    first_step=float(t[1] - t[0]) if t.size > 1 else None)
    if not sol.success or sol.y.shape[1] != t.size or not np.all(np.isfinite(sol.y)):
        raise FreeDecayFitError(f"model={model!r} could not be integrated over the record: {sol.message}")
    y = sol.y.T
    return y[:, :4].copy(), (y[:, 4:].reshape(-1, 4, p) if jac else None)


def trajectory(t_s: np.ndarray, q0: np.ndarray, z: np.ndarray, model: str, *,
               jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Model trajectory at uniform t_s (from t_s[0]) and its Jacobian (n, 4, 4 + k) to (q0, z)."""
    t = np.asarray(t_s, dtype=float)
    if model == "linear":
        dt = float(t[1] - t[0])
        q, phi, sens = linear_sensitivities(z, q0, t.size, dt)
        return q, (np.concatenate([phi, sens], axis=-1) if jac else None)
    return nonlinear_sensitivities(z, q0, t, model, jac=jac)


def _newey_west(scores: np.ndarray, lags: int) -> np.ndarray:
    """sum of Bartlett-weighted autocovariances of the per-sample scores (n, p)."""
    meat = scores.T @ scores
    for lag in range(1, lags + 1):
        g = scores[lag:].T @ scores[:-lag]
        meat += (1.0 - lag / (lags + 1.0)) * (g + g.T)
    return meat


def output_error_fit(t_s: np.ndarray, q: np.ndarray, start: np.ndarray, *, model: str = "linear",
                     covariance: str = "fisher", max_iter: int = 50, sandwich_lags: int | None = None,
                     q0_start: np.ndarray | None = None, rotation_basis: np.ndarray | None = None) -> dict:
    """Levenberg-Marquardt least squares of the samples q (n, 4) minus the model trajectory.

    rotation_basis (n, m): known functions h_j(t) of an output rotation psi(t) = sum_j c_j h_j(t)
    (electrical angle, as a table's angle ripple turns the measured wave), the c_j fitted too:
    the measurement is q(t) + psi(t) G q(t) with G q = (-q2, -p2, q1, p1), psi small.

    start: z from the equation-error fit; q0 starts at the least squares of the samples for that z
    (linear in q0 for the linear model) or at q0_start / the first sample.  Stops when the step is
    below 1e-6 standard errors (in chi^2) or raises FreeDecayFitError after max_iter iterations."""
    check_model(model)
    if covariance not in COVARIANCES:
        raise ValueError(f"covariance={covariance!r} is not one of {COVARIANCES}")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter={max_iter!r} must be at least 1")
    t = np.asarray(t_s, dtype=float)
    t = t - t[0]
    y = np.asarray(q, dtype=float)
    n = y.shape[0]
    z = np.asarray(start, dtype=float).copy()
    k = z.size
    h = None if rotation_basis is None else np.asarray(rotation_basis, dtype=float)
    if h is not None:
        h = h[:, None] if h.ndim == 1 else h
        if h.ndim != 2 or h.shape[0] != n:
            raise ValueError(f"rotation_basis has shape {np.shape(rotation_basis)}; expected ({n}, m)")
        if not np.all(np.isfinite(h)):
            raise ValueError("rotation_basis contains non-finite values")
    m_rot = 0 if h is None else h.shape[1]
    p = 4 + k + m_rot
    dof = 4 * n - p
    if dof <= 0:
        raise ValueError(f"{n} samples give {4 * n} values; need more than the {p} unknowns of {model!r}")
    if q0_start is not None:
        q0 = np.asarray(q0_start, dtype=float).copy()
    elif model == "linear":
        _, phi, _ = linear_sensitivities(z, np.zeros(4), n, float(t[1]), params=())
        q0 = np.linalg.lstsq(phi.reshape(4 * n, 4), y.reshape(-1), rcond=None)[0]
    else:
        q0 = y[0].copy()
    theta = np.concatenate([q0, z, np.zeros(m_rot)])

    def evaluate(th: np.ndarray, with_jac: bool):
        traj, jac = trajectory(t, th[:4], th[4 : 4 + k], model, jac=with_jac)
        if h is not None:
            psi = h @ th[4 + k :]
            gq = traj[:, _ROT_INDEX] * _ROT_SIGN
            if with_jac:
                gjac = jac[:, _ROT_INDEX, :] * _ROT_SIGN[:, None]
                jac = np.concatenate([jac + psi[:, None, None] * gjac, gq[:, :, None] * h[:, None, :]], axis=-1)
            traj = traj + psi[:, None] * gq
        r = y - traj
        return r, float(np.einsum("ia,ia->", r, r)), jac

    r, ss, jac = evaluate(theta, True)
    lam = 1e-3
    converged = False
    iterations = 0
    for iterations in range(1, int(max_iter) + 1):  # noqa: B007 - the count is reported
        jf = jac.reshape(4 * n, p)
        jtj = jf.T @ jf
        g = jf.T @ r.reshape(-1)
        scale = np.sqrt(np.diag(jtj))
        scale[scale == 0] = 1.0
        ns = jtj / np.outer(scale, scale)
        gs = g / scale
        s2 = ss / dof
        try:
            gn = np.linalg.solve(ns, gs)
        except np.linalg.LinAlgError:
            gn = np.linalg.lstsq(ns, gs, rcond=None)[0]
        if float(gs @ gn) < 1e-8 * s2:  # the Gauss-Newton step would lower chi^2 by < 1e-8: at the optimum
            converged = True
            break
        accepted = False
        for _ in range(16):
            step = np.linalg.solve(ns + lam * np.diag(np.diag(ns)), gs) / scale
            try:  # the nonlinear models integrate the Jacobian with the trial (reused when accepted)
                trial = evaluate(theta + step, model != "linear")
            except FreeDecayFitError:
                trial = (None, math.inf, None)
            ss_new = trial[1]
            if ss_new <= ss:
                accepted = True
                break
            if float(gs @ gn) < 1e-3 * s2:  # within the integration's rounding of the optimum: its
                break  # Gauss-Newton step is under 0.03 standard errors
            lam *= 10.0
        if not accepted and float(gs @ gn) < 1e-3 * s2:
            converged = True
            break
        if not accepted:
            raise FreeDecayFitError(f"output-error fit of model={model!r} stalled after {iterations} iterations "
                                    f"(no step lowers the residual sum of squares {ss:.6g})")
        theta = theta + step
        decrease = ss - ss_new
        lam = max(lam / 10.0, 1e-9)
        r, ss, jac = trial if trial[2] is not None else evaluate(theta, True)
        if decrease < 1e-8 * s2:
            converged = True
            break
    if not converged:
        raise FreeDecayFitError(f"output-error fit of model={model!r} did not converge in max_iter={max_iter} "
                                f"iterations (residual sum of squares {ss:.6g})")
    jf = jac.reshape(4 * n, p)
    jtj = jf.T @ jf
    try:
        inv = np.linalg.inv(jtj)
    except np.linalg.LinAlgError as exc:
        raise FreeDecayFitError(f"output-error fit of model={model!r}: singular Fisher information ({exc})") from exc
    s2 = ss / dof
    cov_fisher = s2 * inv
    if covariance == "sandwich":
        lags = int(sandwich_lags) if sandwich_lags is not None else int(math.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)))
        scores = np.einsum("iap,ia->ip", jac, r)
        cov = inv @ _newey_west(scores, max(lags, 0)) @ inv * (4 * n / dof)
    else:
        cov = cov_fisher
    return {"theta": theta, "cov": cov, "cov_fisher": cov_fisher, "resid": r, "ss": ss, "dof": dof,
            "iterations": iterations, "lambda": lam}


def identification_from_oe(fit: dict, model: str, *, detuning_hz: float, level: float,
                           natural_freq_hz: float | None, bryan_factor: float | None,
                           start: Mapping[str, float], dt_s: float, covariance: str) -> Identification:
    """The OE fit as the same `Identification` as the equation-error fit (ci95 from the chosen
    covariance, ci95_textbook from the Fisher information)."""
    names = free_param_names(model)
    k = len(names)
    theta, cov_full = fit["theta"], fit["cov"]
    z_rep = theta[4 : 4 + k].copy()
    z_rep[4] += 2.0 * (2.0 * math.pi * detuning_hz)
    cov = cov_full[4 : 4 + k, 4 : 4 + k]
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    se_f = np.sqrt(np.maximum(np.diag(fit["cov_fisher"][4 : 4 + k, 4 : 4 + k]), 0.0))
    s_p = t_quantile(fit["dof"], level)
    params = {nm: float(v) for nm, v in zip(names, z_rep, strict=True)}
    sigma = math.sqrt(fit["ss"] / fit["dof"])
    return Identification(
        model=model,
        method="free_decay_output_error",
        params=params,
        sigma=sigma,
        ci95=intervals(names, z_rep, se, s_p),
        ci95_textbook=intervals(names, z_rep, se_f, s_p),
        sigma_params={nm: float(s) for nm, s in zip(names, se, strict=True)},
        derived=derived_quantities(params, natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor),
        residuals=fit["resid"],
        n_equations=int(fit["resid"].size),
        covariance=cov,
        noise_sigma=sigma,
        extras={"dt_s": dt_s, "level": level, "q0": theta[:4].copy(), "covariance_full": cov_full,
                "rotation_coefficients": theta[4 + k :].copy(),
                "covariance_kind": covariance, "iterations": fit["iterations"], "start": dict(start)},
    )
