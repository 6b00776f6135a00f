"""Whether a RUNNING row still belongs to a live run: its heartbeat (the store's clock: the
server's on PostgreSQL, refreshed by a daemon thread of the run) and its run token.

A run token is `<boot id>/<pid>/<process start ticks>/<random>`: the boot id is random per boot
of a machine, so two PCs that share a hostname (a cloned image) never take each other's runs for
their own; only a token of this very boot is checked against the process table.  Hostnames are
kept for people to read, never to decide."""

from __future__ import annotations

import datetime as _dt
import os
import socket
import threading
import uuid
from collections.abc import Callable

HEARTBEAT_S = 5.0  # how often a run refreshes its row's heartbeat
STALE_S = 60.0  # a heartbeat older than this (on the store's clock): the run is taken for gone


def host_name() -> str:
    return socket.gethostname()


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat()


def boot_id() -> str:
    """This boot of this machine: Linux's random per-boot id (the hostname where there is none)."""
    try:
        with open("/proc/sys/kernel/random/boot_id") as f:
            return f.read().strip()
    except OSError:
        return f"host-{host_name()}"


def process_start_ticks(pid: int) -> str:
    """When process `pid` started (clock ticks since boot; "" if unknown): a reused pid differs."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""


def new_token(pid: int | None = None) -> str:
    """A run token for a run of process `pid` (this process by default) on this boot."""
    pid = os.getpid() if pid is None else pid
    return f"{boot_id()}/{pid}/{process_start_ticks(pid)}/{uuid.uuid4().hex[:12]}"


def token_alive_here(token: str | None) -> bool | None:
    """True if the token's process runs on this boot, False if it ran on this boot and is gone,
    None when the token is of another machine or boot (or missing): only its heartbeat can tell."""
    if not token:
        return None
    parts = token.split("/")
    if len(parts) != 4 or parts[0] != boot_id():
        return None
    try:
        pid = int(parts[1])
    except ValueError:
        return None
    if not process_alive(pid):
        return False
    start = process_start_ticks(pid)
    return not (parts[2] and start and start != parts[2])


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
    token: str | None,
    heartbeat_at: str | None,
    *,
    now: _dt.datetime | None = None,
    stale_s: float = STALE_S,
) -> bool:
    """A RUNNING row's run is over: its heartbeat is stale at `now` (the store's clock), or its
    token is of this boot and its process is gone.  A fresh heartbeat means a live run, whatever
    host name it ran under; a run taken for gone that beats again is restored (`ResultsStore.heartbeat`)."""
    if age_s(heartbeat_at, now) > stale_s:
        return True
    return token_alive_here(token) is False


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
        """Stop beating; a beat stuck on a store that does not answer is left behind (daemon)."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=0.5)
