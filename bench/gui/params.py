"""What the parameter form needs to know of a procedure parameter, and its validation.

The engine declares parameters on procedures; `spec_from_declared` reads them into `ParamSpec`
(duck-typed, so the form does not depend on the engine's class layout).  Validation happens in
the form before Start is enabled, and again in the engine before any device moves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from bench.validation import ValidationError, convert, not_one_of


@dataclass(frozen=True)
class ParamSpec:
    """One typed procedure parameter: name, kind (float | int | bool | str | choice), unit,
    default, limits (inclusive, None = unbounded), choices, one-line help."""

    name: str
    kind: str = "float"
    unit: str = ""
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] = ()
    doc: str = ""

    def parse(self, text: str) -> Any:
        """The value typed in the form, or ValueError naming the value and the limit (the wording
        of bench.validation, the same as the engine's and the station file's)."""
        text = text.strip()
        if self.kind == "choice":
            for c in self.choices:
                if str(c) == text:
                    return c
            raise ValidationError(not_one_of(self.name, text, self.choices))
        kind = {"float": float, "int": int, "bool": bool, "str": str}.get(self.kind, float)
        return convert(self.name, text, kind, low=self.low, high=self.high, unit=self.unit, parse_text=True)

    def format(self, value: Any) -> str:
        if value is None:
            return ""
        if self.kind == "float" and isinstance(value, float):
            return f"{value:g}"
        return str(value)


def _first_attr(obj: Any, names: tuple[str, ...], default: Any = None) -> Any:
    for n in names:
        if isinstance(obj, dict) and n in obj:
            return obj[n]
        if hasattr(obj, n):
            return getattr(obj, n)
    return default


def spec_from_declared(name: str, declared: Any) -> ParamSpec:
    """A ParamSpec from an engine parameter declaration (object or dict) with whatever of
    unit / default / low, high or limits / choices / kind or type / doc it carries."""
    default = _first_attr(declared, ("default",))
    kind = _first_attr(declared, ("kind", "type", "dtype"))
    choices = tuple(_first_attr(declared, ("choices", "options"), ()) or ())
    if isinstance(kind, type):
        kind = {float: "float", int: "int", bool: "bool", str: "str"}.get(kind, "float")
    if kind is None:
        if choices:
            kind = "choice"
        elif isinstance(default, bool):
            kind = "bool"
        elif isinstance(default, int):
            kind = "int"
        elif isinstance(default, str):
            kind = "str"
        else:
            kind = "float"
    if choices and kind == "str":
        kind = "choice"
    low = _first_attr(declared, ("low", "minimum", "min_value", "lo"))
    high = _first_attr(declared, ("high", "maximum", "max_value", "hi"))
    limits = _first_attr(declared, ("limits", "bounds"))
    if limits is not None and low is None and high is None:
        low, high = limits
    return ParamSpec(
        name=_first_attr(declared, ("name",), name) or name,
        kind=str(kind),
        unit=str(_first_attr(declared, ("unit", "units"), "") or ""),
        default=default,
        low=None if low is None else float(low),
        high=None if high is None else float(high),
        choices=choices,
        doc=str(_first_attr(declared, ("doc", "help", "description"), "") or ""),
    )
