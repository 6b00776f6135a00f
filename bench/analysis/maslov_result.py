"""The frozen result of a Maslov identification and the quantities derived from its parameters."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Identification:
    """Parameters with intervals and diagnostics of one least-squares identification.

    params, sigma_params (standard errors used for ci95), ci95 (corrected, see the method's
    docstring) and ci95_textbook (eq. 2.11: t_p sigma sqrt(c_jj)) are keyed by parameter name;
    sigma is the paper's residual sigma sqrt(S / (n - k)); residuals has shape (blocks, 4)."""

    model: str
    method: str
    params: Mapping[str, float]
    sigma: float
    ci95: Mapping[str, tuple[float, float]]
    ci95_textbook: Mapping[str, tuple[float, float]]
    sigma_params: Mapping[str, float]
    derived: Mapping[str, float]
    residuals: np.ndarray
    n_equations: int
    covariance: np.ndarray
    noise_sigma: float = float("nan")
    extras: Mapping[str, object] = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.params)

    def vector(self) -> np.ndarray:
        """The parameter vector z in the regressor's column order."""
        return np.array([self.params[k] for k in self.params])


def t_quantile(dof: int, level: float = 0.95) -> float:
    """Student's t quantile of order (1 + level)/2 (the paper's s_p)."""
    from scipy import special  # t quantiles without scipy.stats, on first use (issue 36)

    return float(special.stdtrit(max(int(dof), 1), 0.5 * (1.0 + level)))


def intervals(names: tuple[str, ...], z: np.ndarray, se: np.ndarray, s_p: float) -> dict[str, tuple[float, float]]:
    """z_j -/+ s_p se_j keyed by name."""
    return {n: (float(v - s_p * s), float(v + s_p * s)) for n, v, s in zip(names, z, se, strict=True)}


def derived_quantities(
    params: Mapping[str, float], *, natural_freq_hz: float | None = None, bryan_factor: float | None = None
) -> dict[str, float]:
    """Q, split, damping anisotropy, axes, frequency offset and zero-rate output (paper section 4)."""
    gamma = params["gamma"]
    split = math.hypot(params["h_c"], params["h_s"])
    out = {
        "tau_s": 2.0 / gamma if gamma else math.inf,
        "split_rad_s": split,
        "split_hz": split / TWO_PI,
        "delta_inv_tau_per_s": math.hypot(params["b_c"], params["b_s"]),
        "damping_anisotropy_per_s": 2.0 * math.hypot(params["b_c"], params["b_s"]),
        "alpha_rad": 0.25 * math.atan2(params["h_s"], params["h_c"]),
        "beta_rad": 0.25 * math.atan2(params["b_s"], params["b_c"]),
        "freq_offset_rad_s": 0.5 * params["c_m"],
        "freq_offset_hz": 0.5 * params["c_m"] / TWO_PI,
    }
    out["alpha_deg"] = math.degrees(out["alpha_rad"])
    out["beta_deg"] = math.degrees(out["beta_rad"])
    if natural_freq_hz is not None:
        out["Q"] = TWO_PI * natural_freq_hz / gamma if gamma else math.inf
    if bryan_factor is not None:
        if not 0 < bryan_factor <= 1:
            raise ValueError(f"bryan_factor={bryan_factor!r} must be in (0, 1]")
        out["zero_rate_rad_s"] = params["nu"] / (4.0 * bryan_factor)
        out["zero_rate_dps"] = math.degrees(out["zero_rate_rad_s"])
    return out


def check_finite_arrays(**arrays: np.ndarray) -> int:
    """All arrays 1-D, finite and of one length; return that length (errors name the array)."""
    length = None
    for name, arr in arrays.items():
        a = np.asarray(arr, dtype=float)
        if a.ndim != 1:
            raise ValueError(f"{name} must be 1-D, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contains non-finite values")
        if length is None:
            length = a.size
        elif a.size != length:
            raise ValueError(f"{name} has {a.size} samples, expected {length} like the others")
    return int(length or 0)


def derived_ci95(ident: Identification, *, natural_freq_hz: float | None = None,
                 bryan_factor: float | None = None, level: float = 0.95) -> dict[str, tuple[float, float]]:
    """Delta-method intervals of the derived quantities from the parameters' covariance (normal
    quantile; central-difference gradients with a step of 1e-4 standard error)."""
    names = list(ident.params)
    z = np.array([ident.params[n] for n in names])
    se = np.sqrt(np.maximum(np.diag(ident.covariance), 0.0))
    base = derived_quantities(ident.params, natural_freq_hz=natural_freq_hz, bryan_factor=bryan_factor)
    keys = list(base)
    grad = np.zeros((len(keys), len(names)))
    for j in range(len(names)):
        step = 1e-4 * se[j] if se[j] > 0 else 1e-9 * max(abs(z[j]), 1.0)
        vals = []
        for sgn in (1.0, -1.0):
            zz = z.copy()
            zz[j] += sgn * step
            d = derived_quantities(dict(zip(names, zz, strict=True)), natural_freq_hz=natural_freq_hz,
                                   bryan_factor=bryan_factor)
            vals.append(np.array([d[k] for k in keys]))
        grad[:, j] = (vals[0] - vals[1]) / (2.0 * step)
    var = np.einsum("kj,jl,kl->k", grad, ident.covariance, grad)
    from scipy import special  # normal quantiles without scipy.stats, on first use (issue 36)

    q = float(special.ndtri(0.5 * (1.0 + level)))
    return {k: (base[k] - q * math.sqrt(max(v, 0.0)), base[k] + q * math.sqrt(max(v, 0.0)))
            for k, v in zip(keys, var, strict=True)}
