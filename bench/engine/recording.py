"""Records of the length asked: one loop for every procedure's "record for record_s seconds".

A record runs to an absolute deadline on the bench clock (t_end = t_start + record_s), never as a
sum of relative waits whose overshoots add up (at 100x a 900 s record made of 90 waits of 10 s
lasted up to 982 s).  A pause inside a record is handled as the procedure declares
(`Procedure.pause_in_record`): "exclude" cuts the paused span out of the record and lengthens it
by as much, so it still holds record_s of unpaused data; "restart" starts the record again after
the pause.  Either way the log says so, and the span (`RecordSpan.keep`) is what a fit may take.
The length a record holds is stated from its data (`recorded_length_s`), not from what was asked.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: what a pause inside a record does (Procedure.pause_in_record)
EXCLUDE, RESTART = "exclude", "restart"
PAUSE_POLICIES = (EXCLUDE, RESTART)
#: the level of the log rows (and raw-file log rows) that mark a pause and a resume
PAUSE_LEVEL = "PAUSE"


@dataclass(frozen=True)
class RecordSpan:
    """A record's window (t_start_s, t_end_s] on the bench clock, less the paused spans it excludes."""

    t_start_s: float
    t_end_s: float
    excluded: tuple[tuple[float, float], ...] = ()
    restarts: int = 0
    asked_s: float = math.nan
    label: str = ""

    def keep(self, t_s: np.ndarray) -> np.ndarray:
        """Boolean mask of the times that belong to the record: after t_start, up to t_end, outside
        every excluded span."""
        t = np.asarray(t_s, dtype=float)
        mask = (t > self.t_start_s) & (t <= self.t_end_s)
        return mask & ~in_spans(t, self.excluded)

    @property
    def excluded_s(self) -> float:
        return float(sum(b - a for a, b in self.excluded))


def in_spans(t_s: np.ndarray, spans: Sequence[tuple[float, float]]) -> np.ndarray:
    """Boolean mask of the times inside any span (a, b] (a pause: the sample at its start was taken
    before it, the one at its resume while it lasted), so a span excludes (b - a) / dt samples."""
    t = np.asarray(t_s, dtype=float)
    out = np.zeros(t.shape, dtype=bool)
    for a, b in spans:
        if b > a:
            out |= (t > a) & (t <= b)
    return out


def recorded_length_s(t_s: np.ndarray) -> tuple[float, int, float]:
    """(length, samples, sample period) of a record from its sample times: samples x period, the
    period the median spacing (so a record of n samples every dt holds n dt seconds)."""
    t = np.asarray(t_s, dtype=float)
    if len(t) < 2:
        return 0.0, len(t), math.nan
    period = float(np.median(np.diff(t)))
    return len(t) * period, len(t), period


def recorded_text(label: str, t_s: np.ndarray, span: RecordSpan | None = None, asked_s: float | None = None) -> str:
    """The log's sentence on a record, from its data: samples, first and last time, length held."""
    length, n, period = recorded_length_s(t_s)
    asked = asked_s if asked_s is not None else (None if span is None else span.asked_s)
    if n == 0:
        return f"{label}: no samples recorded" + (f" ({asked:g} s asked)" if asked is not None else "")
    t = np.asarray(t_s, dtype=float)
    text = (f"{label}: recorded {n} samples at {1.0 / period:.6g} Hz, t = {t[0]:.3f} .. {t[-1]:.3f} s, "
            f"{length:.3f} s of data" if n > 1 else f"{label}: recorded 1 sample at t = {t[0]:.3f} s")
    if asked is not None and math.isfinite(asked):
        text += f" ({asked:g} s asked)"
    if span is not None and span.excluded:
        text += f"; {span.excluded_s:.3f} s paused inside the record excluded"
    if span is not None and span.restarts:
        text += f"; restarted {span.restarts}x after a pause"
    return text


@dataclass
class PauseLog:
    """The run's pauses as the engine saw them: (bench time paused, bench time resumed)."""

    spans: list[tuple[float, float]] = field(default_factory=list)

    def since(self, n: int) -> list[tuple[float, float]]:
        return self.spans[n:]


def clock_tolerance_s(clock: Any) -> float:
    """How near a deadline a clock can land: half a sample on a simulated one (it moves in whole
    samples), 1 ns otherwise."""
    return 0.5 * float(getattr(getattr(clock, "world", None), "sample_period_s", 0.0) or 0.0) or 1e-9


def sleep_until(clock: Any, t_abs_s: float) -> float:
    """Wait on the bench clock until the absolute time t_abs_s (within `clock_tolerance_s`); the
    clock's time then.  Waits aimed at one deadline do not add up their overshoots."""
    tol_s = clock_tolerance_s(clock)
    while (left := t_abs_s - clock.now()) > tol_s:
        clock.sleep(left)
    return clock.now()


def window_end(clock: Any, t_end_s: float) -> float:
    """A record's end after waiting for its deadline t_end_s: the deadline, or the clock's own
    time when it is on it (within `clock_tolerance_s`: lockstep lands on the sample)."""
    now = clock.now()
    return now if abs(now - t_end_s) <= clock_tolerance_s(clock) else float(t_end_s)


def record_for(ctx: Any, record_s: float, label: str = "record", *, progress_every_s: float = 10.0,
               policy: str | None = None, progress: Callable[[float, str], None] | None = None) -> RecordSpan:
    """Let the bench clock run record_s seconds from now, to an absolute deadline, in equal waits
    of at most progress_every_s (progress between them; pause and abort within); a pause inside
    is excluded or restarts the record (policy; default the procedure's `pause_in_record`);
    progress(fraction, text) is told between waits (default ctx.progress).  Returns the span."""
    if not (record_s > 0 and math.isfinite(record_s)):
        raise ValueError(f"record_s={record_s!r} must be finite and > 0")
    proc = getattr(ctx, "procedure", None)
    policy = policy or getattr(proc, "pause_in_record", EXCLUDE)
    if policy not in PAUSE_POLICIES:
        raise ValueError(f"pause_in_record={policy!r} is not one of {PAUSE_POLICIES}")
    clock = ctx.clock
    report = progress or ctx.progress
    seen = len(ctx.pauses.spans)
    tol_s = clock_tolerance_s(clock)  # a simulated clock moves in whole samples
    t_start = clock.now()
    t_end = t_start + float(record_s)
    excluded: list[tuple[float, float]] = []
    restarts = 0
    while True:
        now = clock.now()
        left = t_end - now
        if left <= tol_s:
            if abs(left) <= tol_s:  # on the deadline (lockstep): the clock's own time of that sample
                t_end = now
            break
        # the next of n equal marks from the start (n = ceil(record_s / progress_every_s)), absolute
        piece = float(record_s) / max(1, math.ceil(float(record_s) / progress_every_s - 1e-9))
        mark = t_start + (math.floor((now - t_start) / piece + 1e-9) + 1) * piece
        clock.sleep(max(0.0, min(t_end, mark) - now))
        for a, b in ctx.pauses.since(seen):
            seen += 1
            if b < t_start:
                continue
            if policy == RESTART:
                restarts += 1
                t_start = b  # the data from the resume on are whole
                t_end = t_start + float(record_s)
                excluded.clear()
                ctx.log.warning(f"{label}: paused inside the record (t = {a:.3f} .. {b:.3f} s): the record "
                                f"restarts at t = {t_start:.3f} s for {record_s:g} s")
            else:
                a = max(a, t_start)
                excluded.append((a, b))
                t_end += b - a
                ctx.log.warning(f"{label}: paused inside the record (t = {a:.3f} .. {b:.3f} s, {b - a:.3f} s): "
                                f"that span is excluded and the record runs on to t = {t_end:.3f} s")
        held = min(clock.now(), t_end) - t_start - sum(b - a for a, b in excluded)
        report(min(held / record_s, 1.0), f"{label}: {held:.0f} / {record_s:g} s")
    return RecordSpan(t_start, t_end, tuple(excluded), restarts, float(record_s), label)
