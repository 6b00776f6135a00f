"""The line's statistics, pure functions on plain rows: yield by a key, process capability (Cp, Cpk)
of a measurement against its limits, and the final attempt of each unit."""

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


def capability(values: Iterable[float], low: float | None, high: float | None) -> dict[str, float | None]:
    """Cp = (high - low) / 6 sigma and Cpk = min(high - mean, mean - low) / 3 sigma (sample sigma,
    ddof 1); a one-sided limit has no Cp and its Cpk is its side's; None when undefined."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    out: dict[str, float | None] = {"n": int(x.size), "mean": None, "sigma": None, "cp": None, "cpk": None}
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
    return out
