"""A database URL's password is never stored or printed: `redact` replaces it with `***` in a
string, or in every string of a nested dict/list (station keys before they go into a raw file)."""

from __future__ import annotations

import re
from typing import Any

# scheme://user:password@host  (the password up to the last "@" before the host part)
_URL_PASSWORD = re.compile(r"(?P<head>[A-Za-z][A-Za-z0-9+.-]*://[^:/@\s]*:)(?P<pw>[^\s/]*)(?P<at>@)")
# key=value pairs in a libpq connection string or a URL query
_KV_PASSWORD = re.compile(r"(?P<head>\bpassword\s*=\s*)(?P<pw>'[^']*'|[^\s&]+)", re.IGNORECASE)
MASK = "***"


def redact_text(text: str) -> str:
    """`text` with any URL password and `password=` value masked."""
    text = _URL_PASSWORD.sub(lambda m: f"{m['head']}{MASK}{m['at']}", text)
    return _KV_PASSWORD.sub(lambda m: f"{m['head']}{MASK}", text)


def redact(value: Any) -> Any:
    """A copy of `value` with every string redacted (dicts, lists and tuples walked)."""
    if isinstance(value, str):
        return redact_text(value)
    if isinstance(value, dict):
        return {k: redact(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(redact(v) for v in value)
    return value
