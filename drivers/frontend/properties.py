"""A small declarative property layer for SCPI instruments, in the PyMeasure idiom.

A device property is declared once at class level from its command strings, a validator, its
allowed values and its unit: `amplitude_v = control("SOUR{ch}:VOLT?", "SOUR{ch}:VOLT {value}",
"Drive amplitude.", validator=strict_range, values=(0, 10), unit="V")`.  Reading it sends the
query and parses the reply; writing it validates (raising LimitError before anything is sent),
then hands the command to the owner's `_set(command)`, which confirms it through the error queue.
`{ch}` in a command is filled from the owner's `channel_id`, so one declaration serves every
channel; `values` may be a callable of the owner, so a bench's limits apply at call time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from bench.validation import check_limit, not_one_of
from drivers.errors import LimitError, ProtocolError

Validator = Callable[[str, Any, Any, str], Any]


def strict_range(name: str, value: Any, values: tuple[float, float], unit: str = "") -> float:
    """A finite number within [lo, hi]; LimitError otherwise (bench.validation's words)."""
    return check_limit(name, value, float, low=values[0], high=values[1], unit=unit)


def strict_int_range(name: str, value: Any, values: tuple[int, int], unit: str = "") -> int:
    """An integer within [lo, hi]; LimitError otherwise (floats with a fraction are refused)."""
    return check_limit(name, value, int, low=values[0], high=values[1], unit=unit)


def strict_discrete_set(name: str, value: Any, values: Sequence[Any], unit: str = "") -> Any:
    """One of the listed values (numbers compared with a 1e-9 relative tolerance)."""
    for v in values:
        if isinstance(v, (int, float)) and isinstance(value, (int, float)) and not isinstance(value, bool):
            if math.isclose(float(value), float(v), rel_tol=1e-9):
                return v
        elif value == v:
            return v
    raise LimitError(name, value, f"one of {list(values)}", unit, message=not_one_of(name, value, values))


def boolean(name: str, value: Any, values: Any = None, unit: str = "") -> bool:
    """True or False only (1 and 0 are not silently accepted as on/off)."""
    return check_limit(name, value, bool)


def format_float(value: float) -> str:
    """Enough digits to round-trip a float64 exactly."""
    return repr(float(value))


def parse_float(reply: str) -> float:
    """A finite number; ValueError for anything else (NaN and inf are never a setting's value)."""
    x = float(reply)
    if not math.isfinite(x):
        raise ValueError(f"{reply!r} is not a finite number")
    return x


def parse_bool(reply: str) -> bool:
    text = reply.strip().upper()
    if text in ("1", "ON"):
        return True
    if text in ("0", "OFF"):
        return False
    raise ValueError(f"not a boolean: {reply!r}")


class control:  # noqa: N801 - a descriptor factory named as PyMeasure names it
    """A read/write instrument property declared from its command strings."""

    def __init__(
        self,
        get_cmd: str | None,
        set_cmd: str | None,
        doc: str,
        *,
        validator: Validator = strict_range,
        values: Any = None,
        unit: str = "",
        get_parser: Callable[[str], Any] = parse_float,
        set_formatter: Callable[[Any], str] = format_float,
    ) -> None:
        self.get_cmd, self.set_cmd = get_cmd, set_cmd
        self.__doc__ = f"{doc} [{unit}]" if unit else doc
        self.validator, self.values, self.unit = validator, values, unit
        self.get_parser, self.set_formatter = get_parser, set_formatter
        self.name = "?"

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def _fill(self, owner: Any, cmd: str, **extra: Any) -> str:
        return cmd.format(ch=getattr(owner, "channel_id", ""), **extra)

    def qualified_name(self, owner: Any) -> str:
        prefix = getattr(owner, "label", "")
        return f"{prefix}.{self.name}" if prefix else self.name

    def allowed(self, owner: Any) -> Any:
        return self.values(owner) if callable(self.values) else self.values

    def validate(self, owner: Any, value: Any) -> Any:
        """Check a value against the validator; LimitError names the value and the limit."""
        return self.validator(self.qualified_name(owner), value, self.allowed(owner), self.unit)

    def __get__(self, owner: Any, objtype: type | None = None) -> Any:
        if owner is None:
            return self
        if self.get_cmd is None:
            raise AttributeError(f"{self.name} is write-only")
        cmd = self._fill(owner, self.get_cmd)
        reply = owner._query(cmd)
        try:
            return self.get_parser(reply)
        except (TypeError, ValueError):
            raise ProtocolError(f"{cmd!r} answered {reply!r}: not a valid {self.name}") from None

    def __set__(self, owner: Any, value: Any) -> None:
        if self.set_cmd is None:
            raise AttributeError(f"{self.name} is read-only")
        checked = self.validate(owner, value)
        owner._set(self._fill(owner, self.set_cmd, value=self.set_formatter(checked)))


def measurement(get_cmd: str, doc: str, *, unit: str = "", get_parser: Callable[[str], Any] = parse_float) -> control:
    """A read-only property."""
    return control(get_cmd, None, doc, unit=unit, get_parser=get_parser)
