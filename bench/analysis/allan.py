"""Allan deviation of a gyro's rate record and the noise terms read off it (IEEE Std 952, annex C).

The overlapping Allan deviation comes from allantools (octave-spaced tau).  The read-offs follow
the annex's slopes: angle random walk N from the -1/2 line (sigma = N / sqrt(tau), quoted at
tau = 1 s, in deg/sqrt(h)), bias instability B from the flat minimum (sigma = 0.664 B), rate random
walk K from the +1/2 line (sigma = K sqrt(tau / 3), quoted at tau = 3 s, in deg/h/sqrt(h)).  A
white angle noise Q (slope -1: the pickoffs' noise in whole-angle mode, a table's jitter) is a
nuisance taken from a joint weighted fit of all four slopes over the curve.  Each of N, B, K is read at
one tau: the flat minimum for B, and for N and K the tau where the term's estimate is most precise
(its share of the Allan variance against the chi-squared spread there).  The other terms' part of
the Allan variance at that tau (from their own read-offs, iterated) is subtracted, so a term is not
biased by its neighbours when the record is long enough to make the spread small.  The interval
is the chi-squared interval of the Allan variance at that tau, with the equivalent degrees of
freedom of Greenhall's algorithm for the record's number of clusters and the noise types there
(the fewest of those holding a tenth or more of the variance), widened by the uncertainty of
what is subtracted.
docs/noise_model.md gives the relations; the functions take plain arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _stats():
    """scipy.stats, imported on first use: a process that only loads the procedures (the line's
    limits, `gyrobench list`) never pays its ~0.4 s (issue 36)."""
    from scipy import stats

    return stats


def _allantools():
    """allantools, imported on first use (it imports scipy.stats, ~0.5 s more; issue 36)."""
    import allantools

    return allantools


#: sigma(tau) of a flicker floor in units of B: sqrt(2 ln 2 / pi)
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
COVARIANCE_INFLATION = 4.0
#: the terms: power p of tau in the Allan variance (c tau^p), Greenhall's alpha for frequency
#: (rate) data, and what the annex calls them
TERMS = {
    "Q": (-2, 2, "white angle noise (slope -1)"),
    "N": (-1, 0, "angle random walk (slope -1/2)"),
    "B": (0, -1, "bias instability (flat)"),
    "K": (1, -2, "rate random walk (slope +1/2)"),
}


@dataclass(frozen=True)
class AllanCurve:
    """Overlapping Allan deviation at octave-spaced tau of a rate record (the record's unit)."""

    tau_s: np.ndarray
    adev: np.ndarray
    n_clusters: np.ndarray  # allantools' count of the overlapping differences at each tau
    n_samples: int
    rate_hz: float

    @property
    def m(self) -> np.ndarray:
        """Cluster size in samples at each tau."""
        return np.rint(self.tau_s * self.rate_hz).astype(np.int64)

    def edf(self, alpha: int) -> np.ndarray:
        """Equivalent degrees of freedom of each point for noise type alpha (Greenhall)."""
        if alpha == 2:  # white angle noise: Greenhall's algorithm has no case for it; the simple formula
            return np.array([_allantools().edf_simple(self.n_samples + 1, int(m), alpha) for m in self.m])
        return np.array([_allantools().edf_greenhall(alpha=alpha, d=2, m=int(m), N=self.n_samples + 1,
                                                  overlapping=True) for m in self.m])


@dataclass(frozen=True)
class TermReadoff:
    """One noise term: its value and interval (deg/sqrt(h), deg/h or deg/h/sqrt(h)), where it was read."""

    name: str
    value: float
    ci: tuple[float, float]
    tau_s: float
    edf: float
    share: float  # the term's fraction of the Allan variance at tau_s


@dataclass(frozen=True)
class NoiseTerms:
    """The read-offs of a curve: arw (N), bias instability (B), rrw (K), the model coefficients c_p
    of sigma^2 = sum c_p tau^p ((deg/h)^2 s^p) and the level."""

    arw: TermReadoff
    bias_instability: TermReadoff
    rrw: TermReadoff
    angle_noise: TermReadoff  # Q (deg), the nuisance: sigma = sqrt(3) Q / tau
    coefficients: dict[str, float] = field(default_factory=dict)
    level: float = 0.95
    boxcar_s: float = 0.0  # the angle samples' averaging time (read_noise_terms' `boxcar`)

    def model_adev(self, tau_s: np.ndarray) -> np.ndarray:
        """sigma(tau) of the read-off model (deg/h)."""
        total = sum(c * _basis_of(k, tau_s, self.boxcar_s) for k, c in self.coefficients.items())
        return np.sqrt(np.maximum(total, 0.0))


def allan_deviation(rate: np.ndarray, rate_hz: float) -> AllanCurve:
    """Overlapping Allan deviation (allantools.oadev) of evenly sampled rates at octave-spaced tau."""
    rate = np.asarray(rate, dtype=float)
    if len(rate) < 8:
        raise ValueError(f"an Allan deviation needs at least 8 samples; the record has {len(rate)}")
    taus, adev, _err, ns = _allantools().oadev(rate, rate=rate_hz, data_type="freq", taus="octave")
    return AllanCurve(np.asarray(taus), np.asarray(adev), np.asarray(ns), len(rate), float(rate_hz))


def _basis_of(name: str, tau: np.ndarray | float, boxcar_s: float = 0.0) -> np.ndarray | float:
    """tau^p; for the white rate term of samples that are boxcar means of the angle over boxcar_s
    (a decimated stream), (1 - boxcar_s / (2 tau)) / tau (docs/noise_model.md)."""
    tau = np.asarray(tau, dtype=float)
    if name == "N" and boxcar_s:
        return (1.0 - boxcar_s / (2.0 * tau)) / tau
    return tau ** TERMS[name][0]


def _initial_fit(curve: AllanCurve, edfs: dict[str, np.ndarray], usable: np.ndarray, boxcar_s: float = 0.0,
                 iterations: int = 6) -> tuple[dict[str, float], dict[str, float]]:
    """Least squares of sigma^2 = sum c_p tau^p over the usable points (unconstrained, so a term's
    noise is not pushed one way onto the others), each weighted
    by the inverse of its chi-squared spread sqrt(2 / edf) sigma^2 under the current model
    (iteratively reweighted; edf of the noise type that dominates the point): a start for the read-offs."""
    tau, avar = curve.tau_s[usable], curve.adev[usable] ** 2
    basis = np.column_stack([_basis_of(k, tau, boxcar_s) for k in TERMS])
    scale = np.max(basis, axis=0)
    edf_by_term = np.column_stack([edfs[k][usable] for k in TERMS])
    model = avar.copy()
    parts = None
    c = np.zeros(len(TERMS))
    for _ in range(iterations):
        edf = edf_by_term[np.arange(len(tau)), np.argmax(parts, axis=1)] if parts is not None else edf_by_term[:, 1]
        w = np.sqrt(edf / 2.0) / np.maximum(model, 1e-300)
        a = basis / scale * w[:, None]
        c = np.linalg.lstsq(a, avar * w, rcond=None)[0] / scale
        parts = np.maximum(basis * c, 0.0)
        model = np.maximum(parts.sum(axis=1), 0.1 * avar)
    # the weighted fit's covariance, times 4: overlapping deviations at neighbouring octaves are
    # correlated, which the fit's independent weights ignore (the factor is checked by Monte Carlo,
    # benchmarks/allan_coverage.py)
    var = COVARIANCE_INFLATION * np.diag(np.linalg.pinv(a.T @ a)) / scale**2
    return {k: float(v) for k, v in zip(TERMS, c, strict=True)}, {k: float(v) for k, v in zip(TERMS, var, strict=True)}


def _value(name: str, c: float) -> float:
    """A coefficient c_p ((deg/h)^2 s^p) as the term's quoted value."""
    r = math.sqrt(max(c, 0.0))
    scale = {"Q": 1.0 / math.sqrt(3.0) / 3600.0, "N": 1.0 / 60.0, "B": 1.0 / FLICKER_FLOOR, "K": math.sqrt(3.0) * 60.0}
    return r * scale[name]


def read_noise_terms(curve: AllanCurve, level: float = 0.95, iterations: int = 4,
                     min_cluster: int = 8, boxcar: bool = False) -> NoiseTerms:
    """N, B, K (and the nuisance Q, deg) read off an Allan curve of a rate in deg/h, each with its
    interval at `level`, at taus
    of at least `min_cluster` samples: N in deg/sqrt(h), B in deg/h, K in deg/h/sqrt(h).  `boxcar`:
    the rates are differences of angles that are each the mean over a sample period (a boxcar-
    decimated stream), which lowers the white rate term's Allan variance by (1 - tau0 / 2 tau)."""
    tau, avar = curve.tau_s, curve.adev**2
    edfs = {k: curve.edf(TERMS[k][1]) for k in TERMS}
    usable = curve.m >= min_cluster  # shorter clusters see the sampling and the spectra's upper ends
    if not usable.any():
        raise ValueError(f"the record is too short: no tau with {min_cluster} samples a cluster")
    box = 1.0 / curve.rate_hz if boxcar else 0.0

    def _basis(name: str, t: np.ndarray | float) -> np.ndarray | float:
        return _basis_of(name, t, box)

    coef, var_c = _initial_fit(curve, edfs, usable, box)  # var_c: each coefficient's variance
    chosen = {"Q": int(np.argmax(usable)), "N": int(np.argmax(usable)),
              "B": int(np.argmin(np.where(usable, curve.adev, np.inf))),
              "K": len(tau) - 1}  # until the loop reads them where they are most precise

    def others_at(k: str, i: int) -> tuple[float, float]:
        """The other terms' part of the Allan variance at tau_i and the variance of that part."""
        part = sum(coef[o] * _basis(o, tau[i]) for o in TERMS if o != k)
        var = sum(var_c[o] * _basis(o, tau[i]) ** 2 for o in TERMS if o != k)
        return float(part), float(var)

    def mixture_edf() -> np.ndarray:
        """Equivalent degrees of freedom of each point for the mixture of terms there: the fewest of
        the noise types that hold at least a tenth of the Allan variance (a random walk's share
        leaves fewer degrees of freedom than the white part's share would suggest)."""
        parts = np.array([np.maximum(coef[o] * _basis(o, tau), 0.0) for o in TERMS])
        share = parts / np.maximum(parts.sum(axis=0), 1e-300)
        e = np.array([edfs[o] for o in TERMS])
        return np.min(np.where(share >= 0.1, e, np.inf), axis=0)

    for _ in range(iterations):
        model = np.maximum(sum(coef[k] * _basis(k, tau) for k in TERMS), 1e-300)
        edf_mix = mixture_edf()
        for k in TERMS:
            if k == "Q":
                continue  # a nuisance: as the joint fit left it (read at one tau it would share N's)
            part = coef[k] * _basis(k, tau)
            if k == "B":  # the annex: the flat minimum (of the model: the measured one wanders at long tau)
                i = int(np.argmin(np.where(usable, model, np.inf)))
            elif np.any(part[usable] > 0):
                # the tau where the term is read most precisely: its share against the chi^2 spread
                # there and the uncertainty of the other terms' part that is subtracted
                oth_var = np.array([others_at(k, j)[1] for j in range(len(tau))])
                spread = np.sqrt(2.0 * model**2 / edf_mix + oth_var)
                with np.errstate(divide="ignore", invalid="ignore"):
                    rel = np.where(usable & (part > 0), spread / part, np.inf)
                i = int(np.argmin(rel))
            else:
                continue
            others, oth_var = others_at(k, i)
            # not clipped at 0 here: a term's noise must not push its neighbours one way only
            coef[k] = (avar[i] - others) / _basis(k, tau[i])
            var_c[k] = (2.0 * avar[i] ** 2 / edf_mix[i] + oth_var) / _basis(k, tau[i]) ** 2
            chosen[k] = i
    model = sum(coef[k] * _basis(k, tau) for k in TERMS)
    edf_mix = mixture_edf()
    z = _stats().norm.ppf((1 + level) / 2)
    out = {}
    for k, i in chosen.items():
        edf = float(edf_mix[i])
        lo_q, hi_q = _stats().chi2.ppf([(1 + level) / 2, (1 - level) / 2], edf)
        others, oth_var = others_at(k, i)
        b = _basis(k, tau[i])
        c = coef[k]
        # the chi-squared interval of sigma^2(tau_i), less the others' part, widened by the others'
        # uncertainty (in quadrature on each side)
        lo_own, hi_own = (edf * avar[i] / lo_q - others) / b, (edf * avar[i] / hi_q - others) / b
        wide = z * math.sqrt(oth_var) / b
        lo_c = c - math.hypot(max(c - lo_own, 0.0), wide)
        hi_c = c + math.hypot(max(hi_own - c, 0.0), wide)
        share = float(c * b / model[i]) if model[i] > 0 else 0.0
        out[k] = TermReadoff(k, _value(k, c), (_value(k, max(lo_c, 0.0)), _value(k, hi_c)), float(tau[i]), edf,
                             share)
    return NoiseTerms(out["N"], out["B"], out["K"], out["Q"], coef, level, box)


def adev_band(curve: AllanCurve, terms: NoiseTerms) -> tuple[np.ndarray, np.ndarray]:
    """The chi-squared band (lower, upper) of each point of the curve at the read-off's level, with
    the equivalent degrees of freedom of the noise type that dominates there."""
    tau = curve.tau_s
    parts = np.array([terms.coefficients[k] * _basis_of(k, tau, terms.boxcar_s) for k in TERMS])
    dominant = np.argmax(parts, axis=0)
    alphas = [TERMS[k][1] for k in TERMS]
    edfs = {a: curve.edf(a) for a in set(alphas)}
    edf = np.array([edfs[alphas[j]][i] for i, j in enumerate(dominant)])
    lo_q = _stats().chi2.ppf((1 + terms.level) / 2, edf)
    hi_q = _stats().chi2.ppf((1 - terms.level) / 2, edf)
    return curve.adev * np.sqrt(edf / lo_q), curve.adev * np.sqrt(edf / hi_q)
