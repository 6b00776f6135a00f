"""The operator station's line session: one logged-in operator, one sequence and its product limits,
one station; each scanned serial runs through `bench.line` as `gyrobench line run` does (routing,
attempts, a unit record, a certificate, a line database row), with the window's prompts.  On a
station with slots one serial a slot (an empty slot is not run, recorded as not fitted) runs as one
batch, as `gyrobench line run` on that station does; one slot may be retested alone.  A station
past a calibration due date or locked by its golden unit refuses to run (bench/line/station_state.py)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from bench.line import LineError

#: columns an operators table may name its people by, in order of preference
NAME_COLUMNS = ("name", "operator", "badge", "login")


def sequences() -> list[str]:
    """The built-in line sequences by name (bench/line/sequences/*.toml)."""
    from bench.line import sequence

    folder = Path(sequence.__file__).parent / "sequences"
    return sorted(p.stem for p in folder.glob("*.toml"))


def default_sequence(station: str | None, preferred: str = "ci-spin") -> str:
    """The sequence the operator station opens on: `preferred` when it runs on the station, else the
    first built-in one that does (a station with slots cannot run ci-spin, whose steps do not say
    which devices they use); `preferred` when none does or the station cannot be read."""
    from bench.composition import load_station
    from bench.line.checks import check_steps
    from bench.line.sequence import load_sequence

    try:
        probe = load_station(station) if station else None
    except Exception:  # the session opening on it says why, in one line
        return preferred
    if probe is None:
        return preferred
    names = sequences()
    for name in [preferred, *[n for n in names if n != preferred]]:
        try:
            seq = load_sequence(name)
            if seq.station and station and seq.station != station and not hasattr(probe, "slots"):
                continue
            if hasattr(probe, "slots"):
                from bench.line.batch_run import check_batch_sequence
                from bench.line.cli import _limits_of

                args = argparse.Namespace(sequence=name, limits=None)
                check_batch_sequence(seq, _limits_of(args, seq), probe)
            else:
                check_steps(seq, probe)
            return name
        except Exception:  # this one does not fit the station: the next
            continue
    return preferred


def known_operators(db: Any) -> list[str] | None:
    """The operators the line database lists (its `operators` table), or None when it has none."""
    from sqlalchemy import MetaData, Table, inspect, select

    engine = getattr(db, "engine", None)
    if engine is None or not inspect(engine).has_table("operators"):
        return None
    table = Table("operators", MetaData(), autoload_with=engine)
    col = next((table.c[n] for n in NAME_COLUMNS if n in table.c), None)
    if col is None:
        return None
    active = table.c.active if "active" in table.c else None
    query = select(col) if active is None else select(col, active)
    with engine.connect() as conn:  # `active` read, not compared in SQL: BOOLEAN, INTEGER or text alike
        rows = list(conn.execute(query))
    return sorted(str(r[0]) for r in rows if r[0] and (active is None or _truthy(r[1])))


def _truthy(value: Any) -> bool:
    """An operators table's `active` as written by any database: True, 1, 't', 'yes' ..."""
    if isinstance(value, str):
        return value.strip().lower() in ("1", "t", "true", "y", "yes")
    return bool(value)


def free_text_allowed(station: Any) -> bool:
    """Whether an operator may log in by a typed name (no operators table): the station file's
    `[station] free_text_operator`; a simulated station allows it unless it says false."""
    cfg = getattr(station, "config", None)
    said = (getattr(cfg, "station", None) or {}).get("free_text_operator")
    if said is not None:
        return bool(said)
    return getattr(cfg, "simulation", None) is not None


class LineSession:
    """A station, a sequence and its limits, the line database; `log_in` then `run_serial` per unit."""

    def __init__(self, station: str, sequence: str, *, runs_dir: str | Path | None = None, db: str | None = None,
                 seed: int | None = None, limits: str | None = None, lot: str = "") -> None:
        from bench.composition import load_station
        from bench.line.checks import check_limits_measured, check_steps
        from bench.line.cli import _limits_of
        from bench.line.db import LineDB
        from bench.line.sequence import load_sequence

        self.overrides = {} if seed is None else {"seed": seed}
        self.seq = load_sequence(sequence)
        self.args = argparse.Namespace(sequence=sequence, limits=limits, runs_dir=None, lot="", rework=None,
                                       retest_reason=None, operator="", dut=[], db=db)
        self.limits = _limits_of(self.args, self.seq)
        from bench.line.inputs import check_lot

        self.args.lot = check_lot(lot or "", self.limits.lot_format) or ""
        self.station_name = station or self.seq.station
        if not self.station_name:
            raise LineError(f"sequence {self.seq.name!r} names no station: choose one")
        probe = load_station(self.station_name, **self.overrides)  # the file checked, nothing opened
        self.n_slots = int(probe.n_slots) if hasattr(probe, "slots") else 0
        if self.n_slots:
            from bench.line.batch_run import check_batch_sequence

            check_batch_sequence(self.seq, self.limits, probe)
        else:
            check_steps(self.seq, probe)
            check_limits_measured(self.seq, self.limits)
        self.station_id = probe.id
        self.calibration = dict(probe.config.calibration)
        self.free_text = free_text_allowed(probe)
        self.args.runs_dir = str(runs_dir or probe.runs_dir)
        self.db_url = db or (probe.results_url if runs_dir is None else None)
        Path(self.args.runs_dir).mkdir(parents=True, exist_ok=True)
        self.db = LineDB(self.db_url or str(Path(self.args.runs_dir) / "results.sqlite"))
        self.operator = ""
        self.ctx: Any = None

    def operators(self) -> list[str] | None:
        return known_operators(self.db)

    def refusal(self) -> str | None:
        """Why the station refuses to run now (a calibration past due, a golden-unit lock), or None."""
        from bench.line.station_state import refusal

        return refusal(self.calibration, self.args.runs_dir, self.station_id)

    def calibration_status(self) -> str:
        """The station's calibration due dates and its golden-unit lock, one line for the login."""
        from bench.line.station_state import current_lock

        dates = ", ".join(f"{name} due {due.isoformat()}" for name, due in sorted(self.calibration.items(),
                                                                                  key=lambda kv: kv[1]))
        held = current_lock(self.args.runs_dir, self.station_id)
        lock = f"LOCKED since {held['at']}: {held['reason']}" if held else "not locked"
        return f"calibration: {dates or 'no due dates in the station file'}; golden unit: {lock}"

    def check_ready(self) -> None:
        """LineError (one message) when the station may not run: calibration past due or locked."""
        why = self.refusal()
        if why:
            raise LineError(why)

    def log_in(self, name: str) -> str:
        """The operator, from the database's operators table; a typed name only where the station
        allows it (LineError otherwise)."""
        from bench.line.inputs import check_operator

        name = check_operator(name)
        listed = self.operators()
        if listed is not None:
            if name not in listed:
                raise LineError(f"operator {name!r} is not in the line database's operators table")
        elif not self.free_text:
            raise LineError(f"station {self.station_id!r} takes operators from the line database, which lists none "
                            "(set [station] free_text_operator = true to allow typed names)")
        from bench.line.cli import _context

        if self.ctx is not None:
            self.close()
        self.args.operator = name
        probe_cfg = None
        try:
            from bench.composition import load_station

            probe_cfg = load_station(self.station_name, **self.overrides).config
        except Exception:  # noqa: BLE001 - the signer is optional; the station was checked above
            probe_cfg = None
        self.ctx = _context(self.args, station_name=self.station_id, operator=name, db_url=self.db_url,
                            config=probe_cfg)
        self.operator = name
        return name

    def check_serial(self, text: str) -> str:
        from bench.line.inputs import check_serial

        return check_serial(text, self.limits.serial_format)

    def run_serial(self, serial: str, operator: Any, *, rework: str | None = None,
                   retest_reason: str | None = None) -> list[dict[str, Any]]:
        """One unit through the sequence (worker thread): routing (a retest after FAIL needs a rework
        code, after PASS a reason), the fixture prompt, its attempts."""
        from bench.composition import load_station
        from bench.line.routing import history, route
        from bench.line.run import run_unit

        if self.ctx is None:
            raise LineError("log in first")
        if self.n_slots:
            raise LineError(f"station {self.station_id!r} has slots: run_slots places one serial a slot")
        self.check_ready()
        ctx = self.ctx
        ctx.aborted.clear()
        from bench.line.inputs import check_reason, check_rework

        rework = check_rework(rework) if rework else None
        retest_reason = check_reason(retest_reason) if retest_reason else None
        ctx.routing[serial], tries = route(history(ctx.db, ctx.runs_dir, serial), serial, self.seq, rework=rework,
                                           retest_reason=retest_reason)
        if not operator.confirm(f"unit {serial} is in the fixture of station {self.station_id!r}?"):
            raise LineError(f"unit {serial}: the fixture was not confirmed; nothing was run")
        return run_unit(ctx, lambda: load_station(self.station_name, **self.overrides), serial, operator,
                        max_tries=tries)

    def run_slots(self, serials: dict[int, str], operator: Any, *, rework: str | None = None,
                  retest_reason: str | None = None, not_fitted: list[int] | None = None,
                  alone: bool = False) -> list[dict[str, Any]]:
        """The placed units (serial by slot, empty slots left out) as one batch (worker thread),
        through the code path of `gyrobench line run` on a station with slots; one slot alone is a
        retest of that unit, routed by the line's rules (a rework code after FAIL, a reason after PASS)."""
        from bench.composition import load_station
        from bench.line.batch_run import run_batch_units
        from bench.line.inputs import check_reason, check_rework

        if self.ctx is None:
            raise LineError("log in first")
        if not self.n_slots:
            raise LineError(f"station {self.station_id!r} holds one unit: run_serial")
        self.check_ready()
        ctx = self.ctx
        ctx.aborted.clear()
        rework = check_rework(rework) if rework else None
        retest_reason = check_reason(retest_reason) if retest_reason else None
        station = load_station(self.station_name, **self.overrides)
        return run_batch_units(ctx, station, dict(sorted(serials.items())), operator, rework=rework,
                               retest_reason=retest_reason, not_fitted=not_fitted, alone=alone)

    def close(self) -> None:
        if self.ctx is not None:
            self.ctx.store.close()
            self.ctx.db.close()
            self.ctx = None
