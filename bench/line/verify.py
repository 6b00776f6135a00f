"""`gyrobench line verify LOT` and the checks `line import` makes: every record of a lot (the files
under RUNS_DIR/line/LOT/ and the line database's rows) against its hash and signature, its raw
files against their SHA-256, and its station's chain (each record names the hash of the one
before it); the breaks in the order the records were written, the first named first."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .integrity import raw_file_problems, record_hash, signature_problem

OPEN = ("RUNNING", "INTERRUPTED")


@dataclass
class Verdict:
    """What `line verify` found: records checked, breaks (first first) and notes."""

    records: int = 0
    stations: set[str] = field(default_factory=set)
    breaks: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _name(rec: dict[str, Any]) -> str:
    return f"{rec.get('serial')}-a{rec.get('attempt')}"


def lot_files(runs_dir: str | Path, lot: str) -> list[tuple[Path, dict[str, Any] | None]]:
    """The record files of a lot folder (a file that is not JSON: None)."""
    out = []
    for f in sorted((Path(runs_dir) / "line" / (lot or "no-lot")).glob("*.json")):
        if f.name.startswith("."):
            continue
        try:
            rec = json.loads(f.read_text())
        except (OSError, ValueError):
            rec = None
        out.append((f, rec if isinstance(rec, dict) else None))
    return out


class _Predecessors:
    """Records of a station by chain index, looked for in the database, then in every lot on disk."""

    def __init__(self, db: Any, runs_dir: str | Path) -> None:
        self.db, self.runs_dir = db, Path(runs_dir)
        self._disk: dict[tuple[str, int], list[dict[str, Any]]] | None = None

    def at(self, station: str, index: int) -> list[dict[str, Any]]:
        found = {}
        if self.db is not None:
            for rec in self.db.records_at(station, index):
                found[record_hash(rec)] = rec
        if self._disk is None:
            self._disk = {}
            for f in self.runs_dir.glob("line/*/*.json"):
                try:
                    rec = json.loads(f.read_text())
                    ch = rec["chain"]
                    self._disk.setdefault((ch["station"], int(ch["index"])), []).append(rec)
                except (OSError, ValueError, KeyError, TypeError):
                    continue
        for rec in self._disk.get((station, index), []):
            found.setdefault(record_hash(rec), rec)
        return list(found.values())


def chain_problem(rec: dict[str, Any], preds: _Predecessors) -> str | None:
    """Whether the record follows the record its chain names (None: it does, or it is the first)."""
    ch = rec.get("chain") or {}
    index, prev, station = ch.get("index"), ch.get("prev_sha256"), ch.get("station")
    if not isinstance(index, int) or index < 1 or station is None:
        return "it holds no place in a station chain"
    if index == 1:
        return None if prev is None else "it is first in its chain but names a record before it"
    before = preds.at(station, index - 1)
    if not before:
        return f"station {station}'s record #{index - 1}, the one before it (#{index}), is missing"
    if all(record_hash(b) != prev for b in before):
        return (f"it does not follow station {station}'s record #{index - 1} ({_name(before[0])}): "
                "that record was edited or replaced")
    return None


def verify_lot(db: Any, runs_dir: str | Path, lot: str, trusted: set[str] | None = None) -> Verdict:
    """Every record of a lot, on disk and in the database, checked (see the module's docstring)."""
    out = Verdict()
    found: list[tuple[str, dict[str, Any], str]] = []  # (when, record, where)
    for f, rec in lot_files(runs_dir, lot):
        if rec is None:
            out.breaks.append(f"{f}: not a readable record")
        else:
            found.append((rec.get("ended_at") or "", rec, str(f)))
    in_db: dict[tuple, dict[str, Any]] = {}
    if db is not None:
        for rec in db.records(lot=lot or "", open_too=True):
            if rec.get("outcome") in OPEN and not rec.get("integrity"):
                out.notes.append(f"{_name(rec)} on station {rec.get('station')}: {rec.get('outcome')}, no record "
                                 f"({rec.get('end_reason') or 'still running'})")
                continue
            in_db[(rec.get("serial"), rec.get("attempt"), rec.get("started_at"))] = rec
    on_disk = {(r.get("serial"), r.get("attempt"), r.get("started_at")): r for _, r, _ in found}
    for key, rec in in_db.items():
        disk = on_disk.get(key)
        if disk is None:
            found.append((rec.get("ended_at") or "", rec, "the line database"))
        elif record_hash(disk) != record_hash(rec) or disk.get("integrity") != rec.get("integrity"):
            found.append((rec.get("ended_at") or "", rec, "the line database"))
            out.breaks.append(f"{_name(rec)}: its file and its database copy differ")
    for key in on_disk.keys() - in_db.keys():
        if db is not None:
            out.notes.append(f"{_name(on_disk[key])}: on disk, not in the line database (`gyrobench line import`)")
    preds = _Predecessors(db, runs_dir)
    ordered: list[tuple[str, str]] = []
    keys_by_station: dict[str, str] = {}
    for when, rec, where in sorted(found, key=lambda t: (t[0], str(t[1].get("attempt")))):
        out.records += 1
        station = (rec.get("chain") or {}).get("station") or rec.get("station") or "?"
        out.stations.add(station)
        problems = []
        sig = signature_problem(rec, trusted)
        if sig:
            problems.append(sig)
        kid = (rec.get("integrity") or {}).get("key_id")
        if kid and keys_by_station.setdefault(station, kid) != kid:
            problems.append(f"signed by key {kid}, the station's earlier records by {keys_by_station[station]}")
        if not sig or "not signed" in sig:
            problems += raw_file_problems(rec)
            chain = chain_problem(rec, preds)
            if chain:
                problems.append(chain)
        for p in problems:
            ordered.append((when, f"{_name(rec)} (station {station}, {where}): {p}"))
    out.breaks = [t for _, t in sorted(ordered, key=lambda x: x[0])] + out.breaks
    if trusted is None and out.records:
        out.notes.append("signatures checked against the keys the records carry: give --key STATION.pub "
                         "to require the stations' own keys")
    return out
