"""Several units through a sequence at once, one per slot of a several-gyros station: each step's
procedure runs as one batch (bench.engine.batch), each unit judged from its own slot's run, one
record per unit.  A unit stopped by a failing step leaves the batch; the others go on."""

from __future__ import annotations

import signal
from typing import Any

from .record import now_iso
from .routing import history, next_attempt, route
from .run import STOP_OUTCOMES, LineContext, abort_on_signals, begin_attempt, finish_record, judge_run
from .verdict import ABORTED, worst


def run_batch_attempt(ctx: LineContext, station: Any, serials: dict[int, str], operator: Any,
                      attempts: dict[str, int] | None = None, *, not_fitted: list[int] | None = None,
                      alone: bool = False) -> list[dict[str, Any]]:
    """One attempt of every unit (serial by slot) on an opened batch station; their records, which
    name the slots left empty (`not_fitted`, default every slot not in serials) and whether one unit
    was retested alone."""
    from bench.engine.batch import Batch
    from bench.line.record import judged
    from procedures import find_procedure

    seq, limits = ctx.sequence, ctx.limits
    started = now_iso()
    asked = attempts or {}
    attempts = {}  # each unit's RUNNING row as it starts, numbered after every attempt on disk and in the database
    for s in serials.values():
        attempts[s] = begin_attempt(ctx, s, max(asked.get(s, 1), next_attempt(history(ctx.db, ctx.runs_dir, s))),
                                    started)
    per: dict[int, dict[str, Any]] = {n: {"runs": [], "measurements": [], "matched": set(), "stopped_by": None}
                                      for n in serials}
    asked_spin = False
    current: list[Any] = []
    # SIGINT / SIGTERM abort the batch running (every slot's drive cut, then the table to rest)
    previous = abort_on_signals(ctx, lambda name: [b.abort(name) for b in list(current)])
    try:
        for step in seq.steps:
            cls = find_procedure(step.procedure)
            step_limits = limits.for_procedure(cls.name, {m.name for m in cls.measurements})
            going = {n: s for n, s in serials.items() if per[n]["stopped_by"] is None}
            if not ctx.aborted and going and "table" in cls.requires and not asked_spin:
                asked_spin = True
                if not operator.confirm(f"the rate table of station {station.id!r} will spin with "
                                        f"{len(serials)} units: is the fixture closed and the area clear?"):
                    ctx.aborted.append("the operator did not confirm the table spin")
            for n in serials:
                if n not in going or ctx.aborted:  # stopped or aborted: the step's limits are recorded skipped
                    u = per[n]
                    for lim in step_limits:
                        u["matched"].add((lim.name, lim.procedure))
                        u["measurements"].append(judged(lim.name, cls.name, None, None, lim, skipped=True))
                    if ctx.aborted and u["stopped_by"] is None:
                        u["stopped_by"] = ABORTED
            if ctx.aborted or not going:
                continue
            batch = Batch(station, going, runs_dir=ctx.runs_dir, store=ctx.store, operator=ctx.operator_name)
            current[:] = [batch]
            if ctx.on_batch is not None:
                ctx.on_batch(batch)
            t0 = now_iso()
            records = batch.run(step.make)
            current.clear()
            for n, rec in records.items():
                u = per[n]
                outcomes = judge_run(cls, step, rec, step_limits, t0, u["runs"], u["measurements"], u["matched"])
                # the results store holds the batch as one run (its N DUTs): this unit's run is part of it
                u["runs"][-1].update(batch_run_id=batch.run_id, store_error=batch.store_error)
                if step.stop_on_fail and outcomes and worst(outcomes) in STOP_OUTCOMES:
                    u["stopped_by"] = worst(outcomes)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    out = []
    batch_info = {"station": station.id, "serials": {str(n): s for n, s in serials.items()},
                  "not_fitted": sorted(not_fitted if not_fitted is not None else
                                       (n for n in range(1, station.n_slots + 1) if n not in serials))}
    if alone:
        batch_info["retest_alone"] = True
    for n, serial in serials.items():
        u = per[n]
        attempt = attempts[serial]
        rec = finish_record(ctx, station.slot(n), serial, attempt, started, u["runs"], u["measurements"],
                            u["matched"], u["stopped_by"], extra={"slot": n, "batch": batch_info})
        operator.show_outcome(serial, rec["outcome"], rec["summary"])
        out.append(rec)
    return out


def check_batch_sequence(seq: Any, limits: Any, station: Any) -> None:
    """The sequence fits a slot of the station, its limits are measured, every step runs as a batch;
    LineError names what does not (before any unit is placed)."""
    from bench.engine.batch import BatchError, check_batchable
    from bench.slots import BATCH_ROLES
    from procedures import find_procedure

    from . import LineError
    from .checks import check_limits_measured, check_steps

    check_steps(seq, station.slot(1))
    check_limits_measured(seq, limits)
    for step in seq.steps:
        try:
            check_batchable(find_procedure(step.procedure), BATCH_ROLES)
        except BatchError as exc:
            raise LineError(f"{seq.source}: {exc}") from None


def run_batch_units(ctx: LineContext, station: Any, serials: dict[int, str], operator: Any, *,
                    rework: str | None = None, retest_reason: str | None = None,
                    run: Any = None, not_fitted: list[int] | None = None, alone: bool = False) -> list[dict[str, Any]]:
    """The units placed (serial by slot; a slot not named is empty: not run, recorded as not fitted)
    through one batch attempt, as `gyrobench line run` on a station with slots: every unit routed
    first (bench/line/routing.py), the fixtures confirmed, the station opened, run and closed.
    `run(work)` runs the attempt (a window's worker thread), default at once; `alone` marks one unit
    retested by itself (the other slots' units, if any, wait; `not_fitted` names the empty slots)."""
    from . import LineError

    if not serials:
        raise LineError(f"station {station.id!r}: no unit placed in any slot")
    bad = [n for n in serials if not 1 <= n <= station.n_slots]
    if bad:
        raise LineError(f"slot(s) {bad}: station {station.id!r} has slots 1..{station.n_slots}")
    if len(set(serials.values())) != len(serials):
        raise LineError(f"{', '.join(serials.values())}: a serial is placed twice")
    for s in serials.values():  # every unit's routing before the batch starts
        ctx.routing[s], _ = route(history(ctx.db, ctx.runs_dir, s), s, ctx.sequence, rework=rework,
                                  retest_reason=retest_reason)
    placed = ", ".join(f"{s} in slot {n}" for n, s in sorted(serials.items()))
    if not operator.confirm(f"units {placed} are in the fixtures of station {station.id!r}?"):
        raise LineError("the fixtures were not confirmed; nothing was run")
    try:
        station.open()
    except Exception as exc:  # noqa: BLE001 - a station that does not open is one line
        raise LineError(f"station {station.id!r} did not open: {type(exc).__name__}: {exc}") from None
    try:
        attempts = {s: 1 for s in serials.values()}  # numbered after every attempt on disk and in the database

        def work() -> list[dict[str, Any]]:
            return run_batch_attempt(ctx, station, serials, operator, attempts, not_fitted=not_fitted, alone=alone)

        return work() if run is None else run(work)
    finally:
        station.close()
