"""A procedure run for N units at once on one table (TestStand's batch model): each slot runs the
procedure in its own thread with its own Runner (its own run, raw file, truth and outcome); a step
that uses only the shared table is a batch step, run once -- by the lowest slot still in the
batch -- after every slot still in the batch has reached it (a barrier); the other steps run per
slot in parallel, a shared instrument used under the engine's lock (bench.slots.SlotLock), taken
for each use -- switch and command -- so no simulated time passes while a slot holds it and the
order the slots take it in cannot change a seeded run.

In lockstep the slots share one SlotClock: the world advances only when every slot is waiting on
it, parked at a barrier or a lock, or gone, so a seeded batch is reproducible whatever the thread
scheduling.  A slot that fails goes to its own safe state (drive cut, outputs off) and leaves the
batch; the others go on.  The table goes to rest when the last slot has left (at once after an
abort or a table fault: every slot's run ends at its next checkpoint, within 0.4 simulated s).

    batch = Batch(station, {1: "S1", 2: "S2"}, runs_dir="runs")
    records = batch.run(lambda: HrgDamping({"record_s": 300}))   # {slot: RunRecord}
"""

from __future__ import annotations

import datetime as _dt
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from drivers.errors import LinkLostError, SafetyTripError

from .context import RunAborted
from .measurement import ERROR
from .procedure import Procedure, step_shares, step_uses
from .runner import Runner, RunRecord
from .safety import SafeStateReport

#: a batch run's outcome: the worst of its slots'
_WORST_FIRST = ("ABORTED", "ERROR", "FAIL", "MARGINAL", "PASS", "COMPLETE")


class BatchError(ValueError):
    """A procedure that cannot run on several gyros at once (a step that mixes the shared table
    with a slot's devices, or does not say what it uses)."""


def check_batchable(cls: type[Procedure], batch_roles: frozenset[str]) -> None:
    """Every step says what it uses, and none mixes the shared table with a slot's devices unless
    it declares the shared roles it drives through `ctx.shared` (`@step(..., shares=...)`)."""
    for name, title in cls.step_specs():
        uses = step_uses(cls, name)
        if uses is None:
            raise BatchError(f"procedure {cls.name!r} step {title!r} does not say which devices it uses "
                             "(@step(..., uses=(...))): it cannot run on several gyros at once")
        shared, own = set(uses) & batch_roles, set(uses) - batch_roles
        if shared and own and not shared <= set(step_shares(cls, name)):
            raise BatchError(f"procedure {cls.name!r} step {title!r} uses the shared {sorted(shared)} and the "
                             f"slot's {sorted(own)}: split it into a table step and a slot step, or drive the "
                             f"shared ones through ctx.shared (@step(..., shares=(...)))")


class Batch:
    """One procedure on the slots of a BatchStation (bench.slots); `run` returns a record per slot."""

    def __init__(self, station: Any, serials: dict[int, str], *, runs_dir: Any = None, store: Any = None,
                 operator: str = "", bus_for: Callable[[int], Any] | None = None) -> None:
        from bench.slots import BATCH_ROLES

        self.station = station
        self.batch_roles = BATCH_ROLES
        self.serials = dict(serials)
        self.store = store
        self.operator = operator
        self.runners = {  # the store gets the batch's one run (its N DUTs), not a run per slot
            n: Runner(station.slot(n), runs_dir=runs_dir, store=None, operator=operator, duts=[serial],
                      bus=None if bus_for is None else bus_for(n), step_gate=self._gate(n))
            for n, serial in self.serials.items()}
        self.runs_dir = runs_dir
        self.record: RunRecord | None = None
        self.store_error: str | None = None
        self._cond = threading.Condition()
        self._active: set[int] = set()
        self._arrived: dict[str, set[int]] = {}
        self._done: dict[str, tuple[int, BaseException | None]] = {}
        self._values: dict[str, dict[int, Any]] = {}  # a sync's slot values (ctx.gather)
        self._results: dict[str, Any] = {}  # a sync's action's result (ctx.shared)
        self._sync_seq: dict[int, int] = {}
        self._threads: dict[int, threading.Thread] = {}
        self._idents: dict[int, int] = {}
        self._abort_reason: str | None = None
        self.table_report: SafeStateReport | None = None
        #: what each slot is doing now (the window's column per slot): step name, or its outcome
        self.current: dict[int, str] = {}

    # --- control, from any thread ----------------------------------------------------------------
    def abort(self, reason: str = "abort requested") -> None:
        """Every slot's run ends at its next checkpoint (its drive cut); then the table to rest."""
        if self._abort_reason is None:
            self._abort_reason = reason
        for r in self.runners.values():
            r.abort(reason)
        with self._cond:
            self._cond.notify_all()

    # --- the batch ---------------------------------------------------------------------------------
    def run(self, make: Callable[[], Procedure]) -> dict[int, RunRecord]:
        """Run a fresh procedure (from `make`) on every slot at once; each slot's RunRecord."""
        procs = {n: make() for n in self.runners}
        check_batchable(type(next(iter(procs.values()))), self.batch_roles)
        from .runner import new_run_id

        self.run_id = new_run_id()
        for n, r in self.runners.items():
            r.next_run_id = f"{self.run_id}-slot{n}"
        started = _dt.datetime.now(_dt.UTC).isoformat()
        t0_wall = time.monotonic()
        records: dict[int, RunRecord] = {}
        errors: dict[int, BaseException] = {}
        self._active = set(self.runners)
        self._arrived.clear()
        self._done.clear()
        self._values.clear()
        self._results.clear()
        self._sync_seq.clear()
        self.station._on_lock_broken = self._lock_broken

        start = threading.Barrier(len(self.runners))

        def main(n: int) -> None:
            clock = self.station.base_clock
            if hasattr(clock, "join"):
                clock.join()
            try:
                start.wait(timeout=30.0)  # every slot a member of the clock before any wait advances it
                records[n] = self.runners[n].run(procs[n])
            except BaseException as exc:  # noqa: BLE001 - the others must go on
                errors[n] = exc
            finally:
                self._leave(n)
                if hasattr(clock, "leave"):
                    clock.leave()

        for n in self.runners:
            self._threads[n] = threading.Thread(target=main, args=(n,), name=f"slot{n}", daemon=True)
        for t in self._threads.values():
            t.start()
        try:
            for t in self._threads.values():
                while t.is_alive():
                    t.join(0.2)
        except KeyboardInterrupt:  # Ctrl-C in the coordinating thread: abort all, wait for their safe states
            self.abort("aborted: SIGINT")
            for t in self._threads.values():
                t.join()
        finally:
            self.table_report = self.station.table_to_rest()
        for n, exc in errors.items():  # a run that raised before it began (bad parameters, wrong station)
            raise exc if isinstance(exc, BatchError | ValueError) else RuntimeError(f"slot {n}: {exc}")
        for rec in records.values():
            if not self.table_report.confirmed:
                rec.safe_state = False
                rec.outcome = ERROR
                rec.end_reason += f"; the shared table did not come to rest: {self.table_report.errors}"
            rec.safe_detail.setdefault("devices", {}).update(
                {f"shared {k}": v for k, v in self.table_report.devices.items()})
        self.record = self._batch_record(procs, records, started, time.monotonic() - t0_wall)
        if self.store is not None:
            spool = None if self.runs_dir is None else Path(self.runs_dir) / "spool"
            self.store_error = self.store.finish_run(self.record, spool)
        return dict(sorted(records.items()))

    def _batch_record(self, procs: dict[int, Procedure], records: dict[int, RunRecord], started: str,
                      wall_s: float) -> RunRecord:
        """The batch as one run of the results store: its N DUTs in slot order, each measurement
        with its DUT, each truth as `SERIAL:name`, each slot's run id and raw file in its params."""
        from .runner import software_version

        first = next(iter(procs.values()))
        ordered = sorted(records.items())
        rank = {o: i for i, o in enumerate(_WORST_FIRST)}
        outcome = min((r.outcome for _, r in ordered), key=lambda o: rank.get(o, len(rank)), default=ERROR)
        return RunRecord(
            run_id=self.run_id, procedure=first.name, station_id=self.station.id,
            simulated=bool(self.station.simulated), outcome=outcome,
            end_reason="; ".join(f"slot {n} ({self.serials[n]}): {r.end_reason}" for n, r in ordered),
            safe_state=all(r.safe_state for _, r in ordered) and bool(ordered),
            safe_detail={"slots": {str(n): r.safe_detail for n, r in ordered},
                         "table": None if self.table_report is None else self.table_report.devices},
            measurements=[replace(m, dut=self.serials[n]) for n, r in ordered for m in r.measurements],
            truth={f"{self.serials[n]}:{k}": v for n, r in ordered for k, v in (r.truth or {}).items()},
            simulated_s=max((r.simulated_s for _, r in ordered), default=0.0), wall_s=wall_s,
            raw_file=None, started_at=started, finished_at=_dt.datetime.now(_dt.UTC).isoformat(),
            software_version=software_version(), operator=self.operator,
            duts=[self.serials[n] for n in sorted(self.serials)],
            seed=getattr(self.station.config, "simulation", None) and self.station.config.simulation.get("seed"),
            params={**{k: v if isinstance(v, int | float | str | bool) or v is None else str(v)
                       for k, v in first.params.items()},
                    "batch_slots": {str(n): {"serial": self.serials[n], "run_id": r.run_id, "raw_file": r.raw_file,
                                             "outcome": r.outcome} for n, r in ordered}},
        )

    def _leave(self, n: int) -> None:
        with self._cond:
            self._active.discard(n)
            self._cond.notify_all()

    def _lock_broken(self, slot: int, thread: threading.Thread, why: str) -> None:
        """A slot held a shared instrument past its deadline (or died holding it): its run ends in
        ERROR and it no longer holds the world back."""
        self.runners[slot].fail(why)
        clock = self.station.base_clock
        if hasattr(clock, "leave") and thread.ident is not None:
            clock.leave(thread.ident)

    # --- steps ---------------------------------------------------------------------------------------
    def _gate(self, slot: int) -> Callable[[Procedure, str, Any], None]:
        def gate(proc: Procedure, name: str, ctx: Any) -> None:
            self.current[slot] = name
            if ctx.batch is None:
                ctx.batch = _SlotSync(self, slot)
            uses = set(step_uses(proc, name) or ())
            if uses and uses <= self.batch_roles:
                self._batch_step(slot, proc, name, ctx)
                return
            getattr(proc, name)(ctx)  # a shared instrument: its lock taken for each use (bench.slots.SlotShare)

        return gate

    def _batch_check(self) -> None:
        """The checkpoint of a batch step's table waits: the batch's abort and the shared devices."""
        if self._abort_reason is not None:
            raise RunAborted(self._abort_reason)
        self.station.check_shared(None)

    def _barrier(self, slot: int, key: str, value: Any = None) -> bool:
        """Wait (parked in the clock) until every slot still in the batch has reached `key`; True
        for the one that leads it (the lowest slot): it runs what is run once and then `_release`s."""
        runner = self.runners[slot]
        clock = self.station.base_clock
        park = hasattr(clock, "park")
        lead = False
        if park:
            clock.park()
        try:
            with self._cond:
                self._idents[slot] = threading.get_ident()
                arrived = self._arrived.setdefault(key, set())
                arrived.add(slot)
                self._values.setdefault(key, {})[slot] = value
                self._cond.notify_all()
                while key not in self._done:
                    if self._active <= arrived and slot == min(self._active):
                        lead = True
                        break
                    if runner.stopping:
                        arrived.discard(slot)
                        self._values[key].pop(slot, None)
                        self._cond.notify_all()
                        break
                    self._cond.wait(0.05)
        finally:
            if park:
                clock.unpark()
        runner.checkpoint()  # an abort while waiting at the barrier ends the slot's run here
        return lead

    def _release(self, slot: int, key: str, exc: BaseException | None, result: Any = None) -> None:
        """The leader of `key` is done: the slots that waited hold the world back again (before
        this slot's next wait), and learn the result."""
        clock = self.station.base_clock
        with self._cond:
            self._results[key] = result
            self._done[key] = (slot, exc)
            if hasattr(clock, "park"):
                for other in self._arrived[key] - {slot}:
                    clock.unpark(self._idents[other])
            self._cond.notify_all()

    def _follow(self, slot: int, key: str, what: str, ctx: Any) -> Any:
        """A slot that waited for `key`'s leader: its result, or its failure raised in this slot."""
        runner = self.runners[slot]
        leader, exc = self._done[key]
        if exc is None:
            return self._results.get(key)
        text = f"batch step {what!r} (run by slot {leader}) failed: {exc}"
        if isinstance(exc, SafetyTripError | LinkLostError):
            raise type(exc)(text)
        if isinstance(exc, RunAborted):
            runner.checkpoint()
            raise RunAborted(exc.reason)
        raise RuntimeError(text)

    def sync(self, slot: int, ctx: Any, *, action: Callable[[], Any] | None = None, value: Any = None,
             what: str = "") -> tuple[Any, list[Any]]:
        """ctx.shared / ctx.gather within a slot step: the slots meet at their n-th sync (they run
        the same code); the lowest runs `action` once (the shared devices' clock guarded by the
        batch's checks); every slot gets its result and the values the slots gave, slot order."""
        n = self._sync_seq.get(slot, 0) + 1
        self._sync_seq[slot] = n
        key = f"sync#{n}"
        what = what or key
        if self._barrier(slot, key, value):
            table_clock = self.station.table_clock
            table_clock.guard = self._batch_check
            exc: BaseException | None = None
            result = None
            try:
                if action is not None:
                    result = action()
            except BaseException as e:
                exc = e
                raise
            finally:
                table_clock.guard = None
                self._release(slot, key, exc, result)
        else:
            result = self._follow(slot, key, what, ctx)
        with self._cond:
            values = [v for _, v in sorted(self._values.get(key, {}).items())]
        return result, values

    def _batch_step(self, slot: int, proc: Procedure, name: str, ctx: Any) -> None:
        if self._barrier(slot, name):
            table_clock = self.station.table_clock
            table_clock.guard = self._batch_check
            exc: BaseException | None = None
            try:
                getattr(proc, name)(ctx)
            except BaseException as e:
                exc = e
                raise
            finally:
                table_clock.guard = None
                self._release(slot, name, exc)
            return
        leader, _ = self._done[name]
        self._follow(slot, name, name, ctx)
        ctx.log.info(f"batch step {name!r}: run once for the {len(self._arrived[name])} slots by slot {leader}")


class _SlotSync:
    """A slot run's handle on its batch (RunContext.batch): ctx.shared and ctx.gather go through it."""

    def __init__(self, batch: Batch, slot: int) -> None:
        self.batch, self.slot = batch, slot

    def sync(self, ctx: Any, **kw: Any) -> tuple[Any, list[Any]]:
        return self.batch.sync(self.slot, ctx, **kw)
