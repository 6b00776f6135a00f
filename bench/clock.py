"""The bench clock: procedures ask it for time and waits, never `time` directly.

`RealClock` is the wall clock (a real bench).  `SimClock` is the simulated world's clock: in
lockstep mode a wait advances the world by exactly that much virtual time (as fast as the CPU
allows, bit-for-bit reproducible); in real-time mode a thread advances the world at `speed` x
the wall clock and waits block until the world gets there.  Transport timeouts are wall time and
never go through this clock.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """What procedures and drivers may ask of time."""

    def now(self) -> float:
        """Seconds on this clock (virtual seconds on a simulated bench)."""
        ...

    def sleep(self, dt_s: float) -> None: ...

    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        """Poll condition every poll_s (clock time) until true or timeout_s passes; True if met."""
        ...


def _check_dt(dt_s: float) -> float:
    if not math.isfinite(dt_s) or dt_s < 0:
        raise ValueError(f"clock wait dt_s={dt_s!r} must be finite and >= 0")
    return float(dt_s)


def paused_s(clock: Any) -> float:
    """Bench seconds a run has been held paused so far on this clock (the engine's GuardedClock counts
    them: a real-time station's clock runs on while paused); 0 on a clock outside a run."""
    return float(getattr(clock, "paused_s", 0.0))


class Deadline:
    """A timeout in bench time from now that leaves out the time the run is held paused meanwhile:
    a pause longer than a wait's timeout must not end the run at the resume (ctx.wait_until, the
    rate table's waits and a soak's settling use it)."""

    def __init__(self, clock: Any, timeout_s: float) -> None:
        self.clock = clock
        self.end_s = clock.now() + timeout_s
        self._paused0 = paused_s(clock)

    def paused_since_s(self) -> float:
        """Bench seconds paused since the deadline was set."""
        return paused_s(self.clock) - self._paused0

    def remaining_s(self, now_s: float | None = None) -> float:
        """Bench seconds left (<= 0: passed), paused time not counted."""
        return self.end_s + self.paused_since_s() - (self.clock.now() if now_s is None else now_s)

    def paused_note(self) -> str:
        """' (and X s paused, not counted)' for a timeout's message when a pause came in between."""
        paused = self.paused_since_s()
        return f" (and {paused:.1f} s paused, not counted)" if paused > 0 else ""


class _PollingWait:
    def wait_until(self, condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        _check_dt(timeout_s)
        if poll_s <= 0:
            raise ValueError(f"poll_s={poll_s!r} must be > 0")
        deadline = self.now() + timeout_s  # type: ignore[attr-defined]
        while True:
            if condition():
                return True
            remaining = deadline - self.now()  # type: ignore[attr-defined]
            if remaining <= 1e-12:
                return bool(condition())
            self.sleep(min(poll_s, remaining))  # type: ignore[attr-defined]


class RealClock(_PollingWait):
    """Wall-clock time for a real bench."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0

    def sleep(self, dt_s: float) -> None:
        time.sleep(_check_dt(dt_s))


class SimClock(_PollingWait):
    """The World's clock.  speed=math.inf is lockstep (the default); a finite speed runs a thread
    that advances the world at speed x real time.  The speed can change while running (the GUI's
    speed control)."""

    #: the most simulated time one advance of the real-time thread covers, in ticks at the asked
    #: speed (the world lock is held for that advance only)
    MAX_ADVANCE_TICKS = 2.0
    #: the most the real-time thread catches up after a stall, in wall seconds at the asked speed;
    #: beyond it the simulated clock falls behind
    MAX_OWED_WALL_S = 0.25
    #: the least wall time the real-time thread leaves the world lock free between advances
    MIN_PAUSE_S = 0.002

    def __init__(self, world, *, speed: float = math.inf, tick_s: float = 0.01) -> None:
        self.world = world
        self._tick_s = tick_s
        self._cond = threading.Condition()
        self._speed = math.inf
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._thread_error: BaseException | None = None
        self._dropped_s = 0.0
        self._owed_s = 0.0  # simulated s the real-time thread owes the wall clock (<= MAX_OWED_WALL_S x speed)
        self._owed_at = time.monotonic()  # the wall time _owed_s was counted to
        world.add_listener(self._on_world_advanced, each_block=False)  # waits need only know it moved
        self.set_speed(speed)

    # --- speed -----------------------------------------------------------------------------
    @property
    def speed(self) -> float:
        return self._speed

    @property
    def lockstep(self) -> bool:
        return math.isinf(self._speed)

    def set_speed(self, speed: float) -> None:
        """inf = lockstep (as fast as the CPU allows); a finite value > 0 = x real time."""
        if not (speed > 0):
            raise ValueError(f"clock speed={speed!r} must be > 0 (math.inf for lockstep)")
        with self._cond:
            self._speed = float(speed)
            self._cond.notify_all()
        if not self.lockstep and self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run_realtime, name="sim-clock", daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    # --- clock -----------------------------------------------------------------------------
    def now(self) -> float:
        return self.world.t_s

    def sleep(self, dt_s: float) -> None:
        dt_s = _check_dt(dt_s)
        self._raise_thread_error()
        target = self.world.t_s + dt_s
        if self.lockstep:
            self.world.advance(dt_s)
            return
        half_sample = 0.5 * self.world.sample_period_s
        with self._cond:
            while self.world.t_s < target - half_sample and not self._stop.is_set():
                if self.lockstep:  # speed switched to lockstep while waiting
                    break
                self._cond.wait(timeout=0.05)
        self._raise_thread_error()
        if self.lockstep and self.world.t_s < target:
            self.world.advance(max(0.0, target - self.world.t_s))

    def _raise_thread_error(self) -> None:
        """Report, once, that the real-time thread died; the clock is lockstep from then on, so
        the waits of the safe state that follows still advance the world (in the caller)."""
        err, self._thread_error = self._thread_error, None
        if err is not None:
            raise RuntimeError(f"the simulated world stopped advancing in real time: {err!r}") from err

    # --- real-time thread --------------------------------------------------------------------
    def _on_world_advanced(self, _world) -> None:
        with self._cond:
            self._cond.notify_all()

    def _run_realtime(self) -> None:
        try:
            self._advance_in_real_time()
        except BaseException as exc:  # noqa: BLE001 - a dead thread must not leave waits hanging
            with self._cond:
                self._thread_error = exc
                self._speed = math.inf
                self._cond.notify_all()
        finally:
            self._thread = None

    def _advance_in_real_time(self) -> None:
        """Advance the world by what the wall clock owes, two ticks' worth at most at a time,
        releasing the world lock in between: device servers (and so the drivers' wall-clock
        timeouts and the table's watchdog feed) never wait more than about that.  Debt beyond
        MAX_OWED_WALL_S is dropped, not caught up in a burst: on a machine too slow for the asked
        speed the simulated clock falls behind (`achieved_speed` says by how much) instead of a
        link timing out."""
        last = time.monotonic()
        self._owed_s, self._owed_at = 0.0, last
        pause_s = self._tick_s
        while not self._stop.is_set():
            time.sleep(pause_s)  # a tick less the time the last advance took (the lock is free meanwhile)
            now = time.monotonic()
            wall = now - last
            last = now
            if self.lockstep:
                self._owed_s, self._owed_at = 0.0, now
                continue
            owed_s = self._owed_s + wall * self._speed
            cap_s = self.MAX_OWED_WALL_S * self._speed
            if owed_s > cap_s:
                self._dropped_s += owed_s - cap_s
                owed_s = cap_s
            chunk_s = max(self.MAX_ADVANCE_TICKS * self._tick_s * self._speed, self.world.sample_period_s)
            step = math.floor(min(owed_s, chunk_s) / self.world.sample_period_s) * self.world.sample_period_s
            self._owed_s, self._owed_at = owed_s, now  # (_due_s reads them from other threads: s before t)
            if step > 0:
                self.world.advance(step)
                self._owed_s = owed_s - step
            pause_s = max(self.MIN_PAUSE_S, self._tick_s - (time.monotonic() - now))

    @property
    def dropped_s(self) -> float:
        """Simulated seconds the real-time thread could not keep up with (0 when it kept pace)."""
        return self._dropped_s

    def _due_s(self) -> float:
        """The simulated time the wall clock has paid for: the world's time and what the real-time
        thread owes it (at most MAX_OWED_WALL_S at the asked speed; what it dropped is not owed)."""
        if self.lockstep:
            return self.world.t_s
        owed_s = self._owed_s + (time.monotonic() - self._owed_at) * self._speed  # to now (a stalled thread too)
        return self.world.t_s + min(owed_s, self.MAX_OWED_WALL_S * self._speed)

    def mark(self) -> tuple[float, float]:
        """(simulated s due, wall s) now: give it to `achieved_speed` to measure a stretch of a run."""
        return (self._due_s(), time.monotonic())

    def achieved_speed(self, since: tuple[float, float]) -> float:
        """Simulated seconds per wall second since a `mark()` (nan before any wall time passed),
        counted on the time due, not the world's: a stretch that begins with the thread behind
        (a stall it then catches up) is not read faster than asked, nor one ending behind slower
        than it ran; dropped time (a machine that cannot keep up) lowers it."""
        sim_s, wall_s = self._due_s() - since[0], time.monotonic() - since[1]
        return sim_s / wall_s if wall_s > 0 else math.nan


class SlotClock(_PollingWait):
    """One SimClock shared by several slot threads (several gyros on one table).

    Lockstep: a member thread's wait asks for a wake-up time and blocks; the world advances only
    when every member is waiting (a member that is parked -- at a batch step's barrier, or waiting
    for a shared instrument's lock -- or has left does not count), and then only to the earliest
    wake-up asked for.  So the world's advances depend on the simulated times the slots ask for,
    never on thread scheduling: a seeded batch is reproducible bit for bit.  A thread that is not a
    member (the batch's coordinator bringing the table to rest) is a member for its wait.  In real
    time the base clock's waits already let every thread wait on the one world."""

    #: wall seconds a waiting member sleeps between looks at an abort (the guard runs after the wait)
    POLL_WALL_S = 0.05

    def __init__(self, base: SimClock) -> None:
        self.base = base
        self.world = base.world
        self._cond = threading.Condition()
        self._members: dict[int, int | None] = {}  # thread id -> wake-up sample index (None: running)
        self._carry: dict[int, float] = {}  # each member's sub-sample remainder
        self._parked: dict[int, int] = {}

    def __getattr__(self, name: str):  # speed, set_speed, lockstep, mark ... of the SimClock
        return getattr(self.base, name)

    def now(self) -> float:
        return self.base.now()

    def close(self) -> None:
        self.base.close()

    # --- membership -----------------------------------------------------------------------------
    def join(self) -> None:
        """The calling thread is a slot: the world waits for it."""
        with self._cond:
            self._members.setdefault(threading.get_ident(), None)
            self._carry.setdefault(threading.get_ident(), 0.0)

    def leave(self, ident: int | None = None) -> None:
        """The calling thread (or `ident`: a slot that died) no longer holds the world back."""
        ident = threading.get_ident() if ident is None else ident
        with self._cond:
            self._members.pop(ident, None)
            self._carry.pop(ident, None)
            self._parked.pop(ident, None)
            self._cond.notify_all()

    def is_member(self) -> bool:
        return threading.get_ident() in self._members

    def is_waiting(self, ident: int) -> bool:
        """Thread `ident` is a member waiting on the clock now."""
        with self._cond:
            return self._members.get(ident) is not None

    def park(self) -> None:
        """The calling member waits on something other than the clock (a barrier, a lock): the
        world may advance without it until `unpark`."""
        me = threading.get_ident()
        with self._cond:
            if me in self._members:
                self._parked[me] = self._parked.get(me, 0) + 1
                del self._members[me]
                self._cond.notify_all()

    def unpark(self, ident: int | None = None) -> None:
        """The calling thread (or `ident`: the leader of a batch step hands every slot that waited
        for it back to the clock before it waits itself) holds the world back again."""
        me = threading.get_ident() if ident is None else ident
        with self._cond:
            depth = self._parked.get(me, 0)
            if depth:
                if depth == 1:
                    del self._parked[me]
                    self._members[me] = None
                else:
                    self._parked[me] = depth - 1

    # --- waits ----------------------------------------------------------------------------------
    def sleep(self, dt_s: float) -> None:
        dt_s = _check_dt(dt_s)
        if not self.base.lockstep:
            self.base.sleep(dt_s)
            return
        me = threading.get_ident()
        period = self.world.sample_period_s
        with self._cond:
            guest = me not in self._members
            if guest:
                self._members[me] = None
                self._carry[me] = 0.0
            try:
                carry = self._carry[me] + dt_s
                n = int(math.floor(carry / period + 1e-9))
                self._carry[me] = max(0.0, carry - n * period)
                target = self.world.sample_index + n
                self._members[me] = target
                while self.world.sample_index < target:
                    wakes = list(self._members.values())
                    if None not in wakes and min(wakes) > self.world.sample_index:
                        # every member waits: advance to the earliest wake-up asked for
                        self.world.advance_samples(min(wakes) - self.world.sample_index)
                        self._cond.notify_all()
                        continue
                    self._cond.wait(self.POLL_WALL_S)
            finally:
                if guest:
                    self._members.pop(me, None)
                    self._carry.pop(me, None)
                elif me in self._members:
                    self._members[me] = None
                self._cond.notify_all()
