"""What a procedure step sees: devices, the bench clock, the recorder, a logger, measure()."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from . import events as ev
from .measurement import Limits, Result


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

    def __init__(self, base: Any) -> None:
        self.base = base
        self.guard: Callable[[], None] | None = None

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
        remaining = float(dt_s)
        while remaining > 1e-12:
            piece = min(remaining, self.MAX_SLICE_S)
            self.base.sleep(piece)
            remaining -= piece
            self._check()

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        if not timeout_s >= 0 or poll_s <= 0:
            raise ValueError(f"wait_until(timeout_s={timeout_s!r}, poll_s={poll_s!r}): bad arguments")
        deadline = self.now() + timeout_s
        while True:
            self._check()
            if condition():
                return True
            remaining = deadline - self.now()
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

    # --- events --------------------------------------------------------------------------
    def publish(self, cls: type[ev.Event], **fields: Any) -> None:
        self.bus.publish(cls(run_id=self.run_id, t_sim_s=self.clock.now(), **fields))

    def close(self) -> None:
        self.log.removeHandler(self._handler)

    # --- engine checkpoints ----------------------------------------------------------------
    def checkpoint(self) -> None:
        """Hold here while paused; raise RunAborted after an abort."""
        self._checkpoint()

    def sleep(self, dt_s: float) -> None:
        self.clock.sleep(dt_s)

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        return self.clock.wait_until(condition, timeout_s, poll_s)

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
    def record(self, stream: str, columns: tuple[str, ...] | list[str], data: np.ndarray) -> None:
        """Rows of a named stream to the recorder (and every other subscriber)."""
        arr = np.asarray(data, dtype=float)
        if arr.ndim == 1:
            arr = arr.reshape(1, -1)
        if arr.shape[1] != len(columns):
            raise ValueError(f"record({stream!r}): data has {arr.shape[1]} columns, names give {len(columns)}")
        self.publish(ev.SampleBlock, stream=stream, columns=tuple(columns), data=arr)

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
