"""What an operator or a command line types into the line (serials, lots, operators, rework codes,
reasons), checked before anything runs: a length limit, no control characters or NUL, and the
product's own format (a regex per product in its limits file, `[product] serial_format` and
`lot_format`).  A lot names a folder under RUNS_DIR/line/, so it can never be a path."""

from __future__ import annotations

import re
import unicodedata

from . import LineError

SERIAL_FORMAT = r"[A-Z0-9][A-Z0-9._-]{0,39}"
LOT_FORMAT = r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}"
REWORK_FORMAT = r"[A-Z0-9][A-Z0-9._-]{0,31}"
MAX_CHARS = {"serial": 40, "lot": 64, "operator": 64, "station": 64, "rework code": 32, "retest reason": 200}


def _printable_problem(text: str) -> str | None:
    """Why text cannot go into a record, a file name or a terminal (None: it can)."""
    for i, ch in enumerate(text):
        if ch == "\x00":
            return f"a NUL character at position {i + 1}"
        if unicodedata.category(ch) in ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"):
            return f"a control character {ch!r} at position {i + 1}"
    return None


def check_text(kind: str, text: str, fmt: str | None = None, *, upper: bool = False) -> str:
    """One typed value: stripped (upper-cased with upper), within its length, printable and, with
    fmt, matching it whole; LineError names the value (escaped), what is wrong and the rule."""
    typed = str(text).strip()
    value = typed.upper() if upper else typed
    limit = MAX_CHARS.get(kind, 64)
    shown = repr(typed if len(typed) <= 60 else typed[:60] + "...")  # as typed, escaped by repr
    if not value:
        raise LineError(f"{kind} '' is not valid: it is empty (give 1 to {limit} characters)")
    if len(value) > limit:
        raise LineError(f"{kind} {shown} is not valid: {len(value)} characters, the limit is {limit}")
    problem = _printable_problem(value)
    if problem is not None:
        raise LineError(f"{kind} {shown} is not valid: {problem} (only printable characters)")
    if fmt is not None and not re.fullmatch(fmt, value):
        raise LineError(f"{kind} {shown} is not valid: it does not match the format {fmt}")
    return value


def check_serial(text: str, fmt: str | None = None) -> str:
    """A serial, upper-cased, against the product's format (default SERIAL_FORMAT)."""
    return check_text("serial", text, fmt or SERIAL_FORMAT, upper=True)


def check_lot(text: str, fmt: str | None = None) -> str:
    """A lot ('' = none), against the product's format; never a path ('/', '..', absolute)."""
    if not str(text).strip():
        return ""
    lot = check_text("lot", text, fmt or LOT_FORMAT)
    if "/" in lot or "\\" in lot or lot in (".", "..") or lot.startswith("."):
        raise LineError(f"lot {lot!r} is not valid: it names a path (a lot is a folder name under RUNS_DIR/line/)")
    return lot


def check_operator(text: str) -> str:
    """An operator's name: printable, within its length."""
    return check_text("operator", text)


def check_rework(text: str) -> str:
    """A rework code (what was done to a failed unit), e.g. RW-12."""
    return check_text("rework code", text, REWORK_FORMAT, upper=True)


def check_reason(text: str) -> str:
    """Why a passed unit is tested again (free text, printable)."""
    return check_text("retest reason", text)
