"""Procedures: classes with typed parameters and named steps; the engine runs them.

A procedure declares its parameters (`Param`: default, unit, limits; checked before any device
moves) and its steps (methods marked `@step`, run in the order they are written).  Each step
gets a `RunContext` (`bench.engine.context`): the station's devices, the bench clock, the
recorder, a logger and `measure(...)`.  The engine (`bench.engine.runner.Runner`), not the
procedure, owns pause, resume, abort and the safe state: every wait on `ctx.clock` (and every
driver wait, since drivers share that clock) is a checkpoint where a pause holds and an abort
raises `RunAborted`.  Do not catch `RunAborted`; clean-up is the engine's job.

Example (procedures/examples/table_spin.py is the full file):

    from bench.engine import Param, Procedure, step

    class TableSpin(Procedure):
        '''Spin the table and check the rate it reports.'''

        name = "table-spin"
        rate_dps = Param(100.0, unit="deg/s", low=-1000.0, high=1000.0, doc="table rate")
        hold_s = Param(2.0, unit="s", low=0.1, high=600.0, doc="time at rate")

        @step("Spin up")
        def spin_up(self, ctx):
            ctx.devices.table.enable()
            ctx.devices.table.set_rate(self.rate_dps)
            ctx.devices.table.wait_at_rate(tolerance_dps=0.1, stable_for_s=0.2, timeout_s=60.0)

        @step("Hold")
        def hold(self, ctx):
            ctx.sleep(self.hold_s)
            rate = ctx.devices.table.status().rate_dps
            ctx.measure("table_rate_dps", rate)  # unit, doc and limits from the declaration

with its measurements declared up front (a reported name not declared, or in another unit, ends
the run ERROR; one declared and never reported is recorded NOT_MEASURED, when its condition holds):

        measurements = (
            Measurement("table_rate_dps", "deg/s", "mean rate the table reports while held",
                        truth=None, limits=lambda p: (p.rate_dps - 0.5, p.rate_dps + 0.5)),
        )

Records: `span = ctx.record_for(record_s, "label")` lets the bench clock run to the absolute
deadline t_start + record_s (never a sum of relative waits, whose overshoots add up when paced)
and returns the span to keep (`span.keep(t_s)`); a pause inside it is excluded or restarts it as
the class declares (`pause_in_record = "exclude"` or `"restart"`); `recorded_text(label, t_s,
span)` is the log's sentence on what the data hold.  `preflight(devices)` may refuse, before
anything moves, a command above a device's own limit (an FPGA loop's force limit).

An optional analysis hook `analysis(self, data) -> list[Result]` works on recorded data (a
`bench.recorder.RunData`, the same during a run via `ctx.data()` and afterwards from the HDF5
file), so `gyrobench analyze RUN` re-fits a recorded run with the same code.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any, ClassVar

from .demands import Demand
from .measurement import Measurement, MeasurementError, Result
from .params import Param, declared_params, resolve_params

_STEP_ATTR = "_gyrobench_step_title"
_USES_ATTR = "_gyrobench_step_uses"
_SHARES_ATTR = "_gyrobench_step_shares"


def step(title: str | Callable | None = None, *, uses: tuple[str, ...] | None = None, shares: tuple[str, ...] = ()):
    """Mark a method `def name(self, ctx)` as a step; `@step` or `@step("Title")`.  `uses` names the
    device roles the step touches (`("table",)`, `("fpga", "frontend")`, `()` for analysis): with
    several gyros on one table a step that uses only the shared table is a batch step (run once for
    every slot), the others run per slot (bench.engine.batch); None = not said.  `shares` names the
    shared roles (the chamber, the table) a slot step drives only through `ctx.shared` (run once for
    the batch, its result handed to every slot), so a per-unit loop can move the shared chamber."""
    if callable(title):
        setattr(title, _STEP_ATTR, title.__name__.replace("_", " ").capitalize())
        setattr(title, _USES_ATTR, uses)
        setattr(title, _SHARES_ATTR, tuple(shares))
        return title

    def mark(fn: Callable) -> Callable:
        setattr(fn, _STEP_ATTR, title or fn.__name__.replace("_", " ").capitalize())
        setattr(fn, _USES_ATTR, None if uses is None else tuple(uses))
        setattr(fn, _SHARES_ATTR, tuple(shares))
        return fn

    return mark


def step_uses(proc: Any, name: str) -> tuple[str, ...] | None:
    """The device roles step `name` of a procedure (class or instance) declares, None if undeclared."""
    return getattr(getattr(proc, name), _USES_ATTR, None)


def step_shares(proc: Any, name: str) -> tuple[str, ...]:
    """The shared roles step `name` drives through `ctx.shared` only (see `step`)."""
    return getattr(getattr(proc, name), _SHARES_ATTR, ())


def _kebab(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "-", name).lower()


class Procedure:
    """Base class of every procedure.  Subclasses set `name`, declare `Param`s and `@step`s."""

    name: ClassVar[str] = ""
    #: device roles the procedure needs on its station ("table", "frontend", "fpga")
    requires: ClassVar[tuple[str, ...]] = ()
    #: kinds of gyro the procedure is written for (`bench.engine.demands.KINDS`); () = any
    kinds: ClassVar[tuple[str, ...]] = ()
    #: the measurements the procedure reports (their names are its results' stable public names)
    measurements: ClassVar[tuple[Measurement, ...]] = ()
    #: a pause inside a record (`ctx.record_for`): "exclude" cuts the paused span out and runs the
    #: record on by as much, "restart" records again from the resume (bench.engine.recording)
    pause_in_record: ClassVar[str] = "exclude"
    #: parameters whose 0 means "the station's nominal value" (param name: bench.nominal key), e.g.
    #: {"bryan_factor": "bryan_factor"}: a procedure never assumes a unit's K or f0 by default
    nominal_params: ClassVar[dict[str, str]] = {}
    #: whether its steps may call `ctx.compute`: the run then starts the compute workers' forkserver
    #: as it begins (its ~0.8 s of CPU importing numpy, scipy and the estimators, beside the run);
    #: False spares a run that never computes that start (a `ctx.compute` still works, starting it then)
    uses_compute: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not cls.__dict__.get("name"):
            cls.name = _kebab(cls.__name__)

    def __init__(self, params: dict[str, Any] | None = None) -> None:
        self.params: dict[str, Any] = resolve_params(type(self), params)
        #: the nominal parameters left at 0: the product's data-sheet value until a station's is taken
        self._from_nominal = [name for name in self.nominal_params if not self.params.get(name)]
        if self._from_nominal:
            from bench.nominal import nominal_for

            self.take_nominal(nominal_for(self.kinds[0] if self.kinds else ""))

    def take_nominal(self, nominal: dict[str, float]) -> dict[str, float]:
        """Fill each `nominal_params` parameter not given (left at 0) with a nominal value: the
        product's at construction, the station's when the engine runs it (before the run is
        recorded, so its record and `analyze` hold the value used); returns those taken."""
        taken = {}
        for name in getattr(self, "_from_nominal", ()):
            key = self.nominal_params[name]
            if key in nominal:
                self.params[name] = taken[name] = self.param_specs()[name].convert(float(nominal[key]))
        return taken

    def demands(self) -> list[Demand]:
        """What this run will ask of each device (rates, accelerations, amplitudes), from the
        parameters; the engine checks them against the station's limits before the first step."""
        return []

    def preflight(self, devices: Any) -> None:
        """Read-only checks of the parameters against the devices' own limits (an FPGA loop's
        force limit), on an opened station before anything moves: raise
        bench.engine.demands.StationMismatch naming the value and the limit."""

    # --- introspection -------------------------------------------------------------------
    @classmethod
    def param_specs(cls) -> dict[str, Param]:
        return declared_params(cls)

    @classmethod
    def step_specs(cls) -> list[tuple[str, str]]:
        """(method name, title) of every step, base classes first, in the order written."""
        out: dict[str, str] = {}
        for klass in reversed(cls.__mro__):
            for attr, value in vars(klass).items():
                title = getattr(value, _STEP_ATTR, None)
                if title is not None:
                    out[attr] = title
        return list(out.items())

    @classmethod
    def title(cls) -> str:
        doc = (cls.__doc__ or "").strip()
        return doc.splitlines()[0] if doc else cls.name

    @classmethod
    def describe(cls) -> dict[str, Any]:
        return {
            "name": cls.name,
            "title": cls.title(),
            "requires": list(cls.requires),
            "kinds": list(cls.kinds),
            "steps": [s for s, _ in cls.step_specs()],
            "params": [p.describe() for p in cls.param_specs().values()],
            "measurements": [m.describe() for m in cls.measurements],
        }

    # --- declared measurements -------------------------------------------------------------
    @classmethod
    def measurement_specs(cls) -> dict[str, Measurement]:
        """The declared measurements by name."""
        return {m.name: m for m in cls.measurements}

    def resolve_result(self, res: Result) -> Result:
        """A reported Result checked against its declaration (MeasurementError if the name is not
        declared or the unit differs) and completed with the declared unit, doc and default limits."""
        spec = self.measurement_specs().get(res.name)
        if spec is None:
            declared = ", ".join(self.measurement_specs()) or "(none)"
            raise MeasurementError(
                f"measurement {res.name!r} is not declared by procedure {self.name!r} (declared: {declared})"
            )
        return spec.resolve(res, self, self.name)

    def not_measured(self, results: list[Result]) -> list[Result]:
        """A NOT_MEASURED Result for every declared measurement whose condition holds and that
        `results` lacks (for each DUT that reported anything, else for the run)."""
        duts = sorted({r.dut for r in results if r.dut is not None}) or [None]
        have = {(r.dut, r.name) for r in results}
        out = []
        for spec in self.measurements:
            if spec.applies(self):
                out += [spec.not_measured(self, d) for d in duts if (d, spec.name) not in have]
        return out

    @classmethod
    def truth_for(cls, truth: dict[str, float] | None) -> dict[str, float]:
        """The simulator's true value of each declared measurement that has one, by measurement name."""
        out = {}
        for spec in cls.measurements:
            value = spec.truth_of(truth)
            if value is not None:
                out[spec.name] = value
        return out

    @classmethod
    def truth_periods(cls) -> dict[str, float]:
        """The period of each declared periodic measurement (an axis angle's 90 deg), by name: a
        truth is compared with its image nearest the value."""
        return {spec.name: spec.period for spec in cls.measurements if spec.period is not None}

    @classmethod
    def no_interval_reasons(cls) -> dict[str, str]:
        """Why each declared measurement that comes without an interval does, by name."""
        return {spec.name: spec.no_interval for spec in cls.measurements if spec.no_interval}

    @classmethod
    def no_truth_reasons(cls) -> dict[str, str]:
        """Why each declared measurement that a simulator's truth is not compared with is not, by name."""
        return {spec.name: spec.no_truth for spec in cls.measurements if spec.no_truth}

    # --- analysis hook ---------------------------------------------------------------------
    def analysis(self, data: Any) -> list[Result]:
        """Estimate the measurements from recorded data; override to support `analyze`."""
        raise NotImplementedError(f"procedure {self.name!r} has no analysis hook")

    @classmethod
    def has_analysis(cls) -> bool:
        return cls.analysis is not Procedure.analysis
