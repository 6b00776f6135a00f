"""One unit through a sequence: its procedures run by the engine on one station, each measurement
judged against the product limits, one record per attempt (retested per the sequence's policy)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import LineError
from .limits import ProductLimits
from .record import (
    SCHEMA_VERSION,
    judge_measurements,
    judged,
    now_iso,
    record_path,
    sha256_of,
    summary,
    write_new_record,
)
from .sequence import Sequence
from .verdict import ABORTED, ERROR, FAIL, PASS, SKIPPED, worst

STOP_OUTCOMES = (FAIL, ERROR, ABORTED)


@dataclass
class LineContext:
    """What every unit of one `line run` / `line simulate` shares."""

    sequence: Sequence
    limits: ProductLimits
    station_name: str
    operator_name: str
    runs_dir: Path
    store: Any = None  # bench.results.ResultsStore for the runs (or None)
    db: Any = None  # bench.line.db.LineDB for the records (or None)
    lot: str = ""
    on_record: Callable[[dict[str, Any]], None] | None = None
    aborted: list[str] = field(default_factory=list)
    on_batch: Callable[[Any], None] | None = None  # told each bench.engine.batch.Batch before it runs (the window)
    on_runner: Callable[[Any], None] | None = None  # told each unit's bench.engine.Runner before its steps run
    signer: Any = None  # bench.line.integrity.Signer: the station's key (None: records chained, not signed)
    routing: dict[str, dict[str, Any]] = field(default_factory=dict)  # serial -> its routing (bench/line/routing.py)
    attempt_ids: dict[str, Any] = field(default_factory=dict)  # serial -> its open attempt (begin_attempt)
    pdf: bool = True  # the certificate as PDF too (when WeasyPrint is there)


@dataclass
class OpenAttempt:
    """An attempt begun: its row in the line database (None when the database was down) and heartbeat."""

    row_id: int | None
    heartbeat: Any = None
    db_error: str | None = None

    def stop(self) -> None:
        if self.heartbeat is not None:
            self.heartbeat.stop()
            self.heartbeat = None


def begin_attempt(ctx: LineContext, serial: str, attempt: int, started: str) -> int:
    """The attempt's RUNNING row in the line database (kept alive by a heartbeat) as it starts, so
    a process killed mid-unit leaves an INTERRUPTED attempt, not nothing; the attempt number
    (another station may have taken the one asked for)."""
    stub = {"schema_version": SCHEMA_VERSION, "serial": serial, "attempt": attempt, "lot": ctx.lot,
            "station": ctx.station_name, "operator": ctx.operator_name, "sequence": ctx.sequence.name,
            "product": ctx.limits.name, "started_at": started, "ended_at": started, "outcome": "RUNNING",
            "routing": ctx.routing.get(serial), "measurements": [], "runs": []}
    opened = OpenAttempt(None)
    if ctx.db is not None and hasattr(ctx.db, "begin_attempt"):
        try:
            opened.row_id = ctx.db.begin_attempt(stub)
            from bench.results.liveness import Heartbeat

            db, row_id = ctx.db, opened.row_id
            opened.heartbeat = Heartbeat(lambda: db.beat(row_id), name=f"line-heartbeat-{serial}")
        except LineError as exc:  # the database is down: the record on disk is what counts
            opened.db_error = str(exc)
    ctx.attempt_ids[serial] = opened
    return int(stub["attempt"])


def _table_question(station: Any) -> str:
    return f"the rate table of station {station.id!r} will spin: is the fixture closed and the area clear?"


def run_attempt(ctx: LineContext, station: Any, serial: str, attempt: int, operator: Any) -> dict[str, Any]:
    """One attempt of one unit on an opened station: its record (written and stored)."""
    from bench.engine import Runner
    from procedures import find_procedure

    seq, limits = ctx.sequence, ctx.limits
    started = now_iso()
    attempt = begin_attempt(ctx, serial, attempt, started)
    runs, measurements = [], []
    matched: set[tuple[str, str | None]] = set()
    stopped_by: str | None = None
    asked_spin = False
    runner = Runner(station, runs_dir=ctx.runs_dir, store=ctx.store, operator=ctx.operator_name, duts=[serial])
    if ctx.on_runner is not None:
        ctx.on_runner(runner)
    previous = abort_on_signals(ctx, runner.abort)
    try:
        for step in seq.steps:
            cls = find_procedure(step.procedure)
            declared = {m.name for m in cls.measurements}
            step_limits = limits.for_procedure(cls.name, declared)
            if stopped_by is not None or ctx.aborted:
                for lim in step_limits:
                    matched.add((lim.name, lim.procedure))
                    measurements.append(judged(lim.name, cls.name, None, None, lim, skipped=True))
                continue
            if "table" in cls.requires and not asked_spin:
                asked_spin = True
                if not operator.confirm(_table_question(station)):
                    ctx.aborted.append("the operator did not confirm the table spin")
                    for lim in step_limits:
                        matched.add((lim.name, lim.procedure))
                        measurements.append(judged(lim.name, cls.name, None, None, lim, skipped=True))
                    stopped_by = ABORTED
                    continue
            t0 = now_iso()
            rec = runner.run(step.make())
            step_outcomes = judge_run(cls, step, rec, step_limits, t0, runs, measurements, matched)
            if step.stop_on_fail and step_outcomes and worst(step_outcomes) in STOP_OUTCOMES:
                stopped_by = worst(step_outcomes)
    except BaseException:  # no record: the attempt's row stops beating and becomes INTERRUPTED
        opened = ctx.attempt_ids.pop(serial, None)
        if opened is not None:
            opened.stop()
        raise
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return finish_record(ctx, station, serial, attempt, started, runs, measurements, matched, stopped_by)


def judge_run(cls: Any, step: Any, rec: Any, step_limits: list, t0: str, runs: list, measurements: list,
              matched: set) -> list[str]:
    """One step's run into the unit's lists: its run entry, its measurements judged against the
    limits (with their truth on a simulated station); the step's outcomes."""
    js = rec.as_json()
    truth = cls.truth_for(js.get("truth")) if js.get("truth") else {}
    runs.append({"run_id": rec.run_id, "procedure": cls.name, "step": step.label, "outcome": rec.outcome,
                 "end_reason": rec.end_reason, "safe_state": bool(rec.safe_state),
                 "raw_file": rec.raw_file, "sha256": sha256_of(rec.raw_file), "started_at": t0,
                 "ended_at": now_iso(), "simulated_s": float(rec.simulated_s), "wall_s": float(rec.wall_s),
                 "params": _plain(rec.params), "store_error": rec.store_error})
    aborted = rec.end_reason if rec.outcome == ABORTED else None  # its unreached limits: SKIPPED
    entries = judge_measurements(cls.name, rec.run_id, js["measurements"], step_limits, truth, aborted)
    measurements.extend(entries)
    step_outcomes = [e["outcome"] for e in entries]
    matched.update((lim.name, lim.procedure) for lim in step_limits)
    if rec.outcome in (ERROR, ABORTED):
        step_outcomes.append(rec.outcome)
    return step_outcomes


def finish_record(ctx: LineContext, station: Any, serial: str, attempt: int, started: str, runs: list,
                  measurements: list, matched: set, stopped_by: str | None,
                  extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """The unit's record from its runs and judged measurements: outcome, provenance, chained and
    signed (bench/line/integrity.py), written once beside its certificate (and compensation file)
    under the first attempt number free on disk, then saved in the line database."""
    from .provenance import provenance

    seq, limits = ctx.sequence, ctx.limits
    for lim in limits.limits:  # named by the limits file, measured by no step of the sequence
        if not any(name == lim.name for name, _ in matched):
            measurements.append(judged(lim.name, lim.procedure or "", None, None, lim))
    decided = [m["outcome"] for m in measurements if m["rule"]] + [
        r["outcome"] for r in runs if r["outcome"] in (ERROR, ABORTED)]
    if ctx.aborted:
        decided.append(ABORTED)
    record = {
        "schema_version": SCHEMA_VERSION,
        "serial": serial,
        "lot": ctx.lot,
        "station": ctx.station_name,
        "operator": ctx.operator_name,
        **provenance(seq.source, limits.source),
        "sequence": seq.name,
        "product": limits.name,
        "attempt": attempt,
        "started_at": started,
        "ended_at": now_iso(),
        "outcome": worst(decided),
        "stopped_by": stopped_by,
        "abort_reason": "; ".join(ctx.aborted) or None,
        "simulated": bool(getattr(station, "simulated", False)),
        "routing": ctx.routing.get(serial),
        "measurements": measurements,
        "runs": runs,
        **(extra or {}),
    }
    folder = ctx.runs_dir / "line" / (ctx.lot or "no-lot")
    if seq.write_trims:
        _trims_step(record, station, folder)
    record["summary"] = summary(record)
    opened = ctx.attempt_ids.pop(serial, None) or OpenAttempt(None)
    opened.stop()
    _write_sealed(ctx, record, folder)
    if ctx.db is not None:
        try:
            if opened.row_id is not None:
                ctx.db.finish_attempt(opened.row_id, record)
            else:
                ctx.db.save(record)
        except LineError as exc:  # the database is down or refused it: the file waits for `line import`
            record["db_error"] = f"{exc}; `gyrobench line import {record['record_file']}` submits it later"
            Path(record["record_file"]).with_suffix(".db_error.txt").write_text(record["db_error"] + "\n")
    if ctx.on_record is not None:
        ctx.on_record(record)
    return record


def _trims_step(record: dict[str, Any], station: Any, folder: Path) -> None:
    """The sequence's gated last step (bench/line/trims.py): a PASS unit's compensation into its
    FPGA's NVM; a write that fails makes the unit ERROR (it is not trimmed as its certificate says)."""
    from .record import _safe
    from .trims import write_unit_trims

    link = (getattr(station, "devices", None) or {}).get("fpga")
    if link is None and record["outcome"] == PASS:
        record["trims"] = {"written": False, "error": f"station {station.id!r} has no FPGA to hold the trims"}
    elif link is None:
        why = f"unit {record['outcome']}: trims are written for PASS units only"
        record["trims"] = {"written": False, "reason": why}
    else:
        path = folder / f"{_safe(record['serial'])}-a{record['attempt']}.compensation.toml"
        record["trims"] = write_unit_trims(link, record, path)
    if record["trims"].get("error"):
        record["outcome"] = ERROR


def _write_documents(record: dict[str, Any], folder: Path, *, pdf: bool) -> None:
    """The unit's certificate (or rejection report), HTML and PDF, and its compensation file beside
    the record; a PDF that cannot be made leaves the HTML (and says so), never the record unwritten."""
    from .certificate import pdf_available, write_unit_documents

    record.pop("documents_error", None)
    errors = []
    for with_pdf in ((True, False) if pdf and pdf_available() else (False,)):
        try:
            record["documents"] = {k: str(v) for k, v in write_unit_documents(record, folder, pdf=with_pdf).items()}
            break
        except Exception as exc:  # noqa: BLE001 - a document that cannot be written must not lose the record
            record.pop("documents", None)
            errors.append(f"{type(exc).__name__}: {exc}")
    if errors:
        record["documents_error"] = "; ".join(errors)


def _write_sealed(ctx: LineContext, record: dict[str, Any], folder: Path) -> None:
    """The record's documents, its place in the station's chain and its signature, then its file
    SERIAL-aN.json created once (never over another): a name already on disk takes the next N."""
    from .integrity import Chain, seal

    folder.mkdir(parents=True, exist_ok=True)
    with Chain(ctx.runs_dir, ctx.station_name).held() as chain:
        while True:
            while record_path(folder, record).exists():
                record["attempt"] += 1
            _write_documents(record, folder, pdf=ctx.pdf)
            seal(record, chain, ctx.signer, ctx.db)
            try:
                write_new_record(record, folder)
            except FileExistsError:  # another process of this runs dir took the name meanwhile
                record["attempt"] += 1
                continue
            chain.advance(record["chain"]["index"], record["integrity"]["sha256"])
            return


def run_unit(ctx: LineContext, open_station: Callable[[], Any], serial: str, operator: Any,
             first_attempt: int | None = None, max_tries: int | None = None) -> list[dict[str, Any]]:
    """A unit's attempts: the first, then a retest while its outcome is one the sequence retests
    (at most max_tries, default the sequence's max_attempts; never after a FAIL, which needs
    rework); the station opened for each attempt and closed after it, whatever happens.  Attempt
    numbers follow every attempt of the serial on disk and in the database."""
    from .routing import history, next_attempt

    records = []
    seq = ctx.sequence
    tries = seq.max_attempts if max_tries is None else max_tries
    for k in range(tries):
        attempt = next_attempt(history(ctx.db, ctx.runs_dir, serial))
        if first_attempt is not None:
            attempt = max(attempt, first_attempt + k)
        station = open_station()
        try:
            try:
                station.open()
            except Exception as exc:  # noqa: BLE001 - a station that does not open is one line
                raise LineError(f"station {station.id!r} did not open: {type(exc).__name__}: {exc}") from None
            rec = run_attempt(ctx, station, serial, attempt, operator)
        finally:
            station.close()
        records.append(rec)
        operator.show_outcome(serial, rec["outcome"], rec["summary"])
        if rec["outcome"] not in seq.retest_on or rec["outcome"] == FAIL or ctx.aborted:
            break
    return records


def abort_on_signals(ctx: LineContext, abort: Callable[[str], None]) -> dict:
    """SIGINT / SIGTERM stop the sequence and call `abort(signal name)` (the running procedure or
    batch; the engine makes the station safe); the caller puts the returned handlers back."""
    previous: dict = {}
    if threading.current_thread() is not threading.main_thread():
        return previous

    def on_signal(signum, _frame):
        name = signal.Signals(signum).name
        ctx.aborted.append(f"aborted: {name}")
        abort(name)

    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, on_signal)
    return previous


def _plain(params: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in params.items():
        out[k] = v if isinstance(v, (int, float, str, bool)) or v is None else str(v)
    return out


__all__ = ["LineContext", "SKIPPED", "run_attempt", "run_unit"]
