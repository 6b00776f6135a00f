"""Routing rules: whether a unit may be tested (again) by a sequence, from every attempt of its
serial on any station and in any command (the line database and the records on disk):

- a unit whose last attempt PASSED is not retested without a reason (`--retest-reason TEXT`);
- a unit whose last attempt FAILED is retested only after rework (`--rework CODE`);
- at most the sequence's `max_attempts` attempts, counted since the last rework or retest reason
  (a rework or a reason starts the count again; both are kept in the record).

A FAIL is never retested inside one command (it needs rework first); MARGINAL, ERROR and ABORTED
are, as the sequence's [retest] says, within the same count."""

from __future__ import annotations

import glob
import json
from pathlib import Path
from typing import Any

from . import LineError
from .record import _safe
from .verdict import FAIL, PASS


def disk_records(runs_dir: str | Path, serial: str) -> list[dict[str, Any]]:
    """Every record of the serial under RUNS_DIR/line/*/ (any lot)."""
    pattern = str(Path(glob.escape(str(runs_dir))) / "line" / "*" / f"{glob.escape(_safe(serial))}-a*.json")
    out = []
    for f in sorted(glob.glob(pattern)):
        try:
            rec = json.loads(Path(f).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(rec, dict) and rec.get("serial") == serial:
            out.append(rec)
    return out


def history(db: Any, runs_dir: str | Path, serial: str) -> list[dict[str, Any]]:
    """The serial's attempts, oldest first: the database's (RUNNING and INTERRUPTED too) and the
    files on disk, one each (by start time)."""
    seen: dict[tuple[str, str], dict[str, Any]] = {}
    for rec in disk_records(runs_dir, serial):
        seen[(rec.get("started_at", ""), rec.get("station", ""))] = rec
    if db is not None and hasattr(db, "records"):
        for rec in db.records(serial=serial, open_too=True):
            key = (rec.get("started_at", ""), rec.get("station", ""))
            if key not in seen or seen[key].get("outcome") in ("RUNNING", "INTERRUPTED"):
                seen.setdefault(key, rec)
    return sorted(seen.values(), key=lambda r: (r.get("started_at", ""), r.get("attempt", 0)))


def next_attempt(attempts: list[dict[str, Any]]) -> int:
    """One more than the highest attempt number on disk or in the database."""
    return max((int(r.get("attempt") or 0) for r in attempts), default=0) + 1


def route(attempts: list[dict[str, Any]], serial: str, sequence: Any, *, rework: str | None = None,
          retest_reason: str | None = None) -> tuple[dict[str, Any], int]:
    """The routing of a new attempt of serial by sequence: its record entry and how many attempts
    this command may run; LineError says why a unit may not be tested and what to give."""
    mine = [r for r in attempts if r.get("sequence") == sequence.name]
    last = mine[-1] if mine else None
    where = "" if last is None else (f" (attempt {last.get('attempt')} on station {last.get('station')}, "
                                     f"{str(last.get('ended_at') or last.get('started_at') or '')[:19]})")
    if last is not None and last.get("outcome") == PASS and not retest_reason:
        raise LineError(f"unit {serial} passed {sequence.name}{where}: a retest needs --retest-reason TEXT")
    if last is not None and last.get("outcome") == FAIL and not rework:
        raise LineError(f"unit {serial} failed {sequence.name}{where}: a retest needs --rework CODE "
                        "(what was done to it)")
    since = 0
    for r in reversed(mine):
        since += 1
        if (r.get("routing") or {}).get("rework") or (r.get("routing") or {}).get("retest_reason"):
            break
    if rework or retest_reason:
        since = 0
    left = sequence.max_attempts - since
    if left <= 0:
        raise LineError(f"unit {serial} has had {since} attempt(s) of {sequence.name} (max_attempts "
                        f"{sequence.max_attempts}){where}: another needs --rework CODE")
    routing = {"prior_attempts": len(mine), "rework": rework, "retest_reason": retest_reason,
               "last_outcome": None if last is None else last.get("outcome")}
    return routing, left
