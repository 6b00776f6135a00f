"""A campaign's runs on dask.distributed: a LocalCluster of one single-threaded worker process a
core (one run a worker at a time) by default, or an existing cluster's scheduler.  Results are
kept as they come back (whatever order), a failed task is recorded with its error, and the
progress (done, failed, running, estimated end) is shown with rich.  No scheduler of our own."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from .execute import execute_run, result_of
from .summary import NOT_MEASURED


@contextmanager
def dask_client(scheduler: str | None, workers: int | None = None) -> Iterator[Any]:
    """A connected dask Client: to `scheduler` (tcp://host:8786), or to a new LocalCluster of
    `workers` processes (default: the cores), one thread each, closed on leaving."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        client = Client(scheduler, timeout="30s")
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    # a worker the nanny stops at the end may take a few seconds (the compute pool's server): not a warning
    logging.getLogger("distributed.nanny").setLevel(logging.ERROR)
    # the engine's compute pool starts a process from the worker: a worker may not be a daemon
    with dask.config.set({"distributed.worker.daemon": False}):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               host="127.0.0.1")
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def dashboard(client: Any) -> str:
    """Where to watch the cluster, or why there is nothing to watch."""
    try:
        import bokeh  # noqa: F401 - the dashboard needs it
    except ImportError:
        return f"{client.dashboard_link} (the dashboard needs bokeh: pip install bokeh)"
    return str(client.dashboard_link)


def run_all(client: Any, runs: list[dict[str, Any]], runs_dir: str, results_url: str | None,
            keep: Callable[[dict[str, Any]], None], operator: str = "", show: bool = True) -> list[dict[str, Any]]:
    """Submit the runs, keep each result as it comes back; the results (in completion order)."""
    from distributed import as_completed

    futures = {client.submit(execute_run, run, runs_dir, results_url, operator, key=f"campaign-{run['run_id']}",
                             pure=False): run for run in runs}
    out = []
    with _Progress(len(runs), _slots(client), show) as bar:
        for future in as_completed(futures):
            run = futures[future]
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - the worker died or the task could not run: recorded
                result = result_of(run, {"outcome": "ERROR", "end_reason": f"{type(exc).__name__}: {exc}"},
                                   error=f"{type(exc).__name__}: {exc}")
            keep(result)
            out.append(result)
            bar.advance(result["outcome"] in NOT_MEASURED)
    return out


def _slots(client: Any) -> int:
    """How many runs the cluster makes at once (its worker threads)."""
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - only for the progress display
        return 1


class _Progress:
    """The rich progress bar: done of total, failed, running, the estimated end."""

    def __init__(self, total: int, slots: int, show: bool) -> None:
        self.total, self.slots, self.done, self.failed = total, slots, 0, 0
        self.t0 = time.monotonic()
        self.bar = None
        if show and total:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            # on stderr: stdout keeps the summary (and --json) alone
            self.bar = Progress(TextColumn("campaign"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("{task.fields[info]}"), TimeElapsedColumn(),
                                console=Console(stderr=True), transient=False)
            self.task = self.bar.add_task("runs", total=total, info=self._info())

    def _info(self) -> str:
        running = min(self.slots, self.total - self.done)
        if self.done:
            rate_s = (time.monotonic() - self.t0) / self.done
            eta = time.strftime("%H:%M:%S", time.localtime(time.time() + rate_s * (self.total - self.done)))
        else:
            eta = "?"
        return f"failed {self.failed}  running {running}  end ~{eta}"

    def __enter__(self) -> _Progress:
        if self.bar is not None:
            self.bar.start()
        return self

    def advance(self, failed: bool) -> None:
        self.done += 1
        self.failed += int(failed)
        if self.bar is not None:
            self.bar.update(self.task, advance=1, info=self._info())

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.stop()
