"""The run engine: validates parameters, runs the steps, owns pause / resume / abort, brings the
station to its safe state whatever happened, and records why the run ended.

    runner = Runner(station, runs_dir="runs", store=store)
    record = runner.run(TableSpin, {"rate_dps": 200.0})
    record.outcome, record.end_reason, record.safe_state, record.as_json()

`abort(reason)`, `pause()`, `resume()` may be called from any thread (a GUI, a signal handler);
they take effect at the next checkpoint (any bench-clock wait, `ctx.progress`, a step boundary).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import signal
import subprocess
import threading
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.errors import LinkLostError, SafetyTripError

from . import events as ev
from .context import GuardedClock, RunAborted, RunContext
from .demands import check_station
from .measurement import ABORTED, COMPLETE, ERROR, FAIL, Result, combine_outcomes
from .procedure import Procedure
from .safety import SafeStateReport


@functools.cache
def software_version() -> str:
    """Package version, plus the git commit when running from a checkout."""
    from bench import __version__

    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
        )
        if rev.returncode == 0 and rev.stdout.strip():
            return f"{__version__}+g{rev.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    return __version__


def new_run_id() -> str:
    return _dt.datetime.now().strftime("%Y%m%d-%H%M%S-") + uuid.uuid4().hex[:6]


@dataclass
class RunRecord:
    """Everything the results store, the CLI's --json and the report need about a run."""

    run_id: str
    procedure: str
    params: dict[str, Any]
    station_id: str
    simulated: bool
    outcome: str = COMPLETE
    end_reason: str = ""
    safe_state: bool = False
    safe_detail: dict[str, Any] = field(default_factory=dict)
    measurements: list[Result] = field(default_factory=list)
    truth: dict[str, float] | None = None
    simulated_s: float = 0.0
    wall_s: float = 0.0
    raw_file: str | None = None
    started_at: str = ""
    finished_at: str = ""
    software_version: str = ""
    operator: str = ""
    duts: list[str] = field(default_factory=list)
    seed: int | None = None
    failed_step: str | None = None
    traceback: str | None = None
    store_error: str | None = None  # the results store did not take the record (it is in the spool)
    stream_overflow_blocks: int = 0  # stream blocks real time dropped because the writer fell behind
    speed_achieved: float | None = None  # simulated s per wall s, on a real-time simulated station

    def as_json(self) -> dict[str, Any]:
        """The shape of `gyrobench run --json`."""
        meas: dict[str, Any] = {}
        for r in self.measurements:
            key = r.name if r.dut is None else f"{r.dut}:{r.name}"
            meas[key] = r.as_json()
        speed = {} if self.speed_achieved is None else {"speed_achieved": float(self.speed_achieved)}  # real time only
        return {
            "run_id": self.run_id,
            "procedure": self.procedure,
            "outcome": self.outcome,
            "measurements": meas,
            "truth": None if self.truth is None else {k: float(v) for k, v in self.truth.items()},
            "simulated_s": float(self.simulated_s),
            "wall_s": float(self.wall_s),
            "safe_state": bool(self.safe_state),
            "end_reason": self.end_reason,
            "raw_file": self.raw_file,
            **speed,
        }


class Runner:
    """Runs procedures on one station.  One run at a time."""

    def __init__(
        self,
        station: Any,
        *,
        bus: ev.EventBus | None = None,
        runs_dir: str | Path | None = None,
        store: Any = None,
        operator: str = "",
        duts: list[str] | tuple[str, ...] = (),
        step_gate: Any = None,
        compact_later: bool = False,
    ) -> None:
        self.station = station
        #: leave the raw file's compression to the caller (bench.recorder.compact_in_background), so
        #: a command can return first; `pending_compaction` is the file it is left to do for
        self.compact_later = compact_later
        self.pending_compaction: Path | None = None
        #: step_gate(proc, name, ctx) runs one step instead of the runner (bench.engine.batch: batch
        #: steps once for every slot, a shared instrument's lock around a slot's step)
        self.step_gate = step_gate
        #: the id the next run takes (a batch names its slots' runs after itself); None = a new one
        self.next_run_id: str | None = None
        self.bus = bus or ev.EventBus()
        self.runs_dir = None if runs_dir is None else Path(runs_dir)
        self.store = store
        self.operator = operator
        self.duts = list(duts)
        self._abort_reason: str | None = None
        self._fatal: RunAborted | None = None  # the recorder failed (reported by bench.writer)
        self._running = threading.Event()
        self._running.set()
        self._in_run = False
        self.record: RunRecord | None = None
        self._ctx: RunContext | None = None  # the run's context while a run goes on (pause events)

    # --- control, from any thread ------------------------------------------------------------
    def abort(self, reason: str = "abort requested") -> None:
        """Takes no lock: a signal handler runs it in the main thread, which may be inside the
        checkpoint's Event.wait holding that Event's (non-reentrant) lock; a paused checkpoint
        polls the reason every 0.05 s instead of being woken."""
        if self._abort_reason is None:
            self._abort_reason = reason

    def fail(self, reason: str) -> None:
        """End the run at its next checkpoint with outcome ERROR (a slot that lost a shared
        instrument's lock; a batch step that failed for every slot)."""
        if self._fatal is None:
            exc = RunAborted(reason)
            exc.outcome = ERROR
            self._fatal = exc
        self._running.set()

    @property
    def stopping(self) -> bool:
        """An abort or a failure is pending: the next checkpoint raises."""
        return self._abort_reason is not None or self._fatal is not None

    def pause(self) -> None:
        self._running.clear()

    def resume(self) -> None:
        self._running.set()

    @property
    def paused(self) -> bool:
        return not self._running.is_set()

    def checkpoint(self) -> None:
        """Raise RunAborted after an abort, hold while paused, raise a lost link the station saw."""
        check = getattr(self.station, "check_links", None)
        ctx = self._ctx
        held = False
        while True:
            if self._fatal is not None:
                raise self._fatal
            if self._abort_reason is not None:
                raise RunAborted(self._abort_reason)
            if self._running.is_set() or self._running.wait(0.05):
                break
            if not held and ctx is not None:  # a pause is an event in the log and the raw file
                held = True
                ctx.paused()
            if check is not None:  # paused: a trip or a lost link still ends the run (real time)
                check()
        if held:
            ctx.resumed()
        if self._fatal is not None:
            raise self._fatal
        if self._abort_reason is not None:
            raise RunAborted(self._abort_reason)
        if check is not None:
            check()

    def _recorder_failed(self, exc: BaseException) -> None:
        """The recorder could not write: the run ends at the next checkpoint (outcome ERROR)."""
        if self._fatal is None:
            if not isinstance(exc, RunAborted):
                exc = RunAborted(f"raw data: {type(exc).__name__}: {exc}")
                exc.outcome = ERROR
            self._fatal = exc
        self._running.set()

    # --- the run -----------------------------------------------------------------------------
    def run(self, procedure: type[Procedure] | Procedure, params: dict[str, Any] | None = None) -> RunRecord:
        """Run a procedure; ParamError (before anything moves) if a parameter is bad."""
        proc = procedure if isinstance(procedure, Procedure) else procedure(params)
        proc.take_nominal(getattr(self.station, "nominal", None) or {})  # K, f0 ... the procedure assumes
        check_station(proc, self.station)  # kind and limits: StationMismatch before anything moves
        missing = [r for r in proc.requires if r not in self.station.devices]
        if missing:
            raise ValueError(
                f"procedure {proc.name!r} needs device role(s) {missing}; station {self.station.id!r} has "
                f"{sorted(self.station.devices)}"
            )
        if self._in_run:
            from .manual import busy_text  # names what holds the station: a run or manual control

            held = self.record
            raise RuntimeError(busy_text(held.procedure, held.run_id, self.station.id) if held
                               else "this runner is already running a procedure")
        self._in_run = True
        try:
            return self._run(proc)
        finally:
            self._in_run = False
            self._abort_reason = None
            self._fatal = None
            self._running.set()

    def _run(self, proc: Procedure) -> RunRecord:
        # an abort requested before the run began (Ctrl-C while the station opened) still holds
        st = self.station
        clock: GuardedClock = st.clock
        run_id, self.next_run_id = self.next_run_id or new_run_id(), None
        rec = RunRecord(
            run_id=run_id,
            procedure=proc.name,
            params=dict(proc.params),
            station_id=st.id,
            simulated=bool(st.simulated),
            started_at=_dt.datetime.now(_dt.UTC).isoformat(),
            software_version=software_version(),
            operator=self.operator,
            duts=list(self.duts),
            seed=getattr(st, "seed", None),
            truth=st.truth() if st.simulated else None,
        )
        self.record = rec
        steps = proc.step_specs()
        t0_sim, t0_wall = clock.now(), time.monotonic()
        speed_mark = clock.mark() if not getattr(clock, "lockstep", True) else None  # real time: _report_speed

        recorder = writer = None
        unsubscribe_rec = None
        if self.runs_dir is not None:
            from bench.recorder import RawDataError, Recorder
            from bench.writer import WriterThread

            try:
                recorder = Recorder.for_run(self.runs_dir, rec, station=st.describe(),
                                            param_units={k: v.unit for k, v in proc.param_specs().items()})
            except RawDataError as exc:  # ends the run at its first checkpoint, before anything moves
                self._fatal = exc
            else:
                rec.raw_file = str(recorder.path)
                recorder.defer_compaction = self.compact_later
                # the recorder is fed by bench.writer (a queue and a thread in real time)
                writer = WriterThread(recorder, lockstep=lambda: bool(getattr(clock, "lockstep", False)),
                                      on_error=self._recorder_failed)
                unsubscribe_rec = self.bus.subscribe(writer.put)
        ctx = RunContext(
            run_id=run_id,
            params=proc.params,
            devices=st.devices,
            clock=clock,
            bus=self.bus,
            recorder=writer,
            checkpoint=self.checkpoint,
            station=st,
            procedure=proc,
        )
        self._ctx = ctx
        spool_dir = None if self.runs_dir is None else self.runs_dir / "spool"  # records the store refused
        if self.store is not None:  # the run's RUNNING row (and heartbeat); never raises
            for note in self.store.begin_run(rec, spool_dir):
                ctx.log.warning(note)
        ctx.publish(
            ev.RunStarted,
            procedure=proc.name,
            params=dict(proc.params),
            station=st.id,
            simulated=bool(st.simulated),
            steps=tuple(s for s, _ in steps),
        )
        stop_streams = None
        outcome: str | None = None
        current = ""
        try:
            clock.guard = self.checkpoint
            if hasattr(st, "ensure_ready"):  # a link lost since the last run: reconnected, or named down
                st.ensure_ready()
            stop_streams = st.start_streams(ctx) if hasattr(st, "start_streams") else None
            for index, (name, title) in enumerate(steps):
                current = name
                self.checkpoint()
                ctx.publish(ev.StepStarted, name=name, index=index, total=len(steps), title=title)
                if self.step_gate is None:
                    getattr(proc, name)(ctx)
                else:
                    self.step_gate(proc, name, ctx)
                ctx.publish(ev.StepFinished, name=name, index=index, status="done")
            rec.end_reason = "completed"
        except RunAborted as exc:
            outcome = getattr(exc, "outcome", ABORTED)  # ERROR when the raw data cannot be written
            rec.end_reason = f"aborted: {exc.reason}" if outcome == ABORTED else exc.reason
            self._step_failed(ctx, steps, current, "aborted" if outcome == ABORTED else "error")
        except KeyboardInterrupt:
            outcome, rec.end_reason = ABORTED, "aborted: SIGINT"
            self._step_failed(ctx, steps, current, "aborted")
        except LinkLostError as exc:
            outcome, rec.end_reason = ERROR, f"link lost: {exc}"
            self._step_failed(ctx, steps, current, "error")
        except SafetyTripError as exc:
            outcome, rec.end_reason = ERROR, f"safety trip: {exc}"
            self._step_failed(ctx, steps, current, "error")
        except Exception as exc:  # noqa: BLE001 - any failure must still reach the safe state
            outcome, rec.end_reason = ERROR, f"{type(exc).__name__} in step {current!r}: {exc}"
            rec.traceback = traceback.format_exc()
            self._step_failed(ctx, steps, current, "error")
        finally:
            clock.guard = None
            self._ctx = None
            if outcome is not None:
                rec.failed_step = current
            with _sigint_deferred(ctx):  # what the procedure acquired, before the safe state; never raises
                ctx.close_resources()
            report = self._safe_state(ctx)
            if stop_streams is not None:
                try:
                    stop_streams()
                except Exception as exc:  # noqa: BLE001
                    ctx.log.warning(f"stopping the streams failed: {exc}")
            rec.safe_state = report.confirmed
            rec.safe_detail = {"devices": report.devices, "errors": report.errors, "order": report.order}
            rec.measurements = list(ctx.results) + ctx.not_measured()  # and the declared ones never reported
            fatal = self._fatal
            if fatal is not None and fatal.reason not in rec.end_reason:  # failed after the last checkpoint
                rec.end_reason = fatal.reason if outcome is None else f"{rec.end_reason}; {fatal.reason}"
                outcome = ERROR
            if outcome is None:
                # a declared measurement with limits that was never measured cannot pass
                outcome = combine_outcomes(FAIL if not r.measured and r.limits else r.outcome for r in rec.measurements)
                if not report.confirmed:
                    outcome = ERROR
                    rec.end_reason = "completed, but the safe state was not confirmed"
            rec.outcome = outcome
            rec.simulated_s = clock.now() - t0_sim
            rec.wall_s = time.monotonic() - t0_wall
            self._report_speed(ctx, rec, clock, speed_mark)
            rec.finished_at = _dt.datetime.now(_dt.UTC).isoformat()
            if writer is not None and writer.overflow_blocks:  # real time only: counted, never silent
                rec.stream_overflow_blocks = writer.overflow_blocks
                ctx.log.warning(writer.overflow_text())
            if recorder is not None:
                if unsubscribe_rec is not None:
                    unsubscribe_rec()
                writer.close()
                try:
                    recorder.close(rec)
                except Exception as exc:  # noqa: BLE001 - the record and the store must still be written
                    rec.outcome = ERROR
                    rec.end_reason += f" (closing the raw file failed: {exc})"
                self.pending_compaction = recorder.path if recorder.compaction_pending else None
            ctx.close()
            if self.store is not None:  # saved, or kept in the spool: then store_error says so
                rec.store_error = self.store.finish_run(rec, spool_dir)
                if rec.store_error:
                    ctx.publish(ev.Log, level="ERROR", message=rec.store_error)
            # last: a listener (the window, a line) may open the raw file and the store's row at once
            ctx.publish(
                ev.RunFinished,
                outcome=rec.outcome,
                end_reason=rec.end_reason,
                safe_state=rec.safe_state,
                raw_file=rec.raw_file,
            )
        return rec

    def _report_speed(self, ctx: RunContext, rec: RunRecord, clock: Any, mark: tuple[float, float] | None) -> None:
        """Real time at a speed factor: say the speed achieved (the clock falls behind, rather
        than a link timing out, when the machine cannot keep up)."""
        asked = getattr(clock, "speed", None)
        if mark is None or getattr(clock, "lockstep", True) or not asked or rec.wall_s <= 0:
            return
        rec.speed_achieved = clock.achieved_speed(mark)  # on the time due: a catch-up is not read as speed
        slow = rec.speed_achieved < 0.9 * asked
        ctx.publish(
            ev.Log,
            level="WARNING" if slow else "INFO",
            message=f"real time: {rec.speed_achieved:.3g}x achieved of the {asked:g}x asked"
            + (" (this machine could not keep up; the simulated clock fell behind)" if slow else ""),
        )

    def _step_failed(self, ctx: RunContext, steps: list, current: str, status: str) -> None:
        names = [s for s, _ in steps]
        idx = names.index(current) if current in names else -1
        ctx.publish(ev.StepFinished, name=current, index=idx, status=status)

    def _safe_state(self, ctx: RunContext) -> SafeStateReport:
        with _sigint_deferred(ctx):
            try:
                report = self.station.safe_state()
            except Exception as exc:  # noqa: BLE001
                report = SafeStateReport(confirmed=False, errors={"station": f"{type(exc).__name__}: {exc}"})
        level = "INFO" if report.confirmed else "ERROR"
        ctx.publish(
            ev.Log,
            level=level,
            message=f"safe state {'confirmed' if report.confirmed else 'NOT confirmed'}: {report.devices}"
            + (f" errors {report.errors}" if report.errors else ""),
        )
        return report


@contextlib.contextmanager
def _sigint_deferred(ctx: RunContext):
    """While the safe state runs, Ctrl-C is logged, not raised: a second Ctrl-C must not leave
    the table turning or the drive on.  (Signal handlers live in the main thread only.)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def note(signum, _frame):
        ctx.log.warning("Ctrl-C during the safe state: finishing it first")

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
