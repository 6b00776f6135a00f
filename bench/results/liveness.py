"""Whether a RUNNING row still belongs to a live run: its heartbeat (wall time, refreshed by a
daemon thread of the run) and, on the run's own host, its process."""

from __future__ import annotations

import datetime as _dt
import os
import socket
import threading
from collections.abc import Callable

HEARTBEAT_S = 5.0  # how often a run refreshes its row's heartbeat
STALE_S = 60.0  # a heartbeat older than this: the run is gone (whatever host it ran on)


def host_name() -> str:
    return socket.gethostname()


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat()


def age_s(iso: str | None, now: _dt.datetime | None = None) -> float:
    """Seconds since an ISO 8601 time (inf if missing or unreadable)."""
    if not iso:
        return float("inf")
    try:
        t = _dt.datetime.fromisoformat(iso)
    except ValueError:
        return float("inf")
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.UTC)
    return ((now or _dt.datetime.now(_dt.UTC)) - t).total_seconds()


def process_alive(pid: int | None) -> bool:
    """True while a process of this id exists on this host and is not a zombie."""
    if not pid or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def is_interrupted(
    host: str | None,
    pid: int | None,
    heartbeat_at: str | None,
    *,
    now: _dt.datetime | None = None,
    stale_s: float = STALE_S,
) -> bool:
    """A RUNNING row's run is over: its heartbeat is stale at `now` (the store's clock), or it ran
    here and its process is gone.  A fresh heartbeat from another host means that station's run is live."""
    if age_s(heartbeat_at, now) > stale_s:
        return True
    return host == host_name() and not process_alive(pid)


class Heartbeat:
    """A daemon thread calling `beat()` every `period_s` of wall time until `stop()`; failures of
    `beat` are ignored (a store that is down now may be back at the next beat)."""

    def __init__(self, beat: Callable[[], None], period_s: float = HEARTBEAT_S, name: str = "heartbeat") -> None:
        self._beat = beat
        self._period_s = period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(self._period_s):
            try:
                self._beat()
            except Exception:  # noqa: BLE001, S110 - the next beat tries again
                pass

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
