"""The station entry of an ASCII-command rate table (`driver = "ascii-table"`)."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, register_driver

from .station_keys import TABLE_HEALTH_COLUMNS, table_health, table_keys


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .ascii_driver import AsciiRateTable
    from .base import TableLimits

    limits = TableLimits(max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    table = AsciiRateTable(
        cfg["url"],
        limits=limits,
        clock=clock,
        baudrate=cfg["baudrate"],
        timeout_s=cfg["timeout_s"],
        watchdog_s=cfg["watchdog_s"],
    )
    table.connect()
    return table


SPEC = register_driver(
    DriverSpec(
        name="ascii-table",
        role="table",
        part="table-to-rest",
        keys=table_keys(
            {
                "url": Key(str, "", doc="serial port, pyserial URL or host:port"),
                "baudrate": Key(int, 115200, 300, 4_000_000, doc="serial line speed (bit/s)"),
            }
        ),
        build=_build,
        serve="simulators.rate_table.ascii_server:serve_station",
        health=table_health,
        health_columns=TABLE_HEALTH_COLUMNS,
        doc="rate table, ASCII commands over a serial line or TCP",
    )
)
