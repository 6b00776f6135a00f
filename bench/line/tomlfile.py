"""Read a line file (sequence, limits) as TOML, one clear message on a file that cannot be read."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from bench.validation import ValidationError, convert, missing_key, not_a, unknown_name

from . import LineError

HERE = Path(__file__).resolve().parent


def find_file(text: str | Path, folder: str, what: str) -> Path:
    """A shipped name (`eol-hrg`) in bench/line/<folder>/, or a path to a TOML file."""
    shipped = {p.stem: p for p in sorted((HERE / folder).glob("*.toml"))}
    if str(text) in shipped:
        return shipped[str(text)]
    path = Path(text)
    if path.is_file():
        return path.resolve()  # the record names the file wherever the command ran
    raise LineError(f"{text}: no such {what} file or shipped {what} (shipped: {', '.join(shipped) or 'none'})")


def shipped(folder: str) -> dict[str, Path]:
    return {p.stem: p for p in sorted((HERE / folder).glob("*.toml"))}


def read_toml(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise LineError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise LineError(f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset {exc.start})") from None
    except OSError as exc:
        raise LineError(f"{path}: cannot be read: {exc.strerror or exc}") from None


def table(where: str, raw: Any, keys: dict[str, tuple], *, name: str = "") -> dict[str, Any]:
    """Check a TOML table against keys {name: (type, default, low, high, choices, required)}."""
    if not isinstance(raw, dict):
        raise LineError(f"{where} {not_a(name or 'table', raw, 'a table')}")
    for key in raw:
        if key not in keys:
            raise LineError(f"{where} {unknown_name(key, 'unknown key', keys)}")
    out: dict[str, Any] = {}
    for key, (kind, default, low, high, choices, required) in keys.items():
        if key not in raw:
            if required:
                raise LineError(f"{where} {missing_key(key, 'required')}")
            out[key] = default
            continue
        value = raw[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if kind in (dict, list):
            if not isinstance(value, kind):
                raise LineError(f"{where} {not_a(key, value, 'a table' if kind is dict else 'a list')}")
            out[key] = value
            continue
        try:
            out[key] = convert(key, value, kind, low=low, high=high, choices=choices)
        except ValidationError as exc:
            raise LineError(f"{where} {exc}") from None
    return out
