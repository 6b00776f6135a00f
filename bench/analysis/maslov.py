"""Resonator identification after Maslov, Maslov and Merkuryev (2022): the public face.

- `identify_forced(drive_freq_hz, q1, p1, q2, p2, *, natural_freq_hz, model=...)`: forced steady
  states of a MEMS ring (paper sections 3-4), see `maslov_forced`.
- `identify_free_decay(t_s, q1, p1, q2, p2, *, model=..., recursive=False)`: free decay of a
  high-Q shell (section 2), Simpson regressors, batch or the paper's 4x4-block recursive LS,
  see `maslov_decay`; method="output-error" for the maximum-likelihood fit at the Cramer-Rao
  bound, see `free_decay_oe`.
- The regressor terms and what was found against the printed formulas: `maslov_terms`.
Pure functions: arrays in, a frozen `Identification` out.
"""

from __future__ import annotations

import math

from bench.analysis.maslov_decay import identify_free_decay, recursive_lsq, simpson_regressors
from bench.analysis.maslov_forced import (
    ForcedIdentification,
    ForcedResponse,
    detuning_rad_s,
    identify_forced,
    steady_states,
)
from bench.analysis.maslov_result import Identification, derived_ci95, derived_quantities
from bench.analysis.maslov_terms import (
    MODELS,
    forced_param_names,
    forced_regressor,
    free_param_names,
    free_regressor,
    k_electrostatic,
    k_quintic_printed,
)

#: The paper's MEMS ring: characteristic frequency and its cubic-model estimate (section 4).
PAPER_W_RAD_S = 85732.0
PAPER_NATURAL_FREQ_HZ = PAPER_W_RAD_S / (2.0 * math.pi)
PAPER_CUBIC_PARAMS = {
    "gamma": 43.029,
    "nu": 2.029,
    "b_c": 1.332,
    "b_s": -1.389,
    "c_m": 24.358,
    "n": 1.173,
    "h_c": -12.797,
    "h_s": 11.588,
    "u1": 32.159,
    "u2": 30.597,
    "u3": 1.415,
    "u4": -0.605,
    "xi": 18.217,
}
#: Residual sigma the paper reports on its measured data, per model.
PAPER_SIGMA = {"linear": 0.295, "cubic": 0.0926, "quintic": 0.0656}
#: Derived values the paper prints (Q, offset 1/s and Hz, split 1/s and Hz, spread, axes, zero rate at K = 0.4).
PAPER_DERIVED = {
    "Q": 1992.0,
    "freq_offset_rad_s": 12.179,
    "freq_offset_hz": 1.94,
    "split_rad_s": 17.264,
    "split_hz": 2.748,
    "damping_anisotropy_per_s": 3.848,
    "alpha_rad": 0.601,
    "beta_rad": -0.201,
    "zero_rate_rad_s": 1.268,
}

__all__ = [
    "MODELS",
    "PAPER_CUBIC_PARAMS",
    "PAPER_DERIVED",
    "PAPER_NATURAL_FREQ_HZ",
    "PAPER_SIGMA",
    "PAPER_W_RAD_S",
    "choose_model",
    "ForcedIdentification",
    "ForcedResponse",
    "Identification",
    "derived_ci95",
    "derived_quantities",
    "detuning_rad_s",
    "forced_param_names",
    "forced_regressor",
    "free_param_names",
    "free_regressor",
    "identify_forced",
    "identify_free_decay",
    "k_electrostatic",
    "k_quintic_printed",
    "recursive_lsq",
    "simpson_regressors",
    "steady_states",
]


def choose_model(sigmas: dict[str, float], improvement: float) -> str:
    """The simplest model that the next richer one does not beat by more than `improvement`
    (relative reduction of the residual sigma)."""
    chosen = "linear"
    for richer in ("cubic", "quintic"):
        if sigmas[richer] < (1.0 - improvement) * sigmas[chosen]:
            chosen = richer
        else:
            break
    return chosen
