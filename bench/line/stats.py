"""The line's statistics, pure functions on plain rows: yield by a key, process capability (Cp, Cpk)
of a measurement against its limits with confidence intervals, the individuals (Shewhart) chart's
limits from the moving range, and the final attempt of each unit."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from .verdict import ERROR, FAIL, MARGINAL, PASS

COUNTED = (PASS, MARGINAL, FAIL, ERROR)


def final_attempts(attempts: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Each unit's last attempt (highest attempt number) by serial."""
    last: dict[str, dict[str, Any]] = {}
    for a in attempts:
        if a["serial"] not in last or a["attempt"] > last[a["serial"]]["attempt"]:
            last[a["serial"]] = a
    return last


def yield_by(attempts: list[dict[str, Any]], key: Callable[[dict[str, Any]], str]) -> list[dict[str, Any]]:
    """Per group (lot, day, station): units, first-pass yield (attempt 1 PASS), final yield (last
    attempt PASS), and the final outcomes counted apart (MARGINAL is neither PASS nor FAIL)."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for a in attempts:
        groups.setdefault(key(a), []).append(a)
    rows = []
    for name, rows_ in sorted(groups.items()):
        last = final_attempts(rows_)
        first = {a["serial"]: a for a in rows_ if a["attempt"] == min(b["attempt"] for b in rows_
                                                                         if b["serial"] == a["serial"])}
        n = len(last)
        counts = {o: sum(1 for a in last.values() if a["outcome"] == o) for o in COUNTED}
        counts["other"] = n - sum(counts.values())
        rows.append({"group": name, "units": n, "attempts": len(rows_),
                     "first_pass_yield": sum(1 for a in first.values() if a["outcome"] == PASS) / n if n else math.nan,
                     "final_yield": counts[PASS] / n if n else math.nan, **counts})
    return rows


def capability(values: Iterable[float], low: float | None, high: float | None,
               confidence: float = 0.95) -> dict[str, Any]:
    """Cp = (high - low) / 6 sigma and Cpk = min(high - mean, mean - low) / 3 sigma (sample sigma,
    ddof 1); a one-sided limit has no Cp and its Cpk is its side's; None when undefined.  With
    their two-sided confidence intervals (`cp_ci`, `cpk_ci`):

    - Cp:  [Cp sqrt(chi2_{a/2, n-1} / (n-1)), Cp sqrt(chi2_{1-a/2, n-1} / (n-1))] (exact for normal data);
    - Cpk: Cpk -+ z_{1-a/2} sqrt(1 / (9 n) + Cpk^2 / (2 (n - 1)))  (Bissell's approximation, 1990)."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    out: dict[str, Any] = {"n": int(x.size), "mean": None, "sigma": None, "cp": None, "cpk": None,
                           "cp_ci": None, "cpk_ci": None}
    if x.size < 2:
        return out
    mean, sd = float(x.mean()), float(x.std(ddof=1))
    out.update(mean=mean, sigma=sd)
    if sd <= 0:
        return out
    if low is not None and high is not None:
        out["cp"] = (high - low) / (6 * sd)
    sides = [s for s in ((high - mean) if high is not None else None, (mean - low) if low is not None else None)
             if s is not None]
    if sides:
        out["cpk"] = min(sides) / (3 * sd)
    out["cp_ci"], out["cpk_ci"] = capability_intervals(out["cp"], out["cpk"], int(x.size), confidence)
    return out


def capability_intervals(cp: float | None, cpk: float | None, n: int,
                         confidence: float = 0.95) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """The confidence intervals of Cp (chi-square) and Cpk (Bissell) from n values (see `capability`)."""
    from scipy import stats

    if n < 2:
        return None, None
    a = 1.0 - confidence
    cp_ci = None
    if cp is not None:
        dof = n - 1
        cp_ci = (cp * math.sqrt(stats.chi2.ppf(a / 2, dof) / dof), cp * math.sqrt(stats.chi2.ppf(1 - a / 2, dof) / dof))
    cpk_ci = None
    if cpk is not None:
        half = float(stats.norm.ppf(1 - a / 2)) * math.sqrt(1 / (9 * n) + cpk**2 / (2 * (n - 1)))
        cpk_ci = (cpk - half, cpk + half)
    return cp_ci, cpk_ci


D2_MR = 1.128  # d2 for a moving range of 2: sigma_within = mean moving range / d2


def individuals_chart(values: Iterable[float]) -> dict[str, Any]:
    """The individuals (X) chart of values in time order: centre line the mean, the within spread
    sigma = mean |x_i - x_(i-1)| / 1.128 (moving range of 2), Shewhart limits mean -+ 3 sigma_within
    (= mean -+ 2.66 MR-bar); the points past a limit (0-based indices)."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    out: dict[str, Any] = {"n": int(x.size), "center": None, "mr_bar": None, "sigma_within": None, "ucl": None,
                           "lcl": None, "outside": []}
    if x.size < 2:
        return out
    mr_bar = float(np.mean(np.abs(np.diff(x))))
    center, sw = float(x.mean()), mr_bar / D2_MR
    out.update(center=center, mr_bar=mr_bar, sigma_within=sw, ucl=center + 3 * sw, lcl=center - 3 * sw)
    out["outside"] = [int(i) for i in np.flatnonzero((x > out["ucl"]) | (x < out["lcl"]))] if sw > 0 else []
    return out
