"""Regressor terms of Maslov et al. (2022): the averaged nonlinear and forcing terms, as printed
and as derived here, so the identification code and the tests share one definition.

Conventions (PHYSICS.md section 2): q = (q1, p1, q2, p2), c_m, n, h_c, h_s, xi, kappa already
divided by w (rad/s).  Findings against the printed paper, each checked in tests/test_maslov_terms.py:
- k1..k4 (cubic) are printed correctly.
- k5..k8 (quintic) are printed with prefactor 1/16; averaging kappa (f^2+g^2)^2 f gives 1/8
  (consistent with the paper's own eqs. 5.5/5.9 and 5.6/5.10).  In k6 a parenthesis closes after
  the lone q1 instead of after the last factor: "... + q1)(p2^4 + ...)" must read
  "... + q1 (p2^4 + ...))".  With both fixed the printed terms equal `slow_model.k_quintic`.
- k9..k14 (electrostatic actuator nonlinearity mu, eq. 3.2) are printed correctly: averaging the
  forcing eta (1 + 3 mu f^2)(-u1 sin wt + u2 cos wt) gives u1 (1 + mu k11) + mu u2 k9 and
  u2 (1 + mu k12) + mu u1 k9 (and the same with f -> g, 1,2 -> 3,4, k9 -> k10).  The block form
  after eq. 3.3 writes "D_u = E + alpha D_n": alpha there is mu.
- eq. 2.8 drops the factor 1/2 of eq. 2.7; eqs. 5.7-5.10 write alpha where the damping axis beta
  belongs in the b_m terms; the number of equations of the free-decay fit is 4 (N - 1), not
  4 (N - 2).
"""

from __future__ import annotations

import numpy as np

from bench.analysis.slow_model import LINEAR_PARAM_NAMES, detuning_term, k_cubic, k_quintic, regressor_linear

MODELS = ("linear", "cubic", "quintic")
FORCING_NAMES = ("u1", "u2", "u3", "u4")


def check_model(model: str) -> None:
    """Raise on an unknown model name (before any computation)."""
    if model not in MODELS:
        raise ValueError(f"model={model!r} is not one of {MODELS}")


def nonlinear_names(model: str) -> tuple[str, ...]:
    """Names of the nonlinearity coefficients a model carries."""
    check_model(model)
    return {"linear": (), "cubic": ("xi",), "quintic": ("xi", "kappa")}[model]


def nonlinear_columns(q: np.ndarray, model: str) -> np.ndarray:
    """Columns multiplying xi (and kappa) in 2 dq/dt: shape (..., 4, 0|1|2)."""
    q = np.asarray(q, dtype=float)
    cols = []
    if model in ("cubic", "quintic"):
        cols.append(k_cubic(q))
    if model == "quintic":
        cols.append(k_quintic(q))
    if not cols:
        return np.zeros(q.shape[:-1] + (4, 0))
    return np.stack(cols, axis=-1)


def k_electrostatic(q: np.ndarray) -> np.ndarray:
    """k9..k14 of eq. 3.2 (printed correctly), shape (..., 6)."""
    q = np.asarray(q, dtype=float)
    q1, p1, q2, p2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            -1.5 * q1 * p1,
            -1.5 * q2 * p2,
            0.75 * (3 * p1 * p1 + q1 * q1),
            0.75 * (p1 * p1 + 3 * q1 * q1),
            0.75 * (3 * p2 * p2 + q2 * q2),
            0.75 * (p2 * p2 + 3 * q2 * q2),
        ],
        axis=-1,
    )


def forcing_block(q: np.ndarray, mu: float = 0.0) -> np.ndarray:
    """D_u = I + mu D_n(q): the columns multiplying (u1, u2, u3, u4) in 2 dq/dt, shape (..., 4, 4)."""
    q = np.asarray(q, dtype=float)
    out = np.broadcast_to(np.eye(4), q.shape[:-1] + (4, 4)).copy()
    if mu:
        k9, k10, k11, k12, k13, k14 = np.moveaxis(k_electrostatic(q), -1, 0)
        dn = np.zeros(q.shape[:-1] + (4, 4))
        dn[..., 0, 0], dn[..., 0, 1], dn[..., 1, 0], dn[..., 1, 1] = k11, k9, k9, k12
        dn[..., 2, 2], dn[..., 2, 3], dn[..., 3, 2], dn[..., 3, 3] = k13, k10, k10, k14
        out = out + mu * dn
    return out


def free_regressor(q: np.ndarray, model: str) -> np.ndarray:
    """D(q) = (Dg | k_cubic | k_quintic) of eq. 2.6, shape (..., 4, 8 + 0|1|2)."""
    return np.concatenate([regressor_linear(q), nonlinear_columns(q, model)], axis=-1)


def forced_regressor(q: np.ndarray, model: str, mu: float = 0.0) -> np.ndarray:
    """D(q) = (Dg | D_u | k_cubic | k_quintic) of eq. 3.3, shape (..., 4, 12 + 0|1|2)."""
    return np.concatenate([regressor_linear(q), forcing_block(q, mu), nonlinear_columns(q, model)], axis=-1)


def free_param_names(model: str) -> tuple[str, ...]:
    return LINEAR_PARAM_NAMES + nonlinear_names(model)


def forced_param_names(model: str) -> tuple[str, ...]:
    return LINEAR_PARAM_NAMES + FORCING_NAMES + nonlinear_names(model)


def forced_rhs(q: np.ndarray, z: np.ndarray, lam_rad_s: np.ndarray | float, model: str, mu: float = 0.0) -> np.ndarray:
    """2 dq/dt of the forced model (eq. 3.3) with parameter vector z; zero at a steady state."""
    q = np.asarray(q, dtype=float)
    lam = np.asarray(lam_rad_s, dtype=float)[..., None]
    return forced_regressor(q, model, mu) @ np.asarray(z, dtype=float) - 2.0 * lam * detuning_term(q)


#: the central differences' eight displacements, +e_m then -e_m (unit steps), one per leading row
_STEPS = np.concatenate([np.eye(4), -np.eye(4)])


def numeric_jacobian(fun, q: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """d fun / d q by central differences for states q (..., 4) -> (..., 4, 4); fun is vectorised.
    The eight displaced states go to fun in one call (shape (8, ..., 4)): a Newton step of the
    forced model's steady states on one state was eight calls of small-array overhead (issue 36)."""
    q = np.asarray(q, dtype=float)
    shifted = q + (step * _STEPS).reshape((8,) + (1,) * (q.ndim - 1) + (4,))
    f = np.asarray(fun(shifted))
    return np.stack([(f[m] - f[4 + m]) / (2.0 * step) for m in range(4)], axis=-1)


# ----------------------------------------------------------------------------------------------
# The quintic terms exactly as printed (kept to document the typos; never used to identify)


def k_quintic_printed(q: np.ndarray, *, fix_k6_parenthesis: bool = False) -> np.ndarray:
    """k5..k8 as printed in the paper (prefactor 1/16).  With fix_k6_parenthesis the misplaced
    parenthesis of k6 is moved to where the algebra needs it."""
    q = np.asarray(q, dtype=float)
    q1, p1, q2, p2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    k5 = -(1 / 16) * (
        5 * p1**5
        + 12 * p1**2 * p2 * q1 * q2
        + 4 * p2 * q1 * q2 * (p2**2 + q1**2 + q2**2)
        + 2 * p1**3 * (5 * (p2**2 + q1**2) + q2**2)
        + p1 * (5 * p2**4 + 6 * p2**2 * q1**2 + 5 * q1**4 + 6 * (p2**2 + q1**2) * q2**2 + q2**4)
    )
    head6 = 5 * p1**4 * q1 + 4 * p1**3 * p2 * q2 + 4 * p1 * p2 * q2 * (p2**2 + 3 * q1**2 + q2**2)
    head6 = head6 + 2 * p1**2 * q1 * (3 * p2**2 + 5 * q1**2 + 3 * q2**2)
    tail6 = p2**4 + 5 * (q1**2 + q2**2) ** 2 + 2 * p2**2 * (q1**2 + 3 * q2**2)
    if fix_k6_parenthesis:
        k6 = (1 / 16) * (head6 + q1 * tail6)
    else:
        k6 = (1 / 16) * (head6 + q1) * tail6
    k7 = -(1 / 16) * (
        p2 * (5 * (p1**2 + p2**2) ** 2 + 2 * (3 * p1**2 + p2**2) * q1**2 + q1**4)
        + 4 * p1 * q1 * (p1**2 + 3 * p2**2 + q1**2) * q2
        + 2 * p2 * (3 * p1**2 + 5 * p2**2 + 3 * q1**2) * q2**2
        + 4 * p1 * q1 * q2**3
        + 5 * p2 * q2**4
    )
    k8 = (1 / 16) * (
        4 * p1**3 * p2 * q1
        + p1**4 * q2
        + 2 * p1**2 * q2 * (3 * (p2**2 + q1**2) + q2**2)
        + 4 * p1 * p2 * q1 * (p2**2 + q1**2 + 3 * q2**2)
        + q2 * (5 * p2**4 + 5 * (q1**2 + q2**2) ** 2 + 2 * p2**2 * (3 * q1**2 + 5 * q2**2))
    )
    return np.stack([k5, k6, k7, k8], axis=-1)


# ----------------------------------------------------------------------------------------------
# Analytic Jacobians of the nonlinear columns (for the interval computations)

# with s1 = (-p1, q1, -p2, q2) and s2 = (-q2, -p2, q1, p1): k_cubic = s1 e + s2 X (e = 3E/4,
# X = (p2 q1 - p1 q2)/2) and k_quintic = s1 (5/8 E^2 - X'^2/2) + s2 X' E/2 (X' = 2X)
_DS1 = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, -1], [0, 0, 1, 0]], dtype=float)
_DS2 = np.array([[0, 0, -1, 0], [0, 0, 0, -1], [1, 0, 0, 0], [0, 1, 0, 0]], dtype=float)


def _jacobian_parts(q: np.ndarray, model: str) -> list[tuple[np.ndarray, ...]]:
    """Per nonlinear column: (a, da, b, db) with column = s1 a + s2 b (see above)."""
    q1, p1, q2, p2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    energy = np.einsum("...a,...a->...", q, q)
    xp = p2 * q1 - p1 * q2
    dxp = np.stack([p2, -q2, -p1, q1], axis=-1)
    d_energy = 2.0 * q
    parts = []
    if model in ("cubic", "quintic"):
        parts.append((0.75 * energy, 0.75 * d_energy, 0.5 * xp, 0.5 * dxp))
    if model == "quintic":
        parts.append(
            (
                0.625 * energy**2 - 0.5 * xp**2,
                1.25 * energy[..., None] * d_energy - xp[..., None] * dxp,
                0.5 * xp * energy,
                0.5 * (dxp * energy[..., None] + xp[..., None] * d_energy),
            )
        )
    return parts


def nonlinear_jacobian(q: np.ndarray, model: str, weights: np.ndarray | None = None) -> np.ndarray:
    """d(nonlinear columns)/dq: shape (..., 4, 4, 0|1|2), [..., row, dq index, column]; with
    weights (xi[, kappa]) the weighted sum over columns, shape (..., 4, 4)."""
    q = np.asarray(q, dtype=float)
    s1 = q @ _DS1.T
    s2 = q @ _DS2.T
    parts = _jacobian_parts(q, model)

    def assemble(a, da, b, db):
        return (a[..., None, None] * _DS1 + s1[..., :, None] * da[..., None, :]
                + b[..., None, None] * _DS2 + s2[..., :, None] * db[..., None, :])

    if weights is not None:
        w = np.asarray(weights, dtype=float)
        if not parts:
            return np.zeros(q.shape[:-1] + (4, 4))
        summed = [sum(wn * part[m] for wn, part in zip(w, parts, strict=True)) for m in range(4)]
        return assemble(*summed)
    if not parts:
        return np.zeros(q.shape[:-1] + (4, 4, 0))
    return np.stack([assemble(*part) for part in parts], axis=-1)
