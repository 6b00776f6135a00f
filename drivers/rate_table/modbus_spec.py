"""The station entry of a Modbus TCP/RTU rate table (`driver = "modbus-table"`)."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, register_driver

from .station_keys import TABLE_HEALTH_COLUMNS, table_keys, table_probe_health


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .base import TableLimits
    from .modbus_driver import ModbusRateTable

    limits = TableLimits(max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    kw = dict(limits=limits, clock=clock, device_id=cfg["device_id"], timeout_s=cfg["timeout_s"])
    if cfg.get("serial_port"):
        table = ModbusRateTable.rtu(cfg["serial_port"], watchdog_s=cfg["watchdog_s"], **kw)
    else:
        table = ModbusRateTable(cfg["host"], cfg["port"], watchdog_s=cfg["watchdog_s"], **kw)
    table.connect()
    return table


SPEC = register_driver(
    DriverSpec(
        name="modbus-table",
        role="table",
        part="table-to-rest",
        keys=table_keys(
            {
                "host": Key(str, "127.0.0.1", doc="Modbus TCP host"),
                "port": Key(int, 502, 1, 65535, doc="Modbus TCP port"),
                "serial_port": Key(str, "", doc="RTU on a serial port instead of TCP"),
                "device_id": Key(int, 1, 0, 247, doc="Modbus unit id"),
            }
        ),
        build=_build,
        serve="simulators.rate_table.modbus_server:serve_station",
        health=table_probe_health,
        health_columns=TABLE_HEALTH_COLUMNS,
        doc="rate table, Modbus TCP or RTU",
    )
)
