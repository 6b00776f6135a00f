"""Events the engine emits while a run goes on.  The CLI, the GUI and the recorder consume the
same stream; the production line (several gyros on one table) will add a `dut` to measurements,
which is why every event carries the run id and measurements carry an optional DUT id.

Events are frozen dataclasses; `EventBus.publish` calls every subscriber synchronously in the
publishing (engine) thread, so a GUI must hop to its own thread (Qt queued signal) itself.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Event:
    run_id: str
    t_sim_s: float  # bench-clock time (virtual on a simulated station)
    t_wall: float = field(default_factory=time.time)  # epoch seconds


@dataclass(frozen=True)
class RunStarted(Event):
    procedure: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    station: str = ""
    simulated: bool = False
    steps: tuple[str, ...] = ()


@dataclass(frozen=True)
class StepStarted(Event):
    name: str = ""
    index: int = 0
    total: int = 0
    title: str = ""


@dataclass(frozen=True)
class StepFinished(Event):
    name: str = ""
    index: int = 0
    status: str = "done"  # done | error | aborted | skipped


@dataclass(frozen=True)
class Progress(Event):
    fraction: float = 0.0  # of the current step, 0..1
    message: str = ""


@dataclass(frozen=True)
class StreamDeclared(Event):
    """A stream's schema (bench.streams.StreamSchema), announced once a run before the
    stream's first block: its source and each column's name, unit, type and legend."""

    schema: Any = None


@dataclass(frozen=True)
class SampleBlock(Event):
    """A block of rows of one named stream, e.g. stream "fpga" with columns
    (t_s, cx, sx, cy, sy, ...), "table" with (t_s, rate_dps, angle_deg), "sweep" with
    (freq_hz, amplitude, phase_deg, ...).  data has shape (n, len(columns))."""

    stream: str = ""
    columns: tuple[str, ...] = ()
    data: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))


@dataclass(frozen=True)
class Measurement(Event):
    name: str = ""
    value: float = float("nan")
    unit: str = ""
    ci95: tuple[float, float] | None = None
    low: float | None = None
    high: float | None = None
    outcome: str = "COMPLETE"  # PASS | FAIL | MARGINAL | COMPLETE (no limits)
    dut: str | None = None
    marginal_low: float | None = None  # the marginal band inside [low, high], when declared
    marginal_high: float | None = None


@dataclass(frozen=True)
class FitUpdate(Event):
    """A model curve to draw over the data (e.g. the E(t) fit), arrays keyed by name."""

    name: str = ""
    curves: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class Log(Event):
    level: str = "INFO"
    message: str = ""


@dataclass(frozen=True)
class Paused(Log):
    """The run held at a checkpoint (the operator paused it); a log row of level PAUSE, so the
    window, the CLI and the raw file's log all show it.  The bench clock may go on meanwhile
    (real time): a record that spans it excludes it or restarts (bench.engine.recording)."""

    level: str = "PAUSE"
    message: str = "paused"


@dataclass(frozen=True)
class Resumed(Log):
    """The run went on after a pause; paused_from_s is the bench time the pause began."""

    level: str = "PAUSE"
    message: str = "resumed"
    paused_from_s: float = float("nan")


@dataclass(frozen=True)
class StationStatus(Event):
    """Device summary for the station panel: {device: {key: value}}."""

    devices: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass(frozen=True)
class RunFinished(Event):
    outcome: str = "COMPLETE"  # PASS | FAIL | MARGINAL | COMPLETE | ERROR | ABORTED
    end_reason: str = ""
    safe_state: bool = False  # true only when confirmed by read-back
    raw_file: str | None = None


Subscriber = Callable[[Event], None]


class EventBus:
    """Synchronous publish/subscribe.  A subscriber that raises is logged and kept out of the
    engine's way: a broken plot must never stop a calibration or its safe state.  (The recorder
    is fed through bench.writer, whose failures reach the runner by their own path.)"""

    def __init__(self) -> None:
        self._subs: list[Subscriber] = []
        self._lock = threading.Lock()
        self.errors: list[tuple[Subscriber, BaseException]] = []

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        with self._lock:
            self._subs.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subs:
                    self._subs.remove(callback)

        return unsubscribe

    def publish(self, event: Event) -> None:
        with self._lock:
            subs = list(self._subs)
        for cb in subs:
            try:
                cb(event)
            except Exception as exc:  # noqa: BLE001 - isolation is the point
                if len(self.errors) < 1000:  # the first ones tell the story; keep memory bounded
                    self.errors.append((cb, exc))
