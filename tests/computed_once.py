"""A costly module fixture's result computed once a test session, whichever xdist worker asks
first: `make test`'s worksteal scheduling can hand a module's tests to two workers, and each ran
the module's fixture again (a four-unit thermal batch: ~11 CPU s more, in 3 of 8 passes measured).
For fixtures whose result is data the tests only read (pickled to the session's shared temporary
directory under a file lock; a worker that asks meanwhile waits for it, idle)."""

from __future__ import annotations

import fcntl
import os
import pickle
from collections.abc import Callable
from typing import Any


def computed_once(tmp_path_factory: Any, key: str, compute: Callable[[], Any]) -> Any:
    """compute()'s result, computed by the first caller of the session and read by the others."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # xdist: the session's own folder
    data = root / f"computed-once-{key}.pickle"
    with open(root / f"computed-once-{key}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if data.exists():
                return pickle.loads(data.read_bytes())
            value = compute()
            part = data.with_suffix(".part")
            part.write_bytes(pickle.dumps(value))
            os.replace(part, data)
            return value
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
