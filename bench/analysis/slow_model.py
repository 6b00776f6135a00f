"""The averaged (slow-variable) resonator model of PHYSICS.md section 2, as pure array maths.

State q = (q1, p1, q2, p2) = (cx, sx, cy, sy).  The model is
    2 dq/dt = Dg(q) zg + xi k_cubic(q) + kappa k_quintic(q) + u - 2 lam J q
Everything here takes arrays whose last axis is the four slow variables, so the same functions
serve the simulator (one state) and the estimators (thousands of samples).  Leaf module:
numpy only, importable by every layer.
"""

from __future__ import annotations

import numpy as np

#: Names of the linear parameter vector zg, in the column order of Dg.
LINEAR_PARAM_NAMES = ("gamma", "nu", "b_c", "b_s", "c_m", "n", "h_c", "h_s")


#: Dg(q)[a, c] = DG_SIGN[a, c] * q[DG_INDEX[a, c]]: every entry of Dg is + or - one state variable,
#: (q1, p1, q2, p2) = indices (0, 1, 2, 3); the rows, written out:
#:     [-q1, q2, -q1, -q2, p1, p2, p1, p2],
#:     [-p1, p2, -p1, -p2, -q1, -q2, -q1, -q2],
#:     [-q2, -q1, q2, -q1, p2, -p1, -p2, p1],
#:     [-p2, -p1, p2, -p1, -q2, q1, q2, -q1]
DG_INDEX = np.array(
    [[0, 2, 0, 2, 1, 3, 1, 3], [1, 3, 1, 3, 0, 2, 0, 2], [2, 0, 2, 0, 3, 1, 3, 1], [3, 1, 3, 1, 2, 0, 2, 0]]
)
DG_SIGN = np.array(
    [
        [-1, 1, -1, -1, 1, 1, 1, 1],
        [-1, 1, -1, -1, -1, -1, -1, -1],
        [-1, -1, 1, -1, 1, -1, -1, 1],
        [-1, -1, 1, -1, -1, 1, 1, -1],
    ],
    dtype=float,
)
#: B_m = dDg/dq_m, shape (4, 4, 8): Dg(q) = sum_m q_m B_m
DG_BASIS = np.stack([DG_SIGN * (DG_INDEX == m) for m in range(4)])
_J_INDEX, _J_SIGN = np.array([1, 0, 3, 2]), np.array([1.0, -1.0, 1.0, -1.0])


def regressor_linear(q: np.ndarray) -> np.ndarray:
    """Dg(q): shape (..., 4, 8), so that Dg(q) @ zg is the linear part of 2 dq/dt.  One gather and
    a sign (the same numbers as writing the rows out, C-ordered as the stack of them was), not 32
    small arrays stacked (issue 36: a sweep's model curves call it ~6,000 times)."""
    return np.ascontiguousarray(np.asarray(q, dtype=float)[..., DG_INDEX] * DG_SIGN)


def detuning_term(q: np.ndarray) -> np.ndarray:
    """J q = (p1, -q1, p2, -q2): the term multiplied by -2 lam in 2 dq/dt."""
    return np.ascontiguousarray(np.asarray(q, dtype=float)[..., _J_INDEX] * _J_SIGN)


def _invariant_parts(q: np.ndarray) -> tuple[np.ndarray, ...]:
    q = np.asarray(q, dtype=float)
    q1, p1, q2, p2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    energy = q1 * q1 + p1 * p1 + q2 * q2 + p2 * p2
    cross = p2 * q1 - p1 * q2
    return q1, p1, q2, p2, energy, cross


def k_cubic(q: np.ndarray) -> np.ndarray:
    """Averaged cubic nonlinearity k1..k4 (multiplies xi); matches PHYSICS.md section 2."""
    q1, p1, q2, p2, energy, cross = _invariant_parts(q)
    e = 0.75 * energy
    x = 0.5 * cross
    return np.stack([-p1 * e - q2 * x, q1 * e - p2 * x, -p2 * e + q1 * x, q2 * e + p1 * x], axis=-1)


def k_quintic(q: np.ndarray) -> np.ndarray:
    """Averaged quintic nonlinearity k5..k8 (multiplies kappa).

    Derived here by averaging kappa (f^2+g^2)^2 f over one period (the printed terms have typos):
    with E = |q|^2 and X = p2 q1 - p1 q2,
        k5 = -p1 (5/8 E^2 - X^2/2) - q2 X E/2,  k6 = q1 (5/8 E^2 - X^2/2) - p2 X E/2,
        k7 = -p2 (5/8 E^2 - X^2/2) + q1 X E/2,  k8 = q2 (5/8 E^2 - X^2/2) + p1 X E/2.
    """
    q1, p1, q2, p2, energy, cross = _invariant_parts(q)
    s = 0.625 * energy * energy - 0.5 * cross * cross
    c = 0.5 * cross * energy
    return np.stack([-p1 * s - q2 * c, q1 * s - p2 * c, -p2 * s + q1 * c, q2 * s + p1 * c], axis=-1)


def slow_rhs(
    q: np.ndarray,
    zg: np.ndarray,
    *,
    xi: float = 0.0,
    kappa: float = 0.0,
    u: np.ndarray | None = None,
    lam: float = 0.0,
) -> np.ndarray:
    """dq/dt of the averaged model (note: the model is written for 2 dq/dt; this halves it)."""
    q = np.asarray(q, dtype=float)
    two_dq = regressor_linear(q) @ np.asarray(zg, dtype=float)
    if xi:
        two_dq = two_dq + xi * k_cubic(q)
    if kappa:
        two_dq = two_dq + kappa * k_quintic(q)
    if u is not None:
        two_dq = two_dq + np.asarray(u, dtype=float)
    if lam:
        two_dq = two_dq - 2.0 * lam * detuning_term(q)
    return 0.5 * two_dq


# Dg(q) zg = (sum_j zg_j B_j) q: the constant matrices B_j, built once from Dg of unit states.
_BASIS = np.stack([regressor_linear(e) for e in np.eye(4)], axis=-1).transpose(1, 0, 2)  # (8, 4, 4)
_DETUNING = np.stack([detuning_term(e) for e in np.eye(4)], axis=-1)  # J, (4, 4)


def linear_matrix(zg: np.ndarray, lam: float = 0.0) -> np.ndarray:
    """A such that dq/dt = A q for the linear part (forcing excluded)."""
    m = np.tensordot(np.asarray(zg, dtype=float), _BASIS, axes=1)
    if lam:
        m = m - 2.0 * lam * _DETUNING
    return 0.5 * m


# ----------------------------------------------------------------------------------------------
# Invariants and orbit elements (PHYSICS.md section 1)


def invariants(q: np.ndarray) -> dict[str, np.ndarray]:
    """E, R, S, Q of PHYSICS.md section 1 for states q (..., 4)."""
    q = np.asarray(q, dtype=float)
    cx, sx, cy, sy = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return {
        "E": cx * cx + sx * sx + cy * cy + sy * sy,
        "R": cx * cx + sx * sx - cy * cy - sy * sy,
        "S": 2.0 * (cx * cy + sx * sy),
        "Q": 2.0 * (cx * sy - sx * cy),
    }


def orbit_elements(q: np.ndarray) -> dict[str, np.ndarray]:
    """Energy E, wave angle theta (rad, physical, in (-pi/4, pi/4]), main amplitude a and
    quadrature amplitude k (signed) from the slow variables."""
    inv = invariants(q)
    theta = 0.25 * np.arctan2(inv["S"], inv["R"])
    diff = np.hypot(inv["R"], inv["S"])  # a^2 - k^2
    a = np.sqrt(np.maximum(0.5 * (inv["E"] + diff), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(a > 0, inv["Q"] / (2.0 * np.where(a > 0, a, 1.0)), 0.0)
    return {"E": inv["E"], "theta_rad": theta, "a": a, "k": k}


def state_from_elements(a: float, k: float, theta_rad: float, chi_rad: float = 0.0) -> np.ndarray:
    """Slow variables of a standing wave (Maslov eq. 5.2): amplitude a, quadrature k, angle theta,
    temporal phase chi."""
    c2, s2 = np.cos(2 * theta_rad), np.sin(2 * theta_rad)
    cc, sc = np.cos(chi_rad), np.sin(chi_rad)
    return np.array(
        [
            a * c2 * cc - k * s2 * sc,
            -a * c2 * sc - k * s2 * cc,
            a * s2 * cc + k * c2 * sc,
            -a * s2 * sc + k * c2 * cc,
        ]
    )
