"""A product limits file (TOML): per declared measurement name its low/high and decision rule.

    [product]
    name = "hrg-5500"
    rule = "guard-band"        # the default rule: guard-band (on the 95 % interval) or value
    serial_format = "HRG-[0-9]{6}"   # optional: a regex every serial matches whole (upper case)
    lot_format = "L[0-9]{4}"         # optional: the same for lots (never a path)

    [limits.tau_s]
    low = 250.0                # either side may be left out (a one-sided limit)
    high = 400.0
    unit = "s"                 # optional: checked against the declared unit

    [limits.drift_after_dph]
    high = 5.0
    rule = "value"             # value-only, with an optional marginal band inside the limits
    marginal_high = 4.0

Every name must be a measurement some procedure declares (`gyrobench list`); a bad file is one
message naming the file, the key, the value and what was allowed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from . import LineError
from .inputs import LOT_FORMAT, SERIAL_FORMAT
from .tomlfile import find_file, read_toml, table
from .verdict import GUARD_BAND, RULES, Limit

PRODUCT_KEYS = {
    "name": (str, "", None, None, None, True),
    "description": (str, "", None, None, None, False),
    "rule": (str, GUARD_BAND, None, None, RULES, False),
    "serial_format": (str, SERIAL_FORMAT, None, None, None, False),
    "lot_format": (str, LOT_FORMAT, None, None, None, False),
}


def _limit_keys(default_rule: str) -> dict[str, tuple]:
    return {
        "low": (float, None, None, None, None, False),
        "high": (float, None, None, None, None, False),
        "rule": (str, default_rule, None, None, RULES, False),
        "marginal_low": (float, None, None, None, None, False),
        "marginal_high": (float, None, None, None, None, False),
        "unit": (str, None, None, None, None, False),
        "procedure": (str, None, None, None, None, False),
    }


@dataclass(frozen=True)
class ProductLimits:
    """A checked limits file: the product's name and its limits by measurement name."""

    source: str
    name: str
    description: str
    limits: tuple[Limit, ...]
    serial_format: str = SERIAL_FORMAT  # a regex a serial matches whole (after upper-casing)
    lot_format: str = LOT_FORMAT

    def for_procedure(self, procedure: str, declared: set[str]) -> list[Limit]:
        """The limits that apply to one procedure's declared measurements."""
        return [lim for lim in self.limits if lim.name in declared and lim.procedure in (None, procedure)]


def declared_measurements() -> dict[str, dict[str, str]]:
    """{measurement name: {procedure: unit}} over every registered procedure."""
    from procedures import all_procedures

    out: dict[str, dict[str, str]] = {}
    for pname, cls in all_procedures().items():
        for m in cls.measurements:
            out.setdefault(m.name, {})[pname] = m.unit
    return out


def load_limits(name_or_path: str | Path) -> ProductLimits:
    """Read and check a limits file (a shipped name such as `hrg` or a path)."""
    path = find_file(name_or_path, "limits", "limits")
    raw = read_toml(path)
    for top in raw:
        if top not in ("product", "limits"):
            raise LineError(f"{path}: unknown table [{top}] (allowed: product, limits)")
    if "product" not in raw:
        raise LineError(f'{path}: missing table [product] with name = "..."')
    product = table(f"{path}: [product]", raw["product"], PRODUCT_KEYS, name="product")
    for key in ("serial_format", "lot_format"):
        try:
            re.compile(product[key])
        except re.error as exc:
            raise LineError(f"{path}: [product] {key}={product[key]!r} is not a regular expression ({exc})") from None
    entries = raw.get("limits")
    if not isinstance(entries, dict) or not entries:
        raise LineError(f"{path}: missing table [limits.<measurement>] (at least one measurement's limits)")
    declared = declared_measurements()
    limits = []
    for mname, body in entries.items():
        where = f"{path}: [limits.{mname}]"
        if mname not in declared:
            raise LineError(f"{where} {mname!r} is not a measurement any procedure declares (`gyrobench list` "
                            "shows them)")
        t = table(where, body, _limit_keys(product["rule"]), name=f"limits.{mname}")
        if t["low"] is None and t["high"] is None:
            raise LineError(f"{where} missing key (low or high, or both)")
        if t["low"] is not None and t["high"] is not None and t["low"] > t["high"]:
            raise LineError(f"{where} low={t['low']:g} is above high={t['high']:g}")
        if t["procedure"] is not None and t["procedure"] not in declared[mname]:
            raise LineError(f"{where} procedure={t['procedure']!r} does not declare {mname!r} "
                            f"(declared by: {', '.join(sorted(declared[mname]))})")
        units = {u for p, u in declared[mname].items() if t["procedure"] in (None, p)}
        if t["unit"] is not None and t["unit"] not in units:
            raise LineError(f"{where} unit={t['unit']!r} is not the declared unit "
                            f"({', '.join(repr(u) for u in sorted(units))})")
        for side, bound in (("marginal_low", "low"), ("marginal_high", "high")):
            m, b = t[side], t[bound]
            if m is not None and t["rule"] != "value":
                raise LineError(f"{where} {side}={m:g}: a marginal band belongs to rule = \"value\"")
            if m is not None and b is not None and ((side == "marginal_low" and m < b) or
                                                    (side == "marginal_high" and m > b)):
                raise LineError(f"{where} {side}={m:g} lies outside {bound}={b:g} (the band is inside the limits)")
        limits.append(Limit(mname, t["low"], t["high"], t["rule"], t["marginal_low"], t["marginal_high"],
                            t["unit"], t["procedure"]))
    return ProductLimits(str(path), product["name"], product["description"], tuple(limits),
                         product["serial_format"], product["lot_format"])
