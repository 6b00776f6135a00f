"""Compiled (numba) DOP853 of the nonlinear averaged resonator: a World block in one call.

The resonator with cubic or quintic stiffness (the MEMS ring) has no exact step; it was integrated
by scipy's `solve_ivp(method="DOP853")` with a Python right-hand side, ~0.6 ms of interpreter
overhead per 50 ms loop block (more than half of a MEMS thermal run's CPU; issue 36).  This is the
same method step for step: Dormand and Prince's 8(5,3) pair with scipy's own tableau (passed in
from `scipy.integrate._ivp.dop853_coefficients`, not restated here), scipy's step-size control
(safety 0.9, factors 0.2-10, error exponent -1/8, the 5th/3rd-order blended error norm), its
minimum step and its 7th-order dense output at the sample instants.  Only the arithmetic's order
differs (loops instead of BLAS dot products), so the states agree with scipy's to rounding (the
test holds them within 1e-12 of the amplitude), far inside the integrator's own tolerance.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys
import types
from pathlib import Path

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources

_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERROR_EXPONENT = -1.0 / 8.0  # -1 / (error estimator order 7 + 1)
N_STAGES = 12
N_STAGES_EXTENDED = 16
TOO_SMALL_STEP = -1


@njit(cache=True)
def _rhs(q: np.ndarray, a: np.ndarray, half_u: np.ndarray, half_xi: float, half_kappa: float,
         out: np.ndarray) -> None:
    """out = A q + u/2 + xi/2 k_cubic(q) + kappa/2 k_quintic(q) (bench.analysis.slow_model)."""
    q1, p1, q2, p2 = q[0], q[1], q[2], q[3]
    for i in range(4):
        out[i] = a[i, 0] * q1 + a[i, 1] * p1 + a[i, 2] * q2 + a[i, 3] * p2 + half_u[i]
    energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
    cross = p2 * q1 - p1 * q2
    ca = half_xi * 0.75 * energy  # the terms multiplying (-p1, q1, -p2, q2) and (-q2, -p2, q1, p1)
    cb = half_xi * 0.5 * cross
    if half_kappa != 0.0:
        ca += half_kappa * (0.625 * energy * energy - 0.5 * cross * cross)
        cb += half_kappa * (0.5 * cross * energy)
    out[0] += -p1 * ca - q2 * cb
    out[1] += q1 * ca - p2 * cb
    out[2] += -p2 * ca + q1 * cb
    out[3] += q2 * ca + p1 * cb


@njit(cache=True)
def _stage_state(k: np.ndarray, s: int, coeffs: np.ndarray, h: float, y: np.ndarray, ys: np.ndarray) -> None:
    """ys = y + h sum_j<s coeffs[j] k[j] (scipy's `y + np.dot(K[:s].T, a[:s]) * h`)."""
    for i in range(4):
        acc = 0.0
        for j in range(s):
            acc += k[j, i] * coeffs[j]
        ys[i] = y[i] + acc * h


@njit(cache=True)
def nonlinear_block(a: np.ndarray, half_u: np.ndarray, half_xi: float, half_kappa: float, q0: np.ndarray,
                    dt: float, n: int, rtol: float, atol: float, tab_a: np.ndarray, tab_b: np.ndarray,
                    e3: np.ndarray, e5: np.ndarray, tab_d: np.ndarray, out: np.ndarray) -> int:
    """The states at dt, 2 dt, ..., n dt from q0 into out (n, 4); the first step is dt.  tab_*, e3, e5:
    scipy's DOP853 tableau (A 16x16, B, E3, E5, D 4x16; the model is autonomous: no C).  Returns the number of accepted
    steps, or TOO_SMALL_STEP when the step fell under scipy's minimum (out is then incomplete)."""
    k = np.empty((N_STAGES_EXTENDED, 4))
    f = np.empty(4)
    y = q0.copy()
    y_new = np.empty(4)
    ys = np.empty(4)
    big_f = np.empty((7, 4))
    _rhs(y, a, half_u, half_xi, half_kappa, f)
    t = 0.0
    t_bound = n * dt
    h_abs = dt
    sample = 0
    steps = 0
    while t != t_bound:
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        if h_abs < min_step:
            h_abs = min_step
        step_rejected = False
        while True:
            if h_abs < min_step:
                return TOO_SMALL_STEP
            t_new = t + h_abs
            if t_new - t_bound > 0.0:
                t_new = t_bound
            h = t_new - t
            h_abs = abs(h)
            # rk_step: the 12 stages, the 8th-order solution and its derivative as stage 13
            for i in range(4):
                k[0, i] = f[i]
            for s in range(1, N_STAGES):
                _stage_state(k, s, tab_a[s], h, y, ys)
                _rhs(ys, a, half_u, half_xi, half_kappa, k[s])
            for i in range(4):
                acc = 0.0
                for j in range(N_STAGES):
                    acc += k[j, i] * tab_b[j]
                y_new[i] = y[i] + h * acc
            _rhs(y_new, a, half_u, half_xi, half_kappa, k[N_STAGES])
            # the blended 5th/3rd-order error norm
            err5_2 = 0.0
            err3_2 = 0.0
            for i in range(4):
                scale = atol + max(abs(y[i]), abs(y_new[i])) * rtol
                acc5 = 0.0
                acc3 = 0.0
                for j in range(N_STAGES + 1):
                    acc5 += k[j, i] * e5[j]
                    acc3 += k[j, i] * e3[j]
                err5_2 += (acc5 / scale) ** 2
                err3_2 += (acc3 / scale) ** 2
            err5_2 = math.sqrt(err5_2) ** 2  # as np.linalg.norm(err5) ** 2
            err3_2 = math.sqrt(err3_2) ** 2
            if err5_2 == 0.0 and err3_2 == 0.0:
                error_norm = 0.0
            else:
                error_norm = abs(h) * err5_2 / math.sqrt((err5_2 + 0.01 * err3_2) * 4)
            if error_norm < 1.0:
                if error_norm == 0.0:
                    factor = _MAX_FACTOR
                else:
                    factor = min(_MAX_FACTOR, _SAFETY * error_norm ** _ERROR_EXPONENT)
                if step_rejected:
                    factor = min(1.0, factor)
                h_abs *= factor
                break
            factor = _SAFETY * error_norm ** _ERROR_EXPONENT
            if not factor > _MIN_FACTOR:  # also a NaN norm, as Python's max(0.2, nan) in scipy
                factor = _MIN_FACTOR
            h_abs *= factor
            step_rejected = True
        steps += 1
        t_old = t
        t = t_new
        # the samples this step reached, from its dense output (scipy's t_eval)
        if sample < n and dt * (sample + 1) <= t:
            for s in range(N_STAGES + 1, N_STAGES_EXTENDED):
                _stage_state(k, s, tab_a[s], h, y, ys)
                _rhs(ys, a, half_u, half_xi, half_kappa, k[s])
            for i in range(4):
                delta = y_new[i] - y[i]
                big_f[0, i] = delta
                big_f[1, i] = h * k[0, i] - delta
                big_f[2, i] = 2.0 * delta - h * (k[N_STAGES, i] + k[0, i])
                for m in range(4):
                    acc = 0.0
                    for j in range(N_STAGES_EXTENDED):
                        acc += tab_d[m, j] * k[j, i]
                    big_f[3 + m, i] = h * acc
            span = t - t_old
            while sample < n and dt * (sample + 1) <= t:
                x = (dt * (sample + 1) - t_old) / span
                for i in range(4):
                    v = 0.0
                    for m in range(7):
                        v += big_f[6 - m, i]
                        if m % 2 == 0:
                            v *= x
                        else:
                            v *= 1.0 - x
                    out[sample, i] = v + y[i]
                sample += 1
        for i in range(4):
            y[i] = y_new[i]
            f[i] = k[N_STAGES, i]
    return steps


def tableau() -> tuple[np.ndarray, ...]:
    """scipy's DOP853 tableau (A, B, E3, E5, D) as contiguous arrays, loaded on first use.

    Its module (numbers and numpy only) is loaded from scipy's file alone: importing it the usual
    way runs scipy.integrate's package `__init__` (~0.44 s CPU of every MEMS run's process) for
    nothing else; when scipy.integrate is already imported, or the file is not where scipy keeps
    it, the ordinary import serves."""
    global _TABLEAU
    if _TABLEAU is None:
        c = _coefficients_module()
        _TABLEAU = tuple(np.ascontiguousarray(x, dtype=float) for x in (c.A, c.B, c.E3, c.E5, c.D))
    return _TABLEAU


def _coefficients_module() -> types.ModuleType:
    """scipy.integrate._ivp.dop853_coefficients, without scipy.integrate's package when it is not loaded."""
    name = "scipy.integrate._ivp.dop853_coefficients"
    if name in sys.modules or "scipy.integrate" in sys.modules:
        return importlib.import_module(name)
    import scipy

    path = Path(scipy.__path__[0]) / "integrate" / "_ivp" / "dop853_coefficients.py"
    spec = importlib.util.spec_from_file_location("_gyrobench_dop853_coefficients", path)
    if spec is None or spec.loader is None or not path.is_file():
        return importlib.import_module(name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_TABLEAU: tuple[np.ndarray, ...] | None = None


def integrate_block(a: np.ndarray, u: np.ndarray, xi: float, kappa: float, q0: np.ndarray, dt: float, n: int,
                    *, rtol: float = 1e-9, atol: float = 1e-12) -> np.ndarray:
    """dq/dt = A q + u/2 + xi/2 k_cubic(q) + kappa/2 k_quintic(q) from q0, sampled at dt .. n dt: (n, 4)."""
    tab_a, tab_b, e3, e5, tab_d = tableau()
    out = np.empty((n, 4))
    steps = nonlinear_block(np.ascontiguousarray(a, dtype=float), 0.5 * np.asarray(u, dtype=float), 0.5 * xi,
                            0.5 * kappa, np.asarray(q0, dtype=float), float(dt), int(n), float(rtol), float(atol),
                            tab_a, tab_b, e3, e5, tab_d, out)
    if steps == TOO_SMALL_STEP or not np.all(np.isfinite(out)):  # the old solve_ivp path's two checks
        raise RuntimeError("resonator integration failed: the required step fell under its minimum"
                           if steps == TOO_SMALL_STEP else "resonator integration failed: a state is not finite")
    return out
