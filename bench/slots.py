"""Several gyros on one rate table: a batch station (`[slots.N]` in the station file) and the
station each slot's run sees.

The shared devices (`[devices.*]`: the table, and on sim-hrg-4 a front end behind a switch) are
opened once; each slot's own devices (`[slots.N.<role>]`) once per slot.  A slot's run gets a
`SlotStation`: its own devices plus the shared ones, its own link checks and safe state (its
drive cut, its outputs off -- never the shared table, which the batch brings to rest when no slot
needs it).  A shared instrument other than the table is used by one slot at a time under an
engine-owned `SlotLock` with a deadline; the table is driven only by batch steps
(bench.engine.batch).  The table is checked once per check interval for every slot; a table
fault found by any slot ends every slot's run.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from bench.devices import DRIVERS, StationError, close_devices
from bench.engine.context import GuardedClock
from bench.engine.safety import SafeStateReport, by_part
from bench.station import Station
from bench.station_config import StationConfig
from drivers.errors import DeviceError, LinkLostError, SafetyTripError

#: roles only batch steps (or a slot step's `ctx.shared`) drive, run once for every slot: the table
#: they all sit on and the chamber they all sit in (docs/chamber.md, "Several gyros in one chamber")
BATCH_ROLES = frozenset({"table", "chamber"})


class LockBroken(DeviceError):
    """A slot held a shared instrument past the lock's deadline (or its thread died holding it)."""


class SlotLock:
    """An engine-owned lock on a shared instrument: one slot at a time, re-entrant within a slot's
    thread, with a deadline.  A holder whose thread has ended, or that holds it longer than
    `deadline_wall_s`, loses it (`on_break(slot, thread, why)` is told) so the others never
    deadlock.  A waiter calls `check()` while it waits, so an abort still ends it."""

    POLL_WALL_S = 0.02

    def __init__(self, role: str, deadline_wall_s: float = 30.0,
                 on_break: Callable[[int, threading.Thread, str], None] | None = None) -> None:
        self.role = role
        self.deadline_wall_s = float(deadline_wall_s)
        self.on_break = on_break
        self._cond = threading.Condition()
        self.holder: int | None = None
        self._thread: threading.Thread | None = None
        self._since = 0.0
        self._depth = 0
        self.broken: list[str] = []

    def acquire(self, slot: int, *, clock: Any = None, check: Callable[[], None] | None = None) -> bool:
        """Take the lock for `slot`; True when newly taken (False: this thread held it already)."""
        me = threading.current_thread()
        with self._cond:
            if self.holder == slot and self._thread is me:
                self._depth += 1
                return False
        # not parked in the clock: a slot holds the lock for one call, in which no simulated time
        # passes, so the world never needs to advance while a slot waits for it (a seeded batch stays
        # the same whichever slot gets it first).  Only a holder that waits on the clock under the lock
        # (a front end's capture) makes the waiter park, so that the world can advance for the holder.
        parked = False
        try:
            while True:
                with self._cond:
                    if self.holder is None:
                        self.holder, self._thread, self._since, self._depth = slot, me, time.monotonic(), 1
                        return True
                    why = None
                    if self._thread is not None and not self._thread.is_alive():
                        why = "its thread ended while holding it"
                    elif time.monotonic() - self._since > self.deadline_wall_s:
                        why = f"it held it longer than the lock's deadline ({self.deadline_wall_s:g} s wall)"
                    if why is not None:
                        self._break(why)
                        continue
                    holder = self._thread
                    if (not parked and clock is not None and hasattr(clock, "is_waiting") and holder is not None
                            and holder.ident is not None and clock.is_waiting(holder.ident)):
                        clock.park()
                        parked = True
                    self._cond.wait(self.POLL_WALL_S)
                if check is not None:
                    check()
        finally:
            if parked:
                clock.unpark()

    def _break(self, why: str) -> None:
        slot, thread = self.holder, self._thread
        text = f"slot {slot} lost the {self.role} lock: {why}"
        self.broken.append(text)
        self.holder, self._thread, self._depth = None, None, 0
        self._cond.notify_all()
        if self.on_break is not None and slot is not None and thread is not None:
            self.on_break(slot, thread, text)

    def release(self, slot: int) -> None:
        """Give the lock back (a no-op when it was taken from this slot after its deadline)."""
        with self._cond:
            if self.holder == slot and self._thread is threading.current_thread():
                self._depth -= 1
                if self._depth <= 0:
                    self.holder, self._thread, self._depth = None, None, 0
                    self._cond.notify_all()

    def held_by(self, slot: int) -> bool:
        return self.holder == slot and self._thread is threading.current_thread()


class Serialized:
    """A shared driver used from several slot threads: one call at a time."""

    def __init__(self, device: Any) -> None:
        self._device = device
        self._lock = threading.RLock()

    def __getattr__(self, name: str) -> Any:
        with self._lock:
            value = getattr(self._device, name)
        if not callable(value):
            return value

        def call(*args: Any, **kw: Any) -> Any:
            with self._lock:
                return value(*args, **kw)

        return call


class SlotShare:
    """A slot's handle on a shared instrument: every use (a call: switch + command) takes the
    instrument's SlotLock for the slot and switches the instrument to it (`select_slot`); `using()`
    holds it over several calls.  No clock wait happens under the lock in a call, so no simulated
    time passes while a slot holds it: which slot gets it first cannot change a seeded batch."""

    def __init__(self, batch: BatchStation, role: str, slot: int) -> None:
        self._batch, self._role, self._slot = batch, role, slot

    @contextlib.contextmanager
    def using(self, check: Callable[[], None] | None = None) -> Iterator[Any]:
        lock = self._batch.locks[self._role]
        device = self._batch.shared[self._role]
        fresh = lock.acquire(self._slot, clock=self._batch.base_clock, check=check)
        try:
            if fresh and hasattr(device, "select_slot"):
                device.select_slot(self._slot)
            yield device
        finally:
            lock.release(self._slot)

    def __setattr__(self, name: str, value: Any) -> None:
        if name.startswith("_"):
            object.__setattr__(self, name, value)
            return
        with self.using() as device:  # a driver property (fe.lockin_tc_s = ...): set on the instrument
            setattr(device, name, value)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        with self.using() as device:
            value = getattr(device, name)
        if not callable(value):
            return value

        def call(*args: Any, **kw: Any) -> Any:
            with self.using():
                return value(*args, **kw)

        return call


class BatchStation:
    """N slots on one table: the shared devices, each slot's devices, the locks and the shared
    checks.  `slot(n)` is the station slot n's run uses."""

    #: wall seconds a slot may hold a shared instrument before the lock is taken from it
    LOCK_DEADLINE_WALL_S = 30.0

    def __init__(self, config: StationConfig) -> None:
        if not config.slots:
            raise StationError(f"{config.source}: no [slots.N] tables: not a several-gyros station")
        self.config = config
        self.id = config.id
        self.simulated = config.simulation is not None
        self.base_clock = self._make_clock()
        self.table_clock = GuardedClock(self.base_clock)  # guarded by the runner of the batch step's leader
        self.shared: dict[str, Any] = {}
        self.locks: dict[str, SlotLock] = {
            role: SlotLock(role, self.LOCK_DEADLINE_WALL_S, self._lock_broken)
            for role in config.devices if role not in BATCH_ROLES}
        self.slots = {n: SlotStation(self, n) for n in sorted(config.slots)}
        self.table_fault: BaseException | None = None
        self.lost_locks: dict[int, str] = {}  # slot -> why it lost a shared instrument's lock
        self._check_lock = threading.Lock()
        self._last_shared_check = -math.inf
        self._on_lock_broken: Callable[[int, threading.Thread, str], None] | None = None

    def _make_clock(self) -> Any:
        from bench.clock import RealClock

        return RealClock()

    @property
    def n_slots(self) -> int:
        return len(self.slots)

    def slot(self, n: int) -> SlotStation:
        if n not in self.slots:
            raise StationError(f"station {self.id!r} has slots {sorted(self.slots)}, not {n}")
        return self.slots[n]

    @property
    def kind(self) -> str:
        return self.slots[min(self.slots)].kind

    @property
    def results_url(self) -> str:
        return self.config.station["results"]

    @property
    def runs_dir(self) -> str:
        return self.config.station["runs_dir"]

    def spec(self, role: str) -> Any:
        return DRIVERS[self.config.devices[role]["driver"]]

    # --- lifecycle ------------------------------------------------------------------------------
    def _device_cfg(self, slot: int | None, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return cfg

    def open(self) -> BatchStation:
        if self.shared:
            return self
        try:
            for role, cfg in self.config.devices.items():
                dev = self.spec(role).build(self._device_cfg(None, role, cfg), self.table_clock)
                self.shared[role] = Serialized(dev)
            for st in self.slots.values():
                st.open_slot()
        except Exception:
            self.close()
            raise
        return self

    def close(self) -> None:
        for st in self.slots.values():
            st.close()
        close_devices(self.shared)

    def __enter__(self) -> BatchStation:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def describe(self) -> dict[str, Any]:
        return {"id": self.id, "source": self.config.source, "simulated": self.simulated,
                "simulation": self.config.simulation, "devices": self.config.devices,
                "slots": {str(n): d for n, d in self.config.slots.items()}, "keys": self.config.station}

    def truth(self, slot: int) -> dict[str, float] | None:
        return None

    # --- shared checks ------------------------------------------------------------------------
    def check_shared(self, ctx: Any) -> None:
        """The table (and a shared front end) asked for a sign of life once per check interval for
        every slot; the table's rows go into every slot's run that asks within it.  A fault is kept:
        every slot's next check raises it."""
        if self.table_fault is not None:
            raise self.table_fault
        now = self.base_clock.now()
        with self._check_lock:
            if self.table_fault is not None:
                raise self.table_fault
            grid = GuardedClock.LOCKSTEP_GRID_S if getattr(self.base_clock, "lockstep", False) else 0.35
            last = self._last_shared_check
            if last > -math.inf and math.floor(now / grid + 1e-9) <= math.floor(last / grid + 1e-9):
                return
            self._last_shared_check = now
            for role in self.config.devices:
                spec = self.spec(role)
                if spec.health is None:
                    continue
                try:
                    rows = spec.health(self.shared[role])
                except (SafetyTripError, LinkLostError, DeviceError, OSError) as exc:
                    self.table_fault = exc if isinstance(exc, (SafetyTripError, LinkLostError)) else \
                        LinkLostError(f"{role}: {exc}")
                    raise self.table_fault from None
                if spec.health_columns and rows is not None and ctx is not None:
                    import numpy as np

                    ctx.record(role, ("t_s", *spec.health_columns), np.column_stack([[now], rows]))

    def table_to_rest(self) -> SafeStateReport:
        """The shared table to rest and the shared chamber to ambient (their specs' safe states, in
        the safe state's order), once no slot needs them, each confirmed by read-back."""
        report = SafeStateReport(confirmed=True)
        plan = by_part({r: self.spec(r).part for r in self.config.devices if r in BATCH_ROLES})
        for role in (r for _, roles in plan for r in roles):  # the table to rest, then the chamber to ambient
            report.order.append(role)
            try:
                ok = bool(self.spec(role).safe_state(self.shared[role]))
            except Exception as exc:  # noqa: BLE001 - report, never raise
                ok = False
                report.errors[role] = f"{type(exc).__name__}: {exc}"
            report.devices[role] = ok
            report.confirmed = report.confirmed and ok
        return report

    def _lock_broken(self, slot: int, thread: threading.Thread, why: str) -> None:
        self.lost_locks[slot] = why
        if self._on_lock_broken is not None:
            self._on_lock_broken(slot, thread, why)


class SlotStation(Station):
    """What one slot's run sees: its own devices plus the shared ones (a locked instrument through
    `SlotShare`), its own checks, truth and safe state (never the shared table's)."""

    def __init__(self, batch: BatchStation, n: int) -> None:
        self.batch, self.slot_number = batch, n
        bc = batch.config
        station = {**bc.station, "id": f"{bc.id}/slot{n}"}
        super().__init__(StationConfig(bc.source, station, bc.simulation, {**bc.devices, **bc.slots[n]},
                                       nominal=bc.nominal))
        self.own_roles = list(bc.slots[n])
        self.simulated = batch.simulated

    def _make_clock(self) -> Any:
        return self.batch.base_clock

    @property
    def seed(self) -> int | None:
        return self.batch.slot_seed(self.slot_number) if hasattr(self.batch, "slot_seed") else None

    def open_slot(self) -> None:
        """Connect this slot's own devices and hand it the shared ones."""
        for role in self.own_roles:
            cfg = self.config.devices[role]
            self.devices[role] = self.spec(role).build(self.batch._device_cfg(self.slot_number, role, cfg), self.clock)
        for role in self.batch.config.devices:
            self.devices[role] = (SlotShare(self.batch, role, self.slot_number) if role in self.batch.locks
                                  else self.batch.shared[role])

    def open(self) -> SlotStation:
        if not self.devices:
            self.batch.open()
        return self

    def close(self) -> None:
        close_devices(self.devices, list(self.own_roles))  # the shared ones are the batch's to close

    def _own_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return self.batch._device_cfg(self.slot_number if role in self.own_roles else None, role, cfg)

    def _device_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return self._own_cfg(role, cfg)

    def safe_state_plan(self) -> list[tuple[str, list[str]]]:
        """This slot's part of the safe state: its drive cut and its outputs off (a shared front end
        under its lock, switched to this slot); the shared table is the batch's."""
        return by_part({role: self.spec(role).part for role in self.devices if role not in BATCH_ROLES})

    def _note_safe_state_retry(self, role: str, ok: bool, attempts: int, failed: list[str]) -> None:
        super()._note_safe_state_retry(f"slot {self.slot_number} {role}", ok, attempts, failed)

    def _health_roles(self) -> list[str]:
        return [r for r in self._ordered_roles() if r in self.own_roles]

    def _reconnect(self, role: str) -> None:
        if role not in self.own_roles:
            raise LinkLostError(f"{role} is shared by the slots: not reconnected by slot {self.slot_number}")
        super()._reconnect(role)

    def check_links(self) -> None:
        lost = self.batch.lost_locks.get(self.slot_number)
        if lost:
            raise LockBroken(lost)
        self.batch.check_shared(self._ctx)
        super().check_links()

    def truth(self) -> dict[str, float] | None:
        return self.batch.truth(self.slot_number)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["slot"] = self.slot_number
        d["batch_station"] = self.batch.id
        d["slots"] = self.batch.n_slots
        return d

    def start_streams(self, ctx: Any) -> Callable[[], None]:
        stop = super().start_streams(ctx)
        self._ctx = ctx
        return stop
