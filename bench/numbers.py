"""Numbers as an engineer writes them in a calibration file: a value with an interval to two
significant digits of the interval's half-width, one without to four significant digits, and a
dash for an empty field (never None, NaN or seventeen digits)."""

from __future__ import annotations

import math
from typing import Any

DASH = "—"


def _finite(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _fixed_or_sci(v: float, last_digit: int) -> str:
    """v rounded to the decade 10**last_digit; scientific notation outside 1e-3 .. 1e6; an exact
    zero (a truth of 0) is '0', not a row of zeros."""
    if v == 0:
        return "0"
    vr = round(v, -last_digit)  # the magnitude after rounding: 9.9996e6 to 4 digits is 1.000e7
    mag = math.floor(math.log10(abs(vr))) if vr else last_digit
    if -3 <= mag < 6 or not v:
        return f"{v:.{max(0, -last_digit)}f}"
    decimals = max(0, mag - last_digit)
    mant, _, exp = f"{v:.{decimals}e}".partition("e")
    return f"{mant}e{int(exp)}"


def sig(x: Any, digits: int = 4) -> str:
    """x to `digits` significant digits ('—' when empty or not a number)."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    v = _finite(x)
    if v is None:
        if x is None or x == "":
            return DASH
        try:
            f = float(x)
        except (TypeError, ValueError):
            return str(x)
        return DASH if math.isnan(f) else ("∞" if f > 0 else "−∞")
    if v == 0:
        return "0"
    mag = math.floor(math.log10(abs(v)))
    if abs(round(v, digits - 1 - mag)) >= 10.0 ** (mag + 1):  # rounds up into the next decade: 99.9988 -> 100.0
        mag += 1
    text = _fixed_or_sci(v, mag - digits + 1)
    return text.replace("-", "−") if text.startswith("-") else text


def last_digit(ci95: Any) -> int | None:
    """The decade of the last digit shown for a value with this interval: two significant
    digits of its half-width (None when the interval is empty or degenerate)."""
    if not ci95 or len(ci95) != 2:
        return None
    lo, hi = _finite(ci95[0]), _finite(ci95[1])
    if lo is None or hi is None or hi <= lo:
        return None
    return math.floor(math.log10(0.5 * (hi - lo))) - 1


def with_interval(value: Any, ci95: Any) -> tuple[str, str]:
    """(value, '[lo, hi]') rounded to two significant digits of the interval's half-width; a
    value without a usable interval gets four significant digits and '—'."""
    v = _finite(value)
    d = last_digit(ci95)
    if v is None or d is None:
        return sig(value), DASH
    lo, hi = float(ci95[0]), float(ci95[1])
    return _minus(_fixed_or_sci(v, d)), f"[{_minus(_fixed_or_sci(lo, d))}, {_minus(_fixed_or_sci(hi, d))}]"


def _minus(text: str) -> str:
    return "−" + text[1:] if text.startswith("-") else text


def limits(low: Any, high: Any) -> str:
    """'[lo, hi]', '≥ lo', '≤ hi' or '—'."""
    lo, hi = _finite(low), _finite(high)
    if lo is None and hi is None:
        return DASH
    if hi is None:
        return f"≥ {plain(lo)}"
    if lo is None:
        return f"≤ {plain(hi)}"
    return f"[{plain(lo)}, {plain(hi)}]"


def nearest_image(truth: float, value: float, period: float | None) -> float:
    """The truth moved by whole periods to the image nearest the value (an axis angle at 89.8 deg
    and its truth 0.1 deg are 0.3 deg apart, not 89.7); the truth itself without a period."""
    if period is None or not math.isfinite(truth) or not math.isfinite(value):
        return truth
    return truth + period * round((value - truth) / period)


def truth_outside(value: Any, truth: Any, ci95: Any, period: float | None = None) -> bool | None:
    """Whether the truth lies outside the value's 95 % interval (its nearest image for a periodic
    quantity); None when there is no value, truth or interval to compare (an open end counts as
    unbounded on that side: a one-sided interval)."""
    v, t = _finite(value), _finite(truth)
    if v is None or t is None or not ci95 or len(ci95) != 2:
        return None
    lo, hi = _finite(ci95[0]), _finite(ci95[1])
    if lo is None and hi is None:
        return None
    t = nearest_image(t, v, period)
    return (lo is not None and t < lo) or (hi is not None and t > hi)


def error_in_intervals(value: Any, truth: Any, ci95: Any, period: float | None = None) -> str:
    """(value - truth) in units of the interval's half-width, e.g. '+0.37' ('—' without one);
    period: the truth's nearest image (an axis angle's 90 deg)."""
    v, t = _finite(value), _finite(truth)
    if v is None or t is None or not ci95 or len(ci95) != 2:
        return DASH
    lo, hi = _finite(ci95[0]), _finite(ci95[1])
    if lo is None or hi is None or hi <= lo:
        return DASH
    t = nearest_image(t, v, period)
    return _minus(f"{(v - t) / (0.5 * (hi - lo)):+.2f}")


def truth_text(truth: Any, ci95: Any) -> str:
    """The truth to the value's precision (two more digits), else four significant digits."""
    t = _finite(truth)
    if t is None:
        return DASH
    if t == 0:  # an exact zero (a coefficient the simulator leaves out), not 0.00000000000
        return "0"
    d = last_digit(ci95)
    return _minus(_fixed_or_sci(t, d)) if d is not None else sig(t)


def pretty_unit(unit: str) -> str:
    """A unit as printed: powers as superscripts (deg/s^2 -> deg/s²)."""
    return unit.replace("^2", "²").replace("^3", "³")


def plain(x: Any, digits: int = 6) -> str:
    """A set value (a parameter, a limit) as written: up to `digits` significant digits, no
    trailing zeros ('500', '0.277', '1e-4')."""
    text = sig(x, digits)
    if any(c.isdigit() for c in text) and "." in text:
        mant, e, exp = text.partition("e")
        mant = mant.rstrip("0").rstrip(".")
        text = mant + e + exp
    return text
