"""One campaign run in a worker process: a normal run (the engine's Runner on a station from the
composition root, its raw file and its store row, as `gyrobench run` makes them) under the
campaign's run id, returned as a small result the client keeps.  A run that cannot even start
(a parameter out of range, a station that does not open) comes back as an ERROR result with its
error: one failed run never stops the others."""

from __future__ import annotations

import multiprocessing
import time
import traceback
from typing import Any

#: one store a worker process and results URL (opening one runs its migrations check)
_STORES: dict[str, Any] = {}


def _store(url: str | None) -> Any:
    from bench.results import ResultsStore

    key = url or ""
    if key not in _STORES:
        _STORES[key] = ResultsStore(url, offline_ok=True)
    return _STORES[key]


def result_of(run: dict[str, Any], js: dict[str, Any], error: str = "") -> dict[str, Any]:
    """A campaign result from a run's `--json` shape: values, intervals and the measurements' truth."""
    from procedures import measurement_truth

    meas = js.get("measurements") or {}
    return {
        "run_id": run["run_id"], "index": run["index"], "procedure": run["procedure"], "seed": run["seed"],
        "varied": run["varied"], "outcome": js.get("outcome", "ERROR"), "end_reason": js.get("end_reason", ""),
        "error": error, "raw_file": js.get("raw_file"), "wall_s": js.get("wall_s"),
        "values": {k: m.get("value") for k, m in meas.items()},
        "ci95": {k: m.get("ci95") for k, m in meas.items()},
        "units": {k: m.get("unit", "") for k, m in meas.items()},
        "truth": measurement_truth(run["procedure"], js.get("truth")),
        "crlb": js.get("crlb") or {},
    }


def result_from_row(run: dict[str, Any], row: dict[str, Any]) -> dict[str, Any]:
    """A campaign result from the store's row of a run (a campaign killed after the run was saved)."""
    def ci(m: dict[str, Any]) -> list[float] | None:
        return None if m["ci95_low"] is None or m["ci95_high"] is None else [m["ci95_low"], m["ci95_high"]]

    js = {"outcome": row["outcome"], "end_reason": row.get("end_reason", ""), "raw_file": row.get("raw_file"),
          "wall_s": row.get("wall_s"), "truth": row.get("truth"),
          "measurements": {m["name"]: {"value": m["value"], "ci95": ci(m), "unit": m["unit"]}
                           for m in row.get("measurements", []) if m.get("source", "run") == "run"}}
    return result_of(run, js)


def _bounds(proc: Any, truth: dict[str, float] | None) -> dict[str, float]:
    """The Cramer-Rao standard deviations the procedure states for this unit, by measurement name
    (a procedure's optional `crlb_std(truth)`); {} when it states none."""
    hook = getattr(proc, "crlb_std", None)
    if hook is None or not truth:
        return {}
    try:
        return {k: float(v) for k, v in hook(truth).items()}
    except Exception:  # noqa: BLE001 - a bound that cannot be computed is left out, the run stands
        return {}


def _in_dask_worker() -> bool:
    """Whether this is a Dask worker (not a caller's own process, whose computations stay apart)."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return False
    return True


def execute_run(run: dict[str, Any], runs_dir: str, results_url: str | None, operator: str = "") -> dict[str, Any]:
    """Make one run of a campaign (a RunSpec as a dict); its campaign result, never raising."""
    t0 = time.monotonic()
    if multiprocessing.current_process().daemon:
        # the engine's compute pool starts a process of its own, which a daemonic one may not
        return result_of(run, {}, error="the Dask worker is a daemonic process; start workers with "
                                        "DASK_DISTRIBUTED__WORKER__DAEMON=False (docs/campaigns.md)")
    try:
        from bench.composition import load_station
        from bench.engine import Runner, check_station
        from bench.engine.compute import compute_in_process
        from procedures import find_procedure

        if _in_dask_worker():  # the worker process is the run's isolation: no forkserver of its own
            compute_in_process()
        proc = find_procedure(run["procedure"])(dict(run["params"]))
        overrides: dict[str, Any] = {"seed": run["seed"], "speed": 0.0}
        if run.get("preset"):
            overrides["preset"] = run["preset"]
        station = load_station(run["station"], unit=run["unit"] or None, **overrides)
        check_station(proc, station)
        store = _store(results_url)
        runner = Runner(station, runs_dir=runs_dir, store=store, operator=operator)
        runner.next_run_id = run["run_id"]
        try:
            station.open()
            rec = runner.run(proc)
        finally:
            station.close()
        js = rec.as_json()
        js["crlb"] = _bounds(proc, js.get("truth"))
        return result_of(run, js, error=rec.store_error or "")
    except Exception as exc:  # noqa: BLE001 - recorded with its error; the campaign goes on
        tb = traceback.format_exception_only(exc)[-1].strip()
        out = result_of(run, {"outcome": "ERROR", "end_reason": tb}, error=tb)
        out["wall_s"] = time.monotonic() - t0
        return out
