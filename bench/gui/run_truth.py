"""The simulated truth of a run's measurements, for the results table's truth column: the
simulator's parameters under the measurement names the procedure declares (empty on a real
bench, for manual control, for a replay, or for a procedure that declares none)."""

from __future__ import annotations

from typing import Any


def truth_for_run(backend: Any, procedure: str, run_id: str = "") -> dict[str, float]:
    """Only for the run the backend's station is running now: a replayed file's truth is the file's
    (`RunData.truth()`), not the live simulator's."""
    station = getattr(backend, "station", None)
    if station is None or not getattr(station, "simulated", False):
        return {}
    live = getattr(getattr(backend, "runner", None), "record", None)
    if live is None or live.run_id != run_id:
        return {}
    try:
        from procedures import measurement_truth

        return dict(measurement_truth(procedure, station.truth()))
    except Exception:  # noqa: BLE001 - no truth column rather than no window (manual control, a file)
        return {}
