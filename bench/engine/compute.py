"""Long computations in a worker process the engine can end, so that an abort is honoured
within a fraction of a second even in the middle of an estimator (`RunContext.compute`).

The worker is a fresh process from the 'forkserver' context (never a fork of the threaded bench
process); the server preloads numpy, scipy and the estimators once, so a call costs a fork and
the pickling of its arguments.  A function the worker cannot import (defined in `__main__`, in
a procedure loaded from a file, or a lambda) runs on a thread instead: an abort still returns at
once, and the thread is left to finish on its own.
"""

from __future__ import annotations

import atexit
import contextlib
import copyreg
import multiprocessing
import signal
import threading
import traceback
import types
from collections.abc import Callable
from typing import Any

#: modules the forkserver imports once, so that each worker starts warm: the worker's own code
#: (bench.engine: ~0.06 s to import) and the estimators with their one-time tables (bench.analysis.warm)
PRELOAD = ("numpy", "scipy.integrate", "scipy.optimize", "threadpoolctl", "bench.engine.compute",
           "bench.analysis.damping", "bench.analysis.maslov", "bench.analysis.warm")
#: how often (wall s) a waiting computation passes an engine checkpoint
POLL_S = 0.05

# read-only mappings (the fits' ci95) travel as what they are: a proxy of a private dict
def _mapping_proxy(items: dict) -> types.MappingProxyType:
    return types.MappingProxyType(items)


copyreg.pickle(types.MappingProxyType, lambda m: (_mapping_proxy, (dict(m),)))

_context_lock = threading.Lock()
_context: Any = None


#: computations on a thread of this process (see `compute_in_process`)
_in_process = False


def compute_in_process() -> None:
    """From now on, this process's computations run on a thread of its own instead of a worker
    process: for a process that is itself a disposable worker (a campaign's Dask worker, which
    nobody aborts mid-run), where a forkserver of its own costs ~1 s of CPU a process and a fork
    a computation for nothing.  BLAS on one thread, as in a worker process (same numbers)."""
    global _in_process
    if not _in_process:
        _single_thread_blas()
        _in_process = True


#: starters of workers abandoned by an abort while still starting (see `_finish_starts`)
_starting: set[threading.Thread] = set()


@atexit.register
def _finish_starts() -> None:
    """Let an abandoned start finish (and kill its worker) before the process exits: a worker
    cut off half-way through receiving its task would print a traceback."""
    for th in list(_starting):
        th.join(timeout=10.0)


class WorkerDied(RuntimeError):
    """The worker process ended without an answer (killed by the system, out of memory)."""


def _mp_context() -> Any:
    global _context
    with _context_lock:
        if _context is None:
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(list(PRELOAD))
            _context = ctx
        return _context


def warm() -> None:
    """Start the forkserver (and its imports) now, on a thread, so that the run's first
    computation does not wait ~0.5 s for it: called when a run starts; idempotent (and nothing
    to do when computations run in this process)."""
    if _in_process:
        return

    def start() -> None:
        with contextlib.suppress(Exception):  # the computation itself reports a failure to start
            _mp_context()
            from multiprocessing import forkserver

            forkserver.ensure_running()

    threading.Thread(target=start, name="gyrobench-compute-warm", daemon=True).start()


def _worker(conn: Any, fn: Callable, args: tuple, kwargs: dict) -> None:
    """In the worker: run fn and send (True, value) or (False, exception, traceback text).  Ctrl-C
    at a terminal reaches the whole process group: the engine handles it and ends this process, so
    the worker ignores it; an engine that no longer listens (it aborted) is not an error here."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        _single_thread_blas()
        try:
            reply = (True, fn(*args, **kwargs), "")
        except Exception as exc:  # noqa: BLE001 - everything goes back to the engine
            reply = (False, exc, traceback.format_exc())
        try:
            conn.send(reply)
        except (OSError, EOFError):
            return  # the engine has gone on (abort): nobody to answer
        except Exception:  # noqa: BLE001 - a value or an exception that does not pickle
            err = reply[1] if not reply[0] else None
            what = f"{type(err).__name__}: {err}" if err is not None else "the result does not pickle"
            with contextlib.suppress(OSError, EOFError):
                conn.send((False, RuntimeError(what), reply[2]))
    finally:
        conn.close()


def _single_thread_blas() -> None:
    """BLAS on one thread in the worker: a freshly forked worker's threaded OpenBLAS spends more
    starting its threads than the estimators' small matrices gain (a 900 s decay fit took
    0.2-0.5 s there against 0.09 s on one thread)."""
    with contextlib.suppress(Exception):
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")


def importable(fn: Callable) -> bool:
    """Whether a worker process can import fn by name (a module-level function of a package)."""
    module = getattr(fn, "__module__", "") or ""
    qualname = getattr(fn, "__qualname__", "") or ""
    return bool(module) and module != "__main__" and not module.startswith("gyrobench_user_") and "<" not in qualname


def run_in_worker(fn: Callable, args: tuple, kwargs: dict, checkpoint: Callable[[], None]) -> Any:
    """fn(*args, **kwargs) in a worker process; `checkpoint()` every POLL_S while it runs.  If the
    checkpoint raises (an abort) the worker is killed at once and the exception goes on."""
    if _in_process or not importable(fn):
        return _run_on_thread(fn, args, kwargs, checkpoint)
    ctx = _mp_context()
    receiver, sender = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_worker, args=(sender, fn, args, kwargs), name="gyrobench-compute", daemon=True)
    cancelled = threading.Event()

    def start() -> None:  # the first start waits for the forkserver's imports: the checks go on meanwhile
        try:
            proc.start()
            if cancelled.is_set():
                proc.kill()
        finally:
            sender.close()  # the worker holds its own end now

    starter = threading.Thread(target=start, name="gyrobench-compute-start", daemon=True)
    starter.start()
    try:
        while starter.is_alive():
            starter.join(POLL_S)
            checkpoint()
    except BaseException:
        cancelled.set()
        if proc.pid is not None and proc.is_alive():
            proc.kill()
        else:  # still starting: the starter kills it once started, before this process exits
            _starting.add(starter)
        receiver.close()
        raise
    if proc.pid is None:
        receiver.close()
        raise WorkerDied(f"the computation {fn.__qualname__} could not start its worker process")
    try:
        while not receiver.poll(POLL_S):
            if not proc.is_alive() and not receiver.poll(0):
                raise WorkerDied(f"the computation {fn.__qualname__} ended without an answer (exit {proc.exitcode})")
            checkpoint()
        ok, value, text = receiver.recv()
    except BaseException:
        if proc.is_alive():
            proc.kill()
        raise
    finally:
        receiver.close()
        proc.join(timeout=1.0)
    if not ok:
        if text and hasattr(value, "add_note"):
            value.add_note(f"in the worker process:\n{text}")
        raise value
    return value


def _run_on_thread(fn: Callable, args: tuple, kwargs: dict, checkpoint: Callable[[], None]) -> Any:
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001
            box["error"] = exc

    th = threading.Thread(target=target, name="gyrobench-compute", daemon=True)
    th.start()
    while True:
        th.join(POLL_S)
        if not th.is_alive():
            break
        checkpoint()
    if "error" in box:
        raise box["error"]
    return box["value"]
