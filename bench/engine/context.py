"""What a procedure step sees: devices, the bench clock, the recorder, a logger, measure()."""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from bench.clock import Deadline
from bench.streams import StreamSchema, schema_of

from . import events as ev
from .measurement import Limits, Result
from .recording import PauseLog, RecordSpan, record_for, sleep_until


class RunAborted(Exception):
    """Raised at a checkpoint after an abort; the engine then brings the station to safe state."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(reason)


class GuardedClock:
    """A bench clock whose waits are engine checkpoints (pause holds, abort raises).  Drivers are
    built with it, so a table's `wait_at_rate` can be aborted too.  With no guard set (outside a
    run, and during the safe state) it is the plain clock."""

    MAX_SLICE_S = 0.1
    #: lockstep: waits are cut at every multiple of this many simulated seconds and the station's
    #: link checks run there (bench.station), so an abort is seen and a fault found within it; a
    #: grid, not a slice length, so a check is never more than this apart (0.1 s slices with a
    #: check every 0.35 s let it drift to 0.45 s, and cost 4x more world advances)
    LOCKSTEP_GRID_S = 0.4

    def __init__(self, base: Any) -> None:
        self.base = base
        self.guard: Callable[[], None] | None = None
        #: bench seconds the run was held paused so far (a real-time station's clock runs on while
        #: paused): a wait's timeout leaves them out (wait_until, the rate table's waits), so a pause
        #: longer than a timeout does not end the run when it resumes
        self.paused_s = 0.0

    def _check(self) -> None:
        guard = self.guard
        if guard is not None:
            guard()

    def now(self) -> float:
        return self.base.now()

    def sleep(self, dt_s: float) -> None:
        """Sleep in slices of at most MAX_SLICE_S, checking between them: a 300 s recording
        can still be paused or aborted within a tenth of a simulated second."""
        if self.guard is None:
            self.base.sleep(dt_s)
            return
        if not dt_s >= 0:
            raise ValueError(f"clock wait dt_s={dt_s!r} must be finite and >= 0")
        self._check()
        if not getattr(self.base, "lockstep", True):
            # real time: the world moves on while the checks between slices run, so the slices
            # aim at one deadline (summing them would stretch a 10 s wait to 100 s at 100x)
            deadline = self.base.now() + float(dt_s)
            while (left := deadline - self.base.now()) > 1e-12:
                self.base.sleep(min(left, self.MAX_SLICE_S))
                self._check()
            return
        grid = self.LOCKSTEP_GRID_S if getattr(self.base, "lockstep", False) else None
        remaining = float(dt_s)
        while remaining > 1e-12:
            if grid is None:
                piece = min(remaining, self.MAX_SLICE_S)
            else:  # up to the next grid point (or the end of the wait)
                now = self.base.now()
                piece = min(remaining, (math.floor(now / grid + 1e-9) + 1) * grid - now)
            self.base.sleep(piece)
            remaining -= piece
            self._check()

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        """Poll condition until it holds (True) or timeout_s of bench time, paused time left out, passed."""
        if not timeout_s >= 0 or poll_s <= 0:
            raise ValueError(f"wait_until(timeout_s={timeout_s!r}, poll_s={poll_s!r}): bad arguments")
        deadline = Deadline(self, timeout_s)
        while True:
            self._check()
            if condition():
                return True
            remaining = deadline.remaining_s()
            if remaining <= 1e-12:
                return bool(condition())
            self.sleep(min(poll_s, remaining))

    def __getattr__(self, name: str) -> Any:  # speed, set_speed, world, close ... of the base
        return getattr(self.base, name)


class Devices(Mapping):
    """The station's devices by role, also as attributes: `ctx.devices.table`."""

    def __init__(self, devices: Mapping[str, Any]) -> None:
        self._devices = dict(devices)

    def __getitem__(self, role: str) -> Any:
        try:
            return self._devices[role]
        except KeyError:
            raise KeyError(f"this station has no {role!r} device (it has: {sorted(self._devices)})") from None

    def __getattr__(self, role: str) -> Any:
        if role.startswith("_"):
            raise AttributeError(role)
        try:
            return self[role]
        except KeyError as exc:
            raise AttributeError(str(exc)) from None

    def __iter__(self):
        return iter(self._devices)

    def __len__(self) -> int:
        return len(self._devices)


class _BusLogHandler(logging.Handler):
    def __init__(self, ctx: RunContext) -> None:
        super().__init__()
        self.ctx = ctx

    def emit(self, record: logging.LogRecord) -> None:
        self.ctx.publish(ev.Log, level=record.levelname, message=record.getMessage())


class RunContext:
    """Handed to every step.  Everything a procedure does to the world goes through it."""

    def __init__(
        self,
        *,
        run_id: str,
        params: dict[str, Any],
        devices: Mapping[str, Any],
        clock: GuardedClock,
        bus: ev.EventBus,
        recorder: Any = None,
        checkpoint: Callable[[], None] | None = None,
        station: Any = None,
        procedure: Any = None,
    ) -> None:
        if getattr(procedure, "uses_compute", True):
            from .compute import warm

            warm()  # the workers of `compute` start from a forkserver: its imports go on beside the run
        self.run_id = run_id
        self.procedure = procedure  # its declared measurements check and complete what is reported
        self.params = params
        self.devices = devices if isinstance(devices, Devices) else Devices(devices)
        self.clock = clock
        self.bus = bus
        self.recorder = recorder
        self.station = station
        self.results: list[Result] = []
        self._checkpoint = checkpoint or (lambda: None)
        self.log = logging.getLogger(f"gyrobench.run.{run_id}")
        self.log.setLevel(logging.DEBUG)
        self.log.propagate = False
        self._handler = _BusLogHandler(self)
        self.log.addHandler(self._handler)
        self._finalizers: list[tuple[str, Callable[[], Any]]] = []
        self._finalizers_lock = threading.Lock()
        self._streams: dict[str, StreamSchema] = {}  # declared in this run (StreamDeclared sent)
        self._streams_lock = threading.Lock()
        self.pauses = PauseLog()  # the run's pauses (bench times), as the engine saw them
        self._pause_lock = threading.Lock()
        self._paused_at: float | None = None

    # --- events --------------------------------------------------------------------------
    def publish(self, cls: type[ev.Event], **fields: Any) -> None:
        self.bus.publish(cls(run_id=self.run_id, t_sim_s=self.clock.now(), **fields))

    def close(self) -> None:
        self.log.removeHandler(self._handler)

    # --- several gyros in one batch (bench.engine.batch) --------------------------------------
    #: the batch's sync for this slot's run (set by bench.engine.batch); None: a run on its own
    batch: Any = None

    @property
    def in_batch(self) -> bool:
        """This run is one slot of a batch: the shared devices are the batch's (their safe state too)."""
        return self.batch is not None

    def shared(self, action: Callable[[], Any], what: str = "") -> Any:
        """Run `action` (a use of a device the slots share: the chamber, the table) once for the
        batch, after every slot still in it has reached this call, and hand its result to every
        slot; on its own, run it.  The slots must call it in the same order (the same code)."""
        if self.batch is None:
            return action()
        return self.batch.sync(self, action=action, what=what)[0]

    def gather(self, value: Any, what: str = "") -> list[Any]:
        """Every slot's `value` (slot order) once every slot still in the batch has given its own:
        a judgement over all units (settled when every unit's drift is below the limit); alone, [value]."""
        if self.batch is None:
            return [value]
        return self.batch.sync(self, value=value, what=what)[1]

    # --- resources that live as long as the run --------------------------------------------
    def defer(self, fn: Callable[[], Any], what: str = "") -> None:
        """Run `fn` when the run ends, whatever happens (last deferred, first run), before the
        safe state: the runner calls `close_resources`."""
        with self._finalizers_lock:
            self._finalizers.append((what or getattr(fn, "__qualname__", repr(fn)), fn))

    def subscribe(self, device: Any, callback: Callable[[Any], None]) -> None:
        """Subscribe `callback` to a device's stream for the rest of the run; the runner
        unsubscribes it when the run ends (nothing for the procedure to undo)."""
        unsubscribe = device.subscribe(callback)
        name = getattr(callback, "__qualname__", type(callback).__name__)
        self.defer(unsubscribe, f"unsubscribe {name}")

    def close_resources(self, timeout_s: float = 5.0) -> list[str]:
        """Run the deferred teardowns, last first, each on a helper thread given `timeout_s` (wall):
        one that fails or hangs is logged and the next still runs.  Returns the failures."""
        with self._finalizers_lock:
            todo, self._finalizers = self._finalizers[::-1], []
        failures: list[str] = []
        for what, fn in todo:
            error: list[BaseException] = []

            def call(fn=fn, error=error) -> None:
                try:
                    fn()
                except BaseException as exc:  # noqa: BLE001 - reported below, the next teardown runs
                    error.append(exc)

            worker = threading.Thread(target=call, name=f"run-teardown {what}", daemon=True)
            worker.start()
            worker.join(timeout_s)
            if worker.is_alive():
                failures.append(f"{what}: still running after {timeout_s:g} s")
            elif error:
                failures.append(f"{what}: {type(error[0]).__name__}: {error[0]}")
        for text in failures:
            self.log.error(f"run teardown failed: {text}")
        return failures

    # --- engine checkpoints ----------------------------------------------------------------
    def checkpoint(self) -> None:
        """Hold here while paused; raise RunAborted after an abort."""
        self._checkpoint()

    def sleep(self, dt_s: float) -> None:
        self.clock.sleep(dt_s)

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        return self.clock.wait_until(condition, timeout_s, poll_s)

    def sleep_until(self, t_abs_s: float) -> float:
        """Wait until the bench clock reads t_abs_s (an absolute deadline); its time then."""
        return sleep_until(self.clock, t_abs_s)

    def record_for(self, record_s: float, label: str = "record", *, progress_every_s: float = 10.0,
                   policy: str | None = None, progress: Callable[[float, str], None] | None = None) -> RecordSpan:
        """Let the bench clock run record_s seconds to an absolute deadline (progress between, a
        pause excluded or restarting the record as the procedure declares); the span to keep."""
        return record_for(self, record_s, label, progress_every_s=progress_every_s, policy=policy, progress=progress)

    def paused(self) -> None:
        """The engine holds at a checkpoint: a Paused event (log row PAUSE) at the bench time now."""
        with self._pause_lock:
            if self._paused_at is not None:
                return
            self._paused_at = t = self.clock.now()
        self.bus.publish(ev.Paused(run_id=self.run_id, t_sim_s=t, message=f"paused at t = {t:.3f} s"))

    def resumed(self) -> None:
        """The engine goes on: a Resumed event and the span kept in `pauses`."""
        with self._pause_lock:
            t0, self._paused_at = self._paused_at, None
            if t0 is None:
                return
            t1 = self.clock.now()
            self.pauses.spans.append((t0, t1))
            if isinstance(self.clock, GuardedClock):
                self.clock.paused_s += t1 - t0
        self.bus.publish(ev.Resumed(run_id=self.run_id, t_sim_s=t1, paused_from_s=t0,
                                    message=f"resumed at t = {t1:.3f} s after {t1 - t0:.3f} s of bench time paused"))

    def compute(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """fn(*args, **kwargs) for a long computation (a fit, an identification): it runs in a
        worker process that an abort ends at once, so the safe state never waits for an estimator.
        fn must be a module-level function; its arguments and result must pickle."""
        from .compute import run_in_worker

        return run_in_worker(fn, args, kwargs, self.checkpoint)

    def progress(self, fraction: float, message: str = "") -> None:
        self.checkpoint()
        self.publish(ev.Progress, fraction=float(min(max(fraction, 0.0), 1.0)), message=message)

    # --- data ------------------------------------------------------------------------------
    def declare_stream(self, stream: str | StreamSchema) -> StreamSchema:
        """Announce a stream's schema (once a run, before its first block); a name is looked up
        among the declared streams (bench.streams.declare)."""
        schema = stream if isinstance(stream, StreamSchema) else schema_of(stream)
        with self._streams_lock:
            known = self._streams.get(schema.name)
            if known is not None:
                if known != schema:
                    raise ValueError(f"stream {schema.name!r} was declared differently earlier in this run")
                return known
            self._streams[schema.name] = schema
            self.publish(ev.StreamDeclared, schema=schema)  # under the lock: before any block of it
        return schema

    def record(self, stream: str | StreamSchema, columns: tuple[str, ...] | list[str], data: np.ndarray) -> None:
        """Rows of a declared stream to the recorder (and every other subscriber); `columns` are
        the schema's names, in its order."""
        name = stream.name if isinstance(stream, StreamSchema) else stream
        schema = self._streams.get(name) or self.declare_stream(stream)
        if tuple(columns) != schema.names:
            raise ValueError(f"record({name!r}): columns {tuple(columns)} are not the declared {schema.names}")
        arr = np.asarray(data, dtype=float)
        if arr.ndim == 1:
            arr = arr.reshape(1, -1)
        if arr.shape[1] != len(columns):
            raise ValueError(f"record({name!r}): data has {arr.shape[1]} columns, names give {len(columns)}")
        self.publish(ev.SampleBlock, stream=name, columns=schema.names, data=arr)

    def fit(self, name: str, **curves: np.ndarray) -> None:
        self.publish(ev.FitUpdate, name=name, curves={k: np.asarray(v) for k, v in curves.items()})

    def data(self) -> Any:
        """What the recorder holds so far (a `bench.recorder.RunData`)."""
        if self.recorder is None:
            raise RuntimeError("this run has no recorder")
        return self.recorder.data()

    def measure(
        self,
        name: str,
        value: float,
        unit: str | None = None,
        *,
        ci95: tuple[float, float] | None = None,
        limits: Limits | tuple | dict | None = None,
        dut: str | None = None,
    ) -> Result:
        """Report a declared measurement (unit None: the declared one); its outcome comes from the
        limits, by default the declared ones (PASS / FAIL / MARGINAL)."""
        res = Result(
            name=name,
            value=float(value),
            unit=unit,
            ci95=None if ci95 is None else (float(ci95[0]), float(ci95[1])),
            limits=Limits.of(limits),
            dut=dut,
        )
        return self.report(res)

    def report(self, res: Result) -> Result:
        """Record a Result made elsewhere (e.g. by the procedure's analysis hook).  With a procedure,
        a name it did not declare or another unit raises MeasurementError (the run ends ERROR)."""
        if self.procedure is not None:
            res = self.procedure.resolve_result(res)
        self.results.append(res)
        self._publish_result(res)
        return res

    def not_measured(self) -> list[Result]:
        """The declared measurements (condition holding) never reported, published as NOT_MEASURED
        (the recorder and the window show them); called by the runner at the run's end, never raises."""
        if self.procedure is None:
            return []
        try:
            missing = self.procedure.not_measured(self.results)
        except Exception as exc:  # noqa: BLE001 - a declaration's condition failed: say so, keep the run's end
            self.log.warning(f"the declared measurements' conditions could not be evaluated: {exc}")
            return []
        for res in missing:
            self._publish_result(res)
        return missing

    def _publish_result(self, res: Result) -> None:
        lim = res.limits
        self.publish(
            ev.Measurement,
            name=res.name,
            value=res.value,
            unit=res.unit or "",
            ci95=res.ci95,
            low=None if lim is None else lim.low,
            high=None if lim is None else lim.high,
            outcome=res.outcome,
            dut=res.dut,
            marginal_low=None if lim is None else lim.marginal_low,
            marginal_high=None if lim is None else lim.marginal_high,
        )
