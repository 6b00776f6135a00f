"""Manual control of an idle station, as a session the engine owns like a run.

The operator's actions (table rate and stop, drive on and off, the AGC setpoint, the stream on
and off) are checked in the caller's thread with the checks procedures get (a `Param`'s limits,
the station's limits through `check_demands`), then carried out by the engine's thread inside
one step of the `manual` procedure.  So the runner gives the session what it gives a run: a
store row (procedure "manual") with its outcome, a raw file holding the log of every action, the
`manual_actions` stream (what was commanded after each action) and the streams started, link
checks at every wait, and the safe state however the session ends (the operator ends it, the
safe-state button aborts it, a fault or a lost link makes it ERROR, the window closes).

    session = ManualSession(station)
    thread = threading.Thread(target=runner.run, args=(session.procedure(),)); thread.start()
    session.submit("table_rate", 100.0).wait()      # LimitError / StationMismatch if refused
    session.end()                                   # then the runner's safe state
"""

from __future__ import annotations

import math
import queue
import threading
from dataclasses import dataclass, field
from typing import Any

from bench.streams import Column, StreamSchema, declare
from bench.validation import LimitError, ValidationError, unknown_name

from .demands import Demand, StationMismatch, check_demands
from .params import Param
from .procedure import Procedure, step

#: what each code of the `action` column means
ACTIONS: dict[int, str] = {0: "start", 1: "table_rate", 2: "table_stop", 3: "drive_on", 4: "drive_off",
                           5: "agc_setpoint", 6: "stream_start", 7: "stream_stop"}
ACTION_CODES = {v: k for k, v in ACTIONS.items()}
#: one row per action: what it was, whether it was done, and what stands commanded after it
ACTIONS_STREAM = declare(StreamSchema("manual_actions", "manual", (
    Column("t_s", "s"),
    Column("action", "1", "i8", legend=ACTIONS),
    Column("accepted", "1", "i1", legend={0: "refused", 1: "done"}),
    Column("rate_cmd_dps", "deg/s", doc="table rate commanded after the action"),
    Column("drive_on", "1", "i1", legend={0: "off", 1: "on"}),
    Column("agc_setpoint", "1", doc="AGC amplitude setpoint (amplitude units)"),
    Column("stream_on", "1", "i1", legend={0: "off", 1: "on"}),
)))

#: the values an operator types, checked exactly as a procedure's parameters are (same limits as
#: the procedures that command the same thing: procedures/hrg_excitation.py's amplitude)
RATE = Param(0.0, unit="deg/s", doc="table rate", name="rate_dps")
AGC_SETPOINT = Param(1.0, unit="", low=0.01, high=10.0, doc="AGC amplitude setpoint", name="agc_setpoint")
#: the role each action needs
NEEDS = {"table_rate": "table", "table_stop": "table", "drive_on": "fpga", "drive_off": "fpga",
         "agc_setpoint": "fpga", "stream_start": "fpga", "stream_stop": "fpga"}
POLL_S = 0.05  # bench seconds between looks at the action queue (each wait is an engine checkpoint)
READ_EVERY_S = 0.25  # bench seconds between table readings for the panel


def busy_text(procedure: str, run_id: str, station_id: str) -> str:
    """Why the station cannot take another run or manual session now (one message)."""
    if procedure == ManualControl.name:
        return (f"manual control holds station {station_id!r} (session {run_id}): end it, or press Safe state, "
                "before starting a run")
    return (f"run {run_id} ({procedure}) holds station {station_id!r}: manual control needs an idle station; "
            "wait for the run's end or abort it")


@dataclass
class Action:
    """One operator action; `wait()` returns once the engine has done or refused it."""

    kind: str
    value: float | None = None
    error: str | None = None
    refused: str | None = None  # refused before the engine (a value beyond its limit): only logged and recorded
    done: threading.Event = field(default_factory=threading.Event)

    def wait(self, timeout_s: float = 10.0) -> bool:
        """True once carried out; False if refused (`error` says why) or not taken within timeout_s."""
        if not self.done.wait(timeout_s):
            self.error = self.error or f"not taken by the engine within {timeout_s:g} s"
            return False
        return self.error is None


@dataclass
class ManualState:
    """What stands commanded, and the latest readings (for the panel; read from any thread)."""

    active: bool = False
    rate_cmd_dps: float = 0.0
    drive_on: bool = False
    agc_setpoint: float = 1.0
    stream_on: bool = False
    rate_dps: float | None = None  # the table's own reading
    drive_read: bool | None = None  # the FPGA's own status: drive on
    angle_deg: float | None = None
    t_s: float = 0.0
    run_id: str = ""
    last: str = ""  # the last action's text (or its refusal)


class ManualControl(Procedure):
    """Manual control of an idle station: the operator's actions, each checked and logged."""

    name = "manual"

    def __init__(self, session: ManualSession) -> None:
        super().__init__({})
        self.session = session

    @step("Manual control")
    def control(self, ctx: Any) -> None:
        self.session.serve(ctx)


class ManualSession:
    """The operator's side (check, submit, end, state) and the engine's side (`serve`)."""

    def __init__(self, station: Any) -> None:
        self.station = station
        self.state = ManualState(agc_setpoint=float(AGC_SETPOINT.default))
        self._queue: queue.Queue[Action] = queue.Queue()
        self._end = threading.Event()
        self._lock = threading.Lock()

    def procedure(self) -> ManualControl:
        return ManualControl(self)

    # --- operator's thread ---------------------------------------------------------------------
    def check(self, kind: str, value: Any = None) -> float | None:
        """The value as the action takes it, or ValidationError (LimitError, ParamError,
        StationMismatch) naming the value and the limit; nothing is sent."""
        if kind not in NEEDS:
            raise ValidationError(unknown_name(kind, "not a manual action", NEEDS))
        role = NEEDS[kind]
        if role not in self.station.config.devices:
            raise ValidationError(f"{kind}: station {self.station.id!r} has no {role} device")
        if kind == "table_rate":
            rate = float(RATE.convert(value))
            try:
                check_demands([Demand("table", "max_rate_dps", "rate_dps", rate, "deg/s")], self.station, "manual")
            except StationMismatch as exc:  # the procedures' check, as the limit error a driver gives
                raise LimitError("rate_dps", rate, self.station.limit("table", "max_rate_dps"), "deg/s",
                                 message=str(exc)) from None
            return rate
        if kind == "agc_setpoint":
            return float(AGC_SETPOINT.convert(value))
        return None

    def submit(self, kind: str, value: Any = None) -> Action:
        """Check the action (raises if refused), then queue it for the engine's thread.  A refused
        value during a session still reaches the engine's thread, to be logged and recorded in
        `manual_actions` as refused (nothing is sent to a device)."""
        try:
            checked = self.check(kind, value)
        except ValidationError as exc:
            if kind in ACTION_CODES and self.state.active and not self._end.is_set():
                self._queue.put(Action(kind, None, error=str(exc), refused=f"{kind} {str(value).strip()!r}"))
            raise
        if not self.state.active or self._end.is_set():
            raise ValidationError(f"{kind}: no manual control session is active")
        action = Action(kind, checked)
        self._queue.put(action)
        return action

    def end(self) -> None:
        """End the session: the step returns and the runner brings the station to its safe state."""
        self._end.set()

    # --- engine's thread -------------------------------------------------------------------------
    def serve(self, ctx: Any) -> None:
        """Carry out queued actions until `end()`; every wait is a checkpoint (abort, link checks)."""
        self.state.run_id = ctx.run_id
        fpga = ctx.devices.get("fpga")
        if fpga is not None:
            self.state.agc_setpoint = float(fpga.read_register("AGC_SETPOINT"))
            self.state.stream_on = bool(getattr(fpga, "_streaming", True))
        ctx.log.info("manual control: every action is checked against the station's limits and logged; "
                     "ending the session brings the station to its safe state")
        self._record(ctx, "start", True)
        self.state.active = True
        next_read = -math.inf
        try:
            while not self._end.is_set():
                if ctx.clock.now() >= next_read:
                    self._read(ctx)
                    next_read = ctx.clock.now() + READ_EVERY_S
                try:
                    action = self._queue.get_nowait()
                except queue.Empty:
                    ctx.sleep(POLL_S)
                    continue
                self._apply(ctx, action)
            ctx.log.info("manual control ended by the operator")
        finally:
            self.state.active = False
            self._refuse_pending("the session ended")

    def _read(self, ctx: Any) -> None:
        table = ctx.devices.get("table")
        self.state.t_s = float(ctx.clock.now())
        if table is not None:
            st = table.status()
            self.state.rate_dps, self.state.angle_deg = float(st.rate_dps), float(st.angle_deg)
        fpga = ctx.devices.get("fpga")
        if fpga is not None:
            from drivers.fpga.protocol import ST_DRIVE_ON

            self.state.drive_read = bool(int(fpga.read_register("STATUS")) & ST_DRIVE_ON)

    def _apply(self, ctx: Any, action: Action) -> None:
        if action.refused is not None:  # refused at its field: said in the log and the record, nothing sent
            self.state.last = f"refused: {action.error}"
            ctx.log.warning(f"manual: {action.refused} refused: {action.error}")
            self._record(ctx, action.kind, False)
            action.done.set()
            return
        text = action.kind if action.value is None else f"{action.kind} {action.value:g}"
        try:
            getattr(self, f"_do_{action.kind}")(ctx, action.value)
        except ValueError as exc:  # a limit a driver enforces (LimitError): refused, the session goes on
            action.error = str(exc)
            self.state.last = f"refused: {exc}"
            ctx.log.warning(f"manual: {text} refused: {exc}")
            self._record(ctx, action.kind, False)
            action.done.set()
            return
        except BaseException as exc:  # a fault or a lost link: the runner ends the session (ERROR, safe state)
            action.error = f"{type(exc).__name__}: {exc}"
            action.done.set()
            raise
        self.state.last = text
        ctx.log.info(f"manual: {text}")
        self._record(ctx, action.kind, True)
        self._read(ctx)
        action.done.set()

    def _refuse_pending(self, why: str) -> None:
        while True:
            try:
                action = self._queue.get_nowait()
            except queue.Empty:
                return
            action.error = why
            action.done.set()

    def _record(self, ctx: Any, kind: str, accepted: bool) -> None:
        s = self.state
        ctx.record(ACTIONS_STREAM, ACTIONS_STREAM.names,
                   [[ctx.clock.now(), ACTION_CODES[kind], int(accepted), s.rate_cmd_dps, int(s.drive_on),
                     s.agc_setpoint, int(s.stream_on)]])

    # --- the actions (engine's thread) ---------------------------------------------------------------
    def _do_table_rate(self, ctx: Any, rate_dps: float) -> None:
        table = ctx.devices.table
        if not table.status().enabled:
            table.enable()
        table.set_rate(rate_dps)
        self.state.rate_cmd_dps = rate_dps

    def _do_table_stop(self, ctx: Any, _value: None) -> None:
        ctx.devices.table.stop()
        self.state.rate_cmd_dps = 0.0

    def _do_drive_on(self, ctx: Any, _value: None) -> None:
        """The loops a procedure's excitation starts: PLL, quadrature loop, AGC at the setpoint, drive."""
        fpga = ctx.devices.fpga
        fpga.set_whole_angle(False)
        fpga.set_drift_compensation(False)
        fpga.set_pll(True)
        fpga.set_quadrature_loop(True)
        fpga.set_agc(True, self.state.agc_setpoint)
        fpga.set_drive_enabled(True)
        self.state.drive_on = True

    def _do_drive_off(self, ctx: Any, _value: None) -> None:
        fpga = ctx.devices.fpga
        fpga.set_drive_enabled(False)
        fpga.set_agc(False)
        fpga.set_pll(False)
        self.state.drive_on = False

    def _do_agc_setpoint(self, ctx: Any, setpoint: float) -> None:
        fpga = ctx.devices.fpga
        if self.state.drive_on:
            fpga.set_agc(True, setpoint)
        else:
            fpga.write_register("AGC_SETPOINT", setpoint)
        self.state.agc_setpoint = setpoint

    def _stream(self, ctx: Any) -> tuple[Any, Any, dict[str, Any]]:
        spec = self.station.spec("fpga").stream
        return ctx.devices.fpga, spec, self.station.config.devices["fpga"]

    def _do_stream_start(self, ctx: Any, _value: None) -> None:
        dev, spec, cfg = self._stream(ctx)
        if not self.state.stream_on:
            spec.start(dev, cfg)
        self.state.stream_on = True

    def _do_stream_stop(self, ctx: Any, _value: None) -> None:
        dev, spec, _cfg = self._stream(ctx)
        if self.state.stream_on:
            spec.stop(dev, ctx.clock)
        self.state.stream_on = False
