"""Whether a station may run line units: its calibration due dates (the station file's
`[calibration]`), and its lock (a golden unit's drift past its limit locks the station until an
unlock with a reason).  Files under RUNS_DIR/line/stations/ (docs/line.md "Station calibration
and the golden unit"):

- `STATION.lock.json`: the lock (when, why, the golden check that set it); absent when unlocked;
- `STATION.log.jsonl`: one JSON line per lock, unlock and golden check, for the audit and the report."""

from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path
from typing import Any

from . import LineError
from .record import _safe, now_iso


def overdue(calibration: dict[str, _dt.date], today: _dt.date) -> list[str]:
    """The devices whose calibration is past due on `today`, each as `NAME (due DATE, N days ago)`."""
    out = []
    for name, due in sorted(calibration.items(), key=lambda kv: kv[1]):
        if due < today:
            out.append(f"{name} (due {due.isoformat()}, {(today - due).days} days ago)")
    return out


def _folder(runs_dir: str | Path) -> Path:
    return Path(runs_dir) / "line" / "stations"


def lock_path(runs_dir: str | Path, station: str) -> Path:
    return _folder(runs_dir) / f"{_safe(station)}.lock.json"


def log_path(runs_dir: str | Path, station: str) -> Path:
    return _folder(runs_dir) / f"{_safe(station)}.log.jsonl"


def append_log(runs_dir: str | Path, station: str, entry: dict[str, Any]) -> None:
    path = log_path(runs_dir, station)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps({"at": now_iso(), "station": station, **entry}, sort_keys=True) + "\n")


def read_log(runs_dir: str | Path, station: str | None = None) -> list[dict[str, Any]]:
    """The log entries of one station (or every station), oldest first."""
    paths = [log_path(runs_dir, station)] if station else sorted(_folder(runs_dir).glob("*.log.jsonl"))
    out = []
    for p in paths:
        if p.exists():
            out += [json.loads(line) for line in p.read_text(encoding="utf-8").splitlines() if line.strip()]
    return sorted(out, key=lambda e: e.get("at", ""))


def current_lock(runs_dir: str | Path, station: str) -> dict[str, Any] | None:
    path = lock_path(runs_dir, station)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None


def lock(runs_dir: str | Path, station: str, reason: str, **extra: Any) -> dict[str, Any]:
    """Lock the station for line runs (kept until `unlock`)."""
    entry = {"at": now_iso(), "station": station, "reason": reason, **extra}
    path = lock_path(runs_dir, station)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(entry, indent=1), encoding="utf-8")
    os.replace(tmp, path)
    append_log(runs_dir, station, {"event": "lock", "reason": reason, **extra})
    return entry


def unlock(runs_dir: str | Path, station: str, reason: str, operator: str) -> dict[str, Any]:
    """Remove the station's lock; the reason and who are logged.  LineError when it is not locked
    or no reason is given."""
    if not reason.strip():
        raise LineError("line unlock: --reason TEXT is required (it is logged with the unlock)")
    held = current_lock(runs_dir, station)
    if held is None:
        raise LineError(f"station {station!r} is not locked")
    lock_path(runs_dir, station).unlink()
    append_log(runs_dir, station, {"event": "unlock", "reason": reason, "operator": operator, "lock": held})
    return held


def refusal(calibration: dict[str, _dt.date], runs_dir: str | Path, station: str,
            today: _dt.date | None = None, lock_too: bool = True) -> str | None:
    """Why the station refuses line runs (calibration past due, a lock), or None."""
    today = today or _dt.datetime.now(_dt.UTC).date()
    why = []
    late = overdue(calibration, today)
    if late:
        why.append("calibration past due: " + ", ".join(late))
    held = current_lock(runs_dir, station) if lock_too else None
    if held is not None:
        why.append(f"locked since {held['at']}: {held['reason']} "
                   f"(`gyrobench line unlock --station {station} --reason TEXT` after the cause is fixed)")
    return f"station {station!r} refuses line runs: " + "; ".join(why) if why else None
