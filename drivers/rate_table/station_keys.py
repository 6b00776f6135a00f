"""What every rate-table model's station entry shares: the limit keys and the health check
(status read, trip raised, rate and angle recorded)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.devices import Key
from drivers.errors import SafetyTripError

#: columns (after t_s) of the rows a table's health check adds to the run's `table` stream
TABLE_HEALTH_COLUMNS = ("rate_dps", "angle_deg")


def table_keys(address: dict[str, Key]) -> dict[str, Key]:
    """The keys of a rate-table model: its limits plus its own address keys."""
    return {
        "driver": Key(str, required=True),
        "max_rate_dps": Key(float, 1000.0, 1e-3, 20000.0, doc="rate limit", unit="deg/s"),
        "max_accel_dps2": Key(float, 500.0, 1e-3, 100000.0, doc="acceleration limit", unit="deg/s^2"),
        "watchdog_s": Key(float, 2.0, 0.1, 60.0, doc="table stops itself without a command for this long", unit="s"),
        "timeout_s": Key(float, 1.0, 0.01, 30.0, doc="wall time allowed for a reply", unit="s"),
        **address,
    }


def table_health(table: Any, since: Any = None) -> np.ndarray:
    """One row (rate_dps, angle_deg); SafetyTripError when the table has tripped."""
    return _health_row(table.status())


def table_probe_health(table: Any, since: Any = None) -> np.ndarray:
    """table_health through the model's cheaper `probe_status` (the same read and row)."""
    return _health_row(table.probe_status())


def _health_row(st: Any) -> np.ndarray:
    if st.tripped:
        raise SafetyTripError(f"rate table tripped: {st.trip_reason()}, rate={st.rate_dps:.3f} deg/s")
    return np.array([[st.rate_dps, st.angle_deg]])
