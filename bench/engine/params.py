"""Typed procedure parameters with units, defaults and limits, validated before any device moves.

A parameter is declared once, at class level, where it is documented:

    rate_dps = Param(100.0, unit="deg/s", low=-500.0, high=500.0, doc="table rate")

Reading `self.rate_dps` on a procedure instance gives the validated value for this run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bench.validation import KIND_WORDS, ValidationError, convert, not_a, range_text, unknown_name


class ParamError(ValidationError):
    """A procedure parameter is unknown, of the wrong type or outside its limits.  The message
    names the parameter, the value and the limit (wording: bench.validation)."""

    def __init__(self, name: str, value: Any, limit: str, message: str) -> None:
        self.name, self.value, self.limit = name, value, limit
        super().__init__(message)


_MISSING = object()


@dataclass
class Param:
    """A typed parameter: default, unit, inclusive limits [low, high], optional choices."""

    default: Any
    unit: str = ""
    low: float | None = None
    high: float | None = None
    doc: str = ""
    choices: tuple[Any, ...] | None = None
    type: type | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if self.type is None:
            self.type = type(self.default)
        if self.type is int and isinstance(self.default, bool):
            self.type = bool

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, objtype: type | None = None) -> Any:
        if obj is None:
            return self
        return obj.params.get(self.name, self.default)

    def limit_text(self) -> str:
        """What is allowed, as text (the window's tooltip, ParamError.limit): `-1000 to 1000 deg/s`."""
        if self.choices is not None:
            return "one of " + ", ".join(map(str, self.choices))
        if self.type in (int, float):
            return range_text(self.low, self.high, self.unit) or "any number"
        return KIND_WORDS.get(self.type, f"a {self.type.__name__}")

    def convert(self, value: Any) -> Any:
        """Parse (a string from `--set name=value`) and check a value; ParamError if bad."""
        typ = self.type
        if typ not in (float, int, bool, str):
            try:  # a parameter of another type takes its text through its constructor
                value = typ(value) if isinstance(value, str) else value
            except (TypeError, ValueError):
                raise ParamError(self.name, value, self.limit_text(), not_a(self.name, value, typ)) from None
        try:
            return convert(
                self.name,
                value,
                typ,
                low=self.low,
                high=self.high,
                unit=self.unit,
                choices=self.choices,
                parse_text=True,
            )
        except ValidationError as exc:
            raise ParamError(self.name, value, self.limit_text(), str(exc)) from None

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "default": self.default,
            "unit": self.unit,
            "low": self.low,
            "high": self.high,
            "choices": list(self.choices) if self.choices is not None else None,
            "doc": self.doc,
        }


def declared_params(cls: type) -> dict[str, Param]:
    """Every Param of a procedure class (base classes first), by name."""
    out: dict[str, Param] = {}
    for klass in reversed(cls.__mro__):
        for name, value in vars(klass).items():
            if isinstance(value, Param):
                out[name] = value
    return out


def resolve_params(cls: type, given: dict[str, Any] | None) -> dict[str, Any]:
    """Defaults overlaid with `given`, each converted and checked; ParamError on the first bad one."""
    decl = declared_params(cls)
    given = dict(given or {})
    unknown = sorted(set(given) - set(decl))
    if unknown:
        owner = getattr(cls, "name", "") or cls.__name__
        msg = unknown_name(unknown[0], f"not a parameter of {owner}", decl)
        raise ParamError(unknown[0], given[unknown[0]], "a declared parameter: " + ", ".join(sorted(decl)), msg)
    values: dict[str, Any] = {}
    for name, p in decl.items():
        values[name] = p.convert(given[name]) if name in given else p.convert(p.default)
    return values
