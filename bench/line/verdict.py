"""The decision on one measurement against product limits: the guard-band rule on its 95 % interval
(ILAC G8) or the value-only rule with a marginal band (OpenHTF's); pure functions, no I/O.

guard-band: PASS when the whole interval lies inside [low, high] (touching a limit is inside),
FAIL when it lies wholly outside, MARGINAL when it straddles a limit.  A non-finite end of the
interval is taken as unbounded on that side (it can never prove PASS).
value: FAIL outside [low, high] (or a non-finite value), MARGINAL inside but beyond the marginal
band (marginal_low / marginal_high), PASS otherwise.  It is what decides a measurement without an
interval, even when the limits ask for the guard band; the verdict says which rule decided.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PASS, MARGINAL, FAIL, ERROR, ABORTED = "PASS", "MARGINAL", "FAIL", "ERROR", "ABORTED"
COMPLETE, SKIPPED = "COMPLETE", "SKIPPED"  # no limits; a step that never ran after a stop-on-fail
GUARD_BAND, VALUE = "guard-band", "value"
RULES = (GUARD_BAND, VALUE)
#: severity for the unit's outcome (worst wins); COMPLETE and SKIPPED do not decide
SEVERITY = {PASS: 0, MARGINAL: 1, FAIL: 2, ABORTED: 3, ERROR: 4}


@dataclass(frozen=True)
class Limit:
    """A product limit on one declared measurement (either side may be open)."""

    name: str
    low: float | None = None
    high: float | None = None
    rule: str = GUARD_BAND
    marginal_low: float | None = None  # value rule: MARGINAL below this (inside the limits)
    marginal_high: float | None = None
    unit: str | None = None  # when given, checked against the declared unit
    procedure: str | None = None  # only this procedure's measurement (None: any that measures it)


@dataclass(frozen=True)
class Verdict:
    """What decided one measurement: outcome, rule, and the expanded uncertainty on each side."""

    outcome: str
    rule: str
    u_low: float | None = None  # value - interval low (U below the value)
    u_high: float | None = None  # interval high - value
    note: str = ""
    condition: str = ""  # a MARGINAL's kind: "conditional pass" or "conditional fail" (ILAC G8), "marginal band"


def conditional(value: float, interval: tuple[float, float], low: float | None, high: float | None) -> tuple[str, str]:
    """ILAC G8's two kinds of MARGINAL, told apart by where the value lies, and the reason: a
    conditional pass (the value inside the limits, its 95 % interval across one) or a conditional
    fail (the value outside, its interval reaching back inside)."""
    lo, hi = sorted(float(x) for x in interval)
    crossed = [f"{name} limit {lim:g}" for name, lim in (("low", low), ("high", high))
               if lim is not None and lo < lim < hi]
    where = " and ".join(crossed) or "a limit"
    iv = f"[{lo:.6g}, {hi:.6g}]"
    if _finite(value) and (low is None or value >= low) and (high is None or value <= high):
        return "conditional pass", f"conditional pass: the value {value:.6g} is inside the limits but its 95 % " \
                                   f"interval {iv} crosses the {where} (ILAC G8)"
    if _finite(value):
        return "conditional fail", f"conditional fail: the value {value:.6g} is outside the limits and its 95 % " \
                                   f"interval {iv} reaches back across the {where} (ILAC G8)"
    return "conditional", f"the 95 % interval {iv} crosses the {where}; no finite value to place (ILAC G8)"


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def expanded_uncertainty(value: float, interval: tuple[float, float] | None) -> tuple[float | None, float | None]:
    """U below and above the value: the 95 % interval's half-widths, each side separately."""
    if interval is None or not _finite(value):
        return None, None
    lo, hi = interval
    return (value - lo if _finite(lo) else None), (hi - value if _finite(hi) else None)


def guard_band(interval: tuple[float, float], low: float | None, high: float | None) -> str:
    """ILAC G8 on an interval: PASS wholly inside (ends inclusive), FAIL wholly outside, else MARGINAL."""
    lo, hi = interval
    lo = -math.inf if lo is None or math.isnan(lo) else lo
    hi = math.inf if hi is None or math.isnan(hi) else hi
    if lo > hi:
        lo, hi = hi, lo
    if (low is not None and hi < low) or (high is not None and lo > high):
        return FAIL
    if (low is None or lo >= low) and (high is None or hi <= high):
        return PASS
    return MARGINAL


def value_rule(value: float, low: float | None, high: float | None,
               marginal_low: float | None = None, marginal_high: float | None = None) -> str:
    """OpenHTF's value-only check with a marginal band inside the limits; NaN FAILs."""
    if value is None or not math.isfinite(value):
        return FAIL
    if (low is not None and value < low) or (high is not None and value > high):
        return FAIL
    if (marginal_low is not None and value < marginal_low) or (marginal_high is not None and value > marginal_high):
        return MARGINAL
    return PASS


def judge(value: float | None, interval: tuple[float, float] | None, limit: Limit) -> Verdict:
    """The verdict on a measured value (and its 95 % interval, if any) against a product limit."""
    v = math.nan if value is None else float(value)
    u_lo, u_hi = expanded_uncertainty(v, interval)
    if limit.rule == GUARD_BAND and interval is not None:
        lo, hi = interval
        if not (_finite(lo) or _finite(hi)):  # no end known: nothing to decide on but the value
            return Verdict(value_rule(v, limit.low, limit.high), VALUE, None, None,
                           "the interval has no finite end; decided on the value")
        outcome = guard_band((lo, hi), limit.low, limit.high)
        if outcome != MARGINAL:
            return Verdict(outcome, GUARD_BAND, u_lo, u_hi)
        lo_, hi_ = (-math.inf if not _finite(lo) else lo), (math.inf if not _finite(hi) else hi)
        kind, why = conditional(v, (lo_, hi_), limit.low, limit.high)
        return Verdict(outcome, GUARD_BAND, u_lo, u_hi, why, kind)
    note = "no 95% interval; decided on the value" if limit.rule == GUARD_BAND else ""
    outcome = value_rule(v, limit.low, limit.high, limit.marginal_low, limit.marginal_high)
    if outcome == MARGINAL:
        marg = (("low", limit.marginal_low), ("high", limit.marginal_high))
        band = [f"beyond the marginal {n} {m:g}" for n, m in marg
                if m is not None and ((n == "low" and v < m) or (n == "high" and v > m))]
        why = f"marginal: the value {v:.6g} is inside the limits but {' and '.join(band)} (value rule)"
        return Verdict(outcome, VALUE, u_lo, u_hi, "; ".join(x for x in (note, why) if x), "marginal band")
    return Verdict(outcome, VALUE, u_lo, u_hi, note)


def worst(outcomes) -> str:
    """A unit's outcome: the worst of its measurements' (ERROR > ABORTED > FAIL > MARGINAL > PASS);
    COMPLETE / SKIPPED do not decide; nothing decided at all is ERROR (no limit was checked)."""
    ranked = [o for o in outcomes if o in SEVERITY]
    if not ranked:
        return ERROR
    return max(ranked, key=SEVERITY.__getitem__)
