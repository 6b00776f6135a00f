"""Several units through a sequence at once, one per slot of a several-gyros station: each step's
procedure runs as one batch (bench.engine.batch), each unit judged from its own slot's run, one
record per unit.  A unit stopped by a failing step leaves the batch; the others go on."""

from __future__ import annotations

import signal
from typing import Any

from .record import now_iso
from .routing import history, next_attempt
from .run import STOP_OUTCOMES, LineContext, abort_on_signals, begin_attempt, finish_record, judge_run
from .verdict import ABORTED, worst


def run_batch_attempt(ctx: LineContext, station: Any, serials: dict[int, str], operator: Any,
                      attempts: dict[str, int] | None = None) -> list[dict[str, Any]]:
    """One attempt of every unit (serial by slot) on an opened batch station; their records."""
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
    batch_info = {"station": station.id, "serials": {str(n): s for n, s in serials.items()}}
    for n, serial in serials.items():
        u = per[n]
        attempt = attempts[serial]
        rec = finish_record(ctx, station.slot(n), serial, attempt, started, u["runs"], u["measurements"],
                            u["matched"], u["stopped_by"], extra={"slot": n, "batch": batch_info})
        operator.show_outcome(serial, rec["outcome"], rec["summary"])
        out.append(rec)
    return out
