"""The rate-table interface procedures use (no transport in it), with the waits and the safe
state written once on top of `status()` so every table model behaves the same."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

from bench.clock import Deadline
from bench.streams import Column, StreamSchema, declare
from bench.validation import check_limit
from drivers.errors import DeviceError, LinkLostError, SafetyTripError

#: the table's readings a station records during a run
TABLE_STREAM = declare(StreamSchema("table", "table", (
    Column("t_s", "s", quantity="time t"), Column("rate_dps", "deg/s", quantity="table rate Ω"),
    Column("angle_deg", "deg", quantity="table angle"))))
#: |rate| below which the table counts as at rest (deg/s): safe_state and stop confirmations.
REST_RATE_DPS = 0.05
#: bench-clock period of the polls inside the waits (s): 10 ms of virtual time per poll.
DEFAULT_POLL_S = 0.01


def angle_error_deg(angle_deg: float, target_deg: float) -> float:
    """angle - target folded into [-180, 180): the table reports angles in [0, 360)."""
    return (angle_deg - target_deg + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class TableLimits:
    """Station-file limits, checked before anything is written to the table."""

    max_rate_dps: float
    max_accel_dps2: float

    def __post_init__(self) -> None:
        check_limit("max_rate_dps", self.max_rate_dps, low=0.0, low_open=True, unit="deg/s")
        check_limit("max_accel_dps2", self.max_accel_dps2, low=0.0, low_open=True, unit="deg/s^2")


@dataclass(frozen=True)
class TableStatus:
    """Actual rate, angle and status bits, taken in one read."""

    rate_dps: float
    angle_deg: float
    enabled: bool
    at_rate: bool
    in_position: bool
    fault: bool
    estop: bool
    interlock_open: bool
    watchdog_expired: bool
    fault_code: int

    @property
    def tripped(self) -> bool:
        """True when the table stopped (or is stopping) itself for safety."""
        return self.fault or self.estop or self.interlock_open or self.watchdog_expired

    def trip_reason(self) -> str:
        names = [n for n in ("estop", "fault", "interlock_open", "watchdog_expired") if getattr(self, n)]
        return ", ".join(names) + f" (fault_code={self.fault_code})"


class RateTable(ABC):
    """A single-axis rate table: rate and position modes, enable, stop, status, safe state.

    Subclasses implement the transport (`connect`, `close`, `enable`, `disable`, `_write_rate`,
    `_write_move`, `_write_stop`, `status`); limits are checked here before they are called.
    Waits run on the bench clock (virtual time on a simulated bench); I/O timeouts are wall time.
    """

    limits: TableLimits

    def __init__(self, *, limits: TableLimits, clock, poll_s: float = DEFAULT_POLL_S) -> None:
        self.limits = limits
        self.clock = clock
        self.poll_s = poll_s
        self.commanded_rate_dps = 0.0
        self.commanded_angle_deg: float | None = None

    # --- transport, per model --------------------------------------------------------------
    @abstractmethod
    def connect(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

    @abstractmethod
    def enable(self) -> None: ...

    @abstractmethod
    def disable(self) -> None: ...

    @abstractmethod
    def status(self) -> TableStatus:
        """Rate, angle and status bits in ONE read."""

    @abstractmethod
    def fault_reset(self) -> None:
        """Clear latched faults (e-stop, fault, watchdog) whose cause is gone."""

    @abstractmethod
    def _write_rate(self, rate_dps: float, accel_dps2: float) -> None: ...

    @abstractmethod
    def _write_move(self, angle_deg: float, rate_dps: float, accel_dps2: float) -> None: ...

    @abstractmethod
    def _write_stop(self, accel_dps2: float) -> None: ...

    # --- checked commands --------------------------------------------------------------------
    def _check_accel(self, accel_dps2: float | None) -> float:
        if accel_dps2 is None:
            return self.limits.max_accel_dps2
        return check_limit("accel_dps2", accel_dps2, low=0.0, low_open=True, high=self.limits.max_accel_dps2,
                           unit="deg/s^2")

    def _check_rate(self, rate_dps: float, *, name: str = "rate_dps") -> float:
        lim = self.limits.max_rate_dps
        return check_limit(name, rate_dps, low=-lim, high=lim, unit="deg/s")

    def set_rate(self, rate_dps: float, accel_dps2: float | None = None) -> None:
        """Rate mode: ramp to rate_dps at accel_dps2 (default: the station's max acceleration)."""
        rate = self._check_rate(rate_dps)
        accel = self._check_accel(accel_dps2)
        self._write_rate(rate, accel)
        self.commanded_rate_dps = rate
        self.commanded_angle_deg = None

    def move_to(self, angle_deg: float, rate_dps: float | None = None, accel_dps2: float | None = None) -> None:
        """Position mode: move (shortest way) to angle_deg in [0, 360) at most at rate_dps, ramping at accel_dps2."""
        angle_deg = check_limit("angle_deg", angle_deg, low=0.0, high=360.0, high_open=True, unit="deg")
        speed = self.limits.max_rate_dps if rate_dps is None else rate_dps
        speed = check_limit("rate_dps", speed, low=0.0, low_open=True, high=self.limits.max_rate_dps, unit="deg/s")
        accel = self._check_accel(accel_dps2)
        self._write_move(float(angle_deg), float(speed), accel)
        self.commanded_rate_dps = 0.0
        self.commanded_angle_deg = float(angle_deg)

    def stop(self, accel_dps2: float | None = None) -> None:
        """Decelerate to rest at accel_dps2 (default: the station's max acceleration)."""
        self._write_stop(self._check_accel(accel_dps2))
        self.commanded_rate_dps = 0.0
        self.commanded_angle_deg = None

    # --- waits on the bench clock ---------------------------------------------------------
    def poll_status(self) -> TableStatus:
        """status() for the waits' polls (every few simulated ms while a wait lasts): a model may
        read the same status a cheaper way (the Modbus table: `probe_status`)."""
        return self.status()

    def _checked_status(self) -> TableStatus:
        st = self.poll_status()
        if st.tripped:
            raise SafetyTripError(f"rate table tripped: {st.trip_reason()}, rate={st.rate_dps:.3f} deg/s")
        return st

    def wait_at_rate(self, tolerance_dps: float, stable_for_s: float, timeout_s: float) -> TableStatus:
        """Wait (bench clock) until |rate - commanded| <= tolerance_dps holds for stable_for_s.
        Raises SafetyTripError on a trip bit, TimeoutError after timeout_s."""
        if not (tolerance_dps > 0 and stable_for_s >= 0 and timeout_s >= 0):
            raise ValueError(f"wait_at_rate({tolerance_dps!r}, {stable_for_s!r}, {timeout_s!r}): bad arguments")
        deadline = Deadline(self.clock, timeout_s)
        since: float | None = None
        while True:
            st = self._checked_status()
            now = self.clock.now()
            if abs(st.rate_dps - self.commanded_rate_dps) <= tolerance_dps:
                since = now if since is None else since
                if now - since >= stable_for_s - 1e-9:
                    return st
            else:
                since = None
            remaining = deadline.remaining_s(now)
            if remaining <= 0:
                raise TimeoutError(
                    f"table not at {self.commanded_rate_dps} +/- {tolerance_dps} deg/s for {stable_for_s} s "
                    f"within {timeout_s} s{deadline.paused_note()} (rate={st.rate_dps:.4f} deg/s)"
                )
            self.clock.sleep(min(self.poll_s, remaining) or self.poll_s)

    def wait_in_position(self, tolerance_deg: float, timeout_s: float) -> TableStatus:
        """Wait (bench clock) for the in-position bit and |angle - target| <= tolerance_deg."""
        if self.commanded_angle_deg is None:
            raise DeviceError("wait_in_position without a move_to")
        if not (tolerance_deg > 0 and timeout_s >= 0):
            raise ValueError(f"wait_in_position({tolerance_deg!r}, {timeout_s!r}): bad arguments")
        deadline = Deadline(self.clock, timeout_s)
        while True:
            st = self._checked_status()
            if st.in_position and abs(angle_error_deg(st.angle_deg, self.commanded_angle_deg)) <= tolerance_deg:
                return st
            now = self.clock.now()
            remaining = deadline.remaining_s(now)
            if remaining <= 0:
                raise TimeoutError(
                    f"table not at {self.commanded_angle_deg} +/- {tolerance_deg} deg within {timeout_s} s"
                    f"{deadline.paused_note()} (angle={st.angle_deg:.4f} deg)"
                )
            self.clock.sleep(min(self.poll_s, remaining) or self.poll_s)

    def wait_at_rest(self, timeout_s: float, rest_dps: float = REST_RATE_DPS) -> TableStatus | None:
        """Wait (bench clock) until |rate| <= rest_dps, ignoring trip bits; None on timeout."""
        deadline = self.clock.now() + timeout_s
        while True:
            st = self.poll_status()
            if abs(st.rate_dps) <= rest_dps:
                return st
            now = self.clock.now()
            if now >= deadline:
                return None
            self.clock.sleep(min(self.poll_s, max(deadline - now, 0.0)) or self.poll_s)

    # --- safety ---------------------------------------------------------------------------
    def safe_state(self, timeout_s: float | None = None) -> bool:
        """Decelerate to rest within the acceleration limit, then disable; True only when a
        read-back confirms rest and drive disabled.  Never raises for device trouble."""
        try:
            st = self.status()
            if timeout_s is None:  # the time a full-limit ramp-down needs, doubled, plus margin
                timeout_s = 2.0 * abs(st.rate_dps) / self.limits.max_accel_dps2 + 5.0
            try:
                self.stop()
            except DeviceError:  # refused (e-stopped, faulted): the table brakes by itself
                pass
            if self.wait_at_rest(timeout_s) is None:
                return False  # still turning: left enabled and commanded to stop, under control
            self.disable()
            st = self.status()
            return (not st.enabled) and abs(st.rate_dps) <= REST_RATE_DPS
        except (DeviceError, LinkLostError, OSError, TimeoutError):
            return False

    def __enter__(self) -> RateTable:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()
