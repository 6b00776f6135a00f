"""A store operation with a bound on the wait: it runs in a daemon thread, and the caller gives up
after `wait_s` (the thread, stuck on a server that does not answer, is left behind; the process
can still exit).  A socket to a stopped server is never closed by the kernel, so only a bound of
the caller's own ends the wait."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


class NoAnswer(Exception):
    """The store did not answer within the wait."""

    def __init__(self, wait_s: float) -> None:
        super().__init__(f"no answer in {wait_s:.0f} s")
        self.wait_s = wait_s


def call_bounded(
    fn: Callable[[], T],
    wait_s: float,
    *,
    slow_after_s: float | None = None,
    on_slow: Callable[[float], None] | None = None,
) -> T:
    """fn() in a daemon thread: its value, or what it raised; NoAnswer after `wait_s`.  After
    `slow_after_s` without an answer `on_slow(elapsed_s)` is called once (to tell a waiting user)."""
    done = threading.Event()
    box: dict[str, object] = {}

    def target() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = exc
        finally:
            done.set()

    t0 = time.monotonic()
    threading.Thread(target=target, name="results-store call", daemon=True).start()
    if slow_after_s is not None and on_slow is not None and slow_after_s < wait_s:
        if not done.wait(slow_after_s):
            on_slow(time.monotonic() - t0)
    if not done.wait(max(0.0, wait_s - (time.monotonic() - t0))):
        raise NoAnswer(wait_s)
    if "error" in box:
        raise box["error"]  # type: ignore[misc]
    return box["value"]  # type: ignore[return-value]
