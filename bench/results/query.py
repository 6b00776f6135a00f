"""Find runs in the results store by procedure, station, DUT, outcome and start date (the
window's history browser and anything else that searches): one indexed query, newest first."""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select

from .schema import run_duts, runs

ROW_COLUMNS = ("run_id", "procedure", "station_id", "outcome", "started_at", "finished_at", "simulated_s",
               "end_reason", "raw_file", "simulated", "seed")


@dataclass(frozen=True)
class RunFilter:
    """What to look for; an empty field matches everything.  Dates are inclusive calendar days
    (UTC, as the store keeps `started_at`); `dut` matches a serial by substring."""

    procedure: str = ""
    station_id: str = ""
    dut: str = ""
    outcome: str = ""
    since: _dt.date | None = None
    until: _dt.date | None = None
    limit: int | None = 5000


def _where(flt: RunFilter) -> list[Any]:
    conds: list[Any] = []
    if flt.procedure:
        conds.append(runs.c.procedure == flt.procedure)
    if flt.station_id:
        conds.append(runs.c.station_id == flt.station_id)
    if flt.outcome:
        conds.append(runs.c.outcome == flt.outcome)
    if flt.since is not None:
        conds.append(runs.c.started_at >= flt.since.isoformat())
    if flt.until is not None:
        conds.append(runs.c.started_at < (flt.until + _dt.timedelta(days=1)).isoformat())
    if flt.dut:
        conds.append(runs.c.run_id.in_(select(run_duts.c.run_id).where(run_duts.c.serial.like(f"%{flt.dut}%"))))
    return conds


def find_runs(store: Any, flt: RunFilter) -> tuple[list[dict[str, Any]], int]:
    """(rows newest first, at most flt.limit, each with its `duts` joined by ", "; the number of
    runs that match).  RUNNING rows whose run is gone are first marked INTERRUPTED."""
    store._reap_quietly()
    conds = _where(flt)
    cols = [getattr(runs.c, c) for c in ROW_COLUMNS]
    q = select(*cols).where(*conds).order_by(runs.c.started_at.desc())
    if flt.limit is not None:
        q = q.limit(flt.limit)
    with store.engine.connect() as conn:
        rows = [dict(r._mapping) for r in conn.execute(q)]
        total = len(rows)
        if flt.limit is not None and total >= flt.limit:
            total = conn.execute(select(func.count()).select_from(runs).where(*conds)).scalar_one()
        duts: dict[str, list[str]] = {}
        ids = [r["run_id"] for r in rows]
        for i in range(0, len(ids), 900):  # below SQLite's bound-parameter limit
            part = ids[i:i + 900]
            q_duts = select(run_duts.c.run_id, run_duts.c.serial).where(run_duts.c.run_id.in_(part))
            for run_id, serial in conn.execute(q_duts.order_by(run_duts.c.run_id, run_duts.c.slot)):
                duts.setdefault(run_id, []).append(serial)
    for r in rows:
        r["duts"] = ", ".join(duts.get(r["run_id"], ()))
    return rows, total


def filter_choices(store: Any) -> dict[str, list[str]]:
    """The procedures, stations and outcomes the store holds (for the browser's pickers)."""
    out: dict[str, list[str]] = {}
    with store.engine.connect() as conn:
        for key, col in (("procedure", runs.c.procedure), ("station_id", runs.c.station_id),
                         ("outcome", runs.c.outcome)):
            out[key] = sorted(v for (v,) in conn.execute(select(col).distinct()) if v)
    return out
