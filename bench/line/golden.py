"""A golden unit: a known serial with reference values, run at shift start; each measurement's drift
from its reference against its limit (docs/line.md "Station calibration and the golden unit").

    [golden]
    serial = "HRG-GOLD-01"
    sequence = "eol-hrg"           # optional: the sequence the references were taken with

    [reference.tau_s]
    value = 300.0                  # the reference value
    limit = 2.0                    # |measured - reference| allowed, in the unit
    unit = "s"
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import LineError
from .tomlfile import read_toml


@dataclass(frozen=True)
class Reference:
    """One reference value and the drift allowed from it."""

    name: str
    value: float
    limit: float
    unit: str = ""


@dataclass(frozen=True)
class Golden:
    source: str
    serial: str
    sequence: str
    references: tuple[Reference, ...]


def load_golden(path: str | Path) -> Golden:
    """Read and check a golden file; LineError names the key and the value."""
    path = Path(path)
    if not path.is_file():
        raise LineError(f"golden file {path} not found")
    raw = read_toml(path)
    head = raw.get("golden")
    if not isinstance(head, dict) or not str(head.get("serial") or "").strip():
        raise LineError(f'{path}: missing [golden] serial = "..."')
    refs = []
    for name, body in (raw.get("reference") or {}).items():
        try:
            value, limit = float(body["value"]), float(body["limit"])
        except (KeyError, TypeError, ValueError):
            raise LineError(f"{path}: [reference.{name}] needs value and limit as numbers") from None
        if not (math.isfinite(value) and math.isfinite(limit) and limit > 0):
            raise LineError(f"{path}: [reference.{name}] value={value!r} limit={limit!r}: finite, limit above 0")
        refs.append(Reference(name, value, limit, str(body.get("unit", ""))))
    if not refs:
        raise LineError(f"{path}: no [reference.NAME] table (value, limit, unit)")
    return Golden(str(path), str(head["serial"]).strip().upper(), str(head.get("sequence", "")), tuple(refs))


def drifts(record: dict[str, Any], golden: Golden) -> list[dict[str, Any]]:
    """Each reference's drift: the record's value of that measurement (the first with a value)
    minus the reference, against the limit; `ok` False past the limit or when not measured."""
    out = []
    for ref in golden.references:
        values = [m["value"] for m in record.get("measurements") or () if m.get("name") == ref.name
                  and m.get("value") is not None]
        if not values:
            out.append({"name": ref.name, "unit": ref.unit, "reference": ref.value, "limit": ref.limit,
                        "value": None, "drift": None, "ok": False, "note": "not measured"})
            continue
        drift = float(values[0]) - ref.value
        out.append({"name": ref.name, "unit": ref.unit, "reference": ref.value, "limit": ref.limit,
                    "value": float(values[0]), "drift": drift, "ok": abs(drift) <= ref.limit, "note": ""})
    return out


def lock_reason(serial: str, rows: list[dict[str, Any]]) -> str | None:
    """The lock's reason when a drift is past its limit (or a reference was not measured), else None."""
    bad = [r for r in rows if not r["ok"]]
    if not bad:
        return None
    words = [f"{r['name']} not measured" if r["drift"] is None else
             f"{r['name']} drifted {r['drift']:+.4g} {r['unit']} from {r['reference']:.6g} (limit ±{r['limit']:g})"
             for r in bad]
    return f"golden unit {serial}: " + "; ".join(words)
