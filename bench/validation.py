"""One wording for every bad value a user can give (station keys, --set, --speed, the GUI form).

Each check returns the converted value or raises `ValidationError`, whose message names the value
and what was expected, in one of these shapes:

    rate_dps='abc' is not a number
    rate_dps=99999 deg/s is above the limit 1000 deg/s
    driver: missing key (one of modbus-table, ascii-table)
    nosuchparam: not a parameter of table-spin (allowed: hold_s, rate_dps)

Callers add where the value came from (a file and table) in front of the message.  Procedure
parameters (`Param.convert`), station keys (`Key.check`), the window's form (through `Param`) and
the drivers' limits (`check_limit`, raising `LimitError`) all check here, in these words.

A library such as pydantic could do the type checks, but its messages ("Input should be a valid
number, unable to parse string as a number") name neither the key nor the unit nor the limit,
and would need translating back into these shapes; the checks themselves are a few lines.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from typing import Any

KIND_WORDS = {float: "a number", int: "an integer", bool: "true or false", str: "text", dict: "a table"}
TRUE_WORDS, FALSE_WORDS = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


class ValidationError(ValueError):
    """A value that is of the wrong kind, outside its limits, missing or unknown; the message says
    which value and what was expected."""


class LimitError(ValidationError):
    """A value a driver was asked to write is outside a configured or device limit; raised before
    anything is written.  `name`, `value`, `limit` (text) and `unit` say which and why."""

    def __init__(self, name: str, value: Any, limit: str | float = "", unit: str = "",
                 message: str | None = None) -> None:
        self.name, self.value, self.limit, self.unit = name, value, limit, unit
        u = f" {unit}" if unit else ""
        super().__init__(message or f"{name}={fmt_value(value, unit)} is outside the limit {limit}{u}")


def fmt_value(value: Any, unit: str = "") -> str:
    """A value as shown in a message: numbers (numpy's too) plainly with their unit, anything
    else as repr."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return repr(value)
    text = str(int(value)) if isinstance(value, numbers.Integral) else f"{float(value):.10g}"
    return f"{text} {unit}" if unit else text


def not_a(name: str, value: Any, kind: type | str) -> str:
    what = kind if isinstance(kind, str) else KIND_WORDS.get(kind, f"a {kind.__name__}")
    return f"{name}={fmt_value(value)} is not {what}"


def above(name: str, value: float, limit: float, unit: str = "") -> str:
    return f"{name}={fmt_value(value, unit)} is above the limit {fmt_value(limit, unit)}"


def below(name: str, value: float, limit: float, unit: str = "") -> str:
    return f"{name}={fmt_value(value, unit)} is below the limit {fmt_value(limit, unit)}"


def not_below(name: str, value: float, limit: float, unit: str = "") -> str:
    """An open upper bound: `angle_deg=360 deg is not below the limit 360 deg`."""
    return f"{name}={fmt_value(value, unit)} is not below the limit {fmt_value(limit, unit)}"


def not_above(name: str, value: float, limit: float, unit: str = "") -> str:
    """An open lower bound: `accel_dps2=0 deg/s^2 is not above the limit 0 deg/s^2`."""
    return f"{name}={fmt_value(value, unit)} is not above the limit {fmt_value(limit, unit)}"


def not_one_of(name: str, value: Any, choices: Iterable[Any]) -> str:
    shown = [repr(c) if c == "" else str(c) for c in choices]  # an empty choice stays visible
    return f"{name}={fmt_value(value)} is not one of {', '.join(shown)}"


def missing_key(name: str, expected: str) -> str:
    return f"{name}: missing key ({expected})"


def unknown_name(name: str, what: str, allowed: Iterable[str]) -> str:
    """`nosuchparam: not a parameter of table-spin (allowed: a, b)`; `hots: unknown key (...)`."""
    names = ", ".join(sorted(allowed)) or "none"
    return f"{name}: {what} (allowed: {names})"


def range_text(low: float | None, high: float | None, unit: str = "") -> str:
    """`0 to 1000 deg/s`, `at least 0 s`, `at most 5 V`, or '' when unbounded."""
    if low is not None and high is not None:
        return f"{fmt_value(low)} to {fmt_value(high, unit)}"
    if low is not None:
        return f"at least {fmt_value(low, unit)}"
    if high is not None:
        return f"at most {fmt_value(high, unit)}"
    return ""


def convert(
    name: str,
    value: Any,
    kind: type,
    *,
    low: float | None = None,
    high: float | None = None,
    unit: str = "",
    choices: Iterable[Any] | None = None,
    parse_text: bool = False,
    low_open: bool = False,
    high_open: bool = False,
) -> Any:
    """`value` as `kind` (float, int, bool, str), within [low, high] (an open end with low_open,
    high_open) and `choices`, or ValidationError.  With parse_text a string (from `--set`, a
    form) is parsed first; surrounding spaces never count."""
    if parse_text and isinstance(value, str) and kind is str:
        value = value.strip()
    elif parse_text and isinstance(value, str):
        text = value.strip()
        try:
            if kind is bool:
                if text.lower() not in TRUE_WORDS + FALSE_WORDS:
                    raise ValueError(text)
                value = text.lower() in TRUE_WORDS
            elif kind is int:
                value = int(text) if text.lstrip("+-").isdigit() else int(text, 0)  # 010 and 0x10 both
            elif kind is float:
                value = float(text)
        except ValueError:
            raise ValidationError(not_a(name, value, kind)) from None
    if isinstance(value, numbers.Real) and not isinstance(value, bool):  # numpy's scalars too
        if kind is float:
            value = float(value)
        elif kind is int and isinstance(value, numbers.Integral):
            value = int(value)
        elif kind is int and float(value).is_integer():
            value = int(value)
    if not isinstance(value, kind) or (kind in (int, float) and isinstance(value, bool)):
        raise ValidationError(not_a(name, value, kind))
    if choices is not None:
        choices = tuple(choices)
        if value not in choices:
            raise ValidationError(not_one_of(name, value, choices))
    if kind in (int, float):
        if isinstance(value, float) and not math.isfinite(value):
            raise ValidationError(not_a(name, value, "a finite number"))
        if low is not None and value < low:
            raise ValidationError(below(name, value, low, unit))
        if high is not None and value > high:
            raise ValidationError(above(name, value, high, unit))
        if low_open and value == low:
            raise ValidationError(not_above(name, value, low, unit))
        if high_open and value == high:
            raise ValidationError(not_below(name, value, high, unit))
    return value


def check_limit(name: str, value: Any, kind: type = float, *, low: float | None = None, high: float | None = None,
                unit: str = "", low_open: bool = False, high_open: bool = False) -> Any:
    """A driver's check of a value it is about to write: `convert`, raising LimitError (which the
    engine tells apart from a lost link) in the same words."""
    try:
        return convert(name, value, kind, low=low, high=high, unit=unit, low_open=low_open, high_open=high_open)
    except ValidationError as exc:
        lo = fmt_value(-math.inf if low is None else low)
        hi = fmt_value(math.inf if high is None else high)
        limit = f"{'(' if low_open else '['}{lo}, {hi}{')' if high_open else ']'}"
        raise LimitError(name, value, limit, unit, message=str(exc)) from None


def parse_assignment(item: str, option: str = "--set") -> tuple[str, str]:
    """`NAME=VALUE` from the command line as (name, value text); ValidationError otherwise."""
    name, sep, value = item.partition("=")
    if not sep or not name.strip():
        raise ValidationError(f"{option} {item!r}: expected NAME=VALUE, e.g. {option} rate_dps=200")
    return name.strip(), value


#: the longest DUT serial, operator name or station id: a column every store takes as text
MAX_LABEL_CHARS = 64


def check_label(name: str, value: Any, *, max_chars: int = MAX_LABEL_CHARS, allow_empty: bool = False) -> str:
    """A name a person types that ends up in records and on screens (a DUT serial, an operator, a
    station id): text of at most max_chars printable characters, no NUL or control character, so
    no store rejects it later and no terminal runs it as an escape."""
    if not isinstance(value, str):
        raise ValidationError(not_a(name, value, str))
    if not value.strip():
        if allow_empty and not value:
            return value
        raise ValidationError(f"{name}={value!r} is empty")
    if len(value) > max_chars:
        raise ValidationError(f"{name}={value[:20]!r}... has {len(value)} characters, above the limit {max_chars}")
    bad = next((ch for ch in value if not ch.isprintable()), None)
    if bad is not None:
        what = "NUL" if bad == "\0" else f"U+{ord(bad):04X}"
        raise ValidationError(f"{name}={value!r} holds a control character ({what}); only printable text is allowed")
    return value


def printable(text: Any) -> str:
    """A stored value as a screen shows it: control characters (escapes, newlines) spelled out as
    in repr, so a record written before labels were checked cannot move a terminal's cursor."""
    s = str(text)
    return s if s.isprintable() else "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in s)
