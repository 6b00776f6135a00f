"""The station entry of the Acutrol table (`driver = "acutrol-table"`): its keys, how to build the
driver from them, its health and safe-state part; bench.devices finds and imports this module."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, StationError, register_driver

from .station_keys import TABLE_HEALTH_COLUMNS, table_health, table_keys


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .acutronic_driver import AcutrolRateTable
    from .base import TableLimits

    if not (cfg["host"] or cfg["visa_resource"]):
        raise StationError("[devices.table] acutrol-table needs host (TCP) or visa_resource (GPIB through VISA)")
    limits = TableLimits(max_rate_dps=cfg["max_rate_dps"], max_accel_dps2=cfg["max_accel_dps2"])
    table = AcutrolRateTable(
        cfg["host"],
        cfg["port"],
        resource=cfg["visa_resource"],
        framing=cfg["framing"],
        visa_library=cfg["visa_library"],
        axis=cfg["axis"],
        limits=limits,
        clock=clock,
        vtrip_dps=cfg["vtrip_dps"] or None,
        lockout=cfg["lockout"],
        timeout_s=cfg["timeout_s"],
    )
    table.connect()
    return table


SPEC = register_driver(
    DriverSpec(
        name="acutrol-table",
        role="table",
        part="table-to-rest",
        keys=table_keys(
            {
                "host": Key(str, "", doc="controller address (TCP); its real-time computer is 192.168.53.1"),
                "port": Key(int, 9878, 1, 65535, doc="TCP port of the ACL command interface"),
                "visa_resource": Key(str, "", doc="VISA resource instead of TCP, e.g. GPIB0::1::INSTR"),
                "framing": Key(
                    str,
                    "auto",
                    choices=("auto", "tcp", "gpib"),
                    doc="answer framing: auto = GPIB resources lines, sockets the TCP header (TM-8004 2)",
                ),
                "visa_library": Key(
                    str, "", doc="pyvisa library for visa_resource: '' = the default, '@py', a vendor VISA's path"
                ),
                "axis": Key(int, 1, 1, 6, doc="controller axis the gyro is mounted on"),
                "vtrip_dps": Key(float, 0.0, 0.0, 40000.0, doc="velocity trip; 0: 1.1 x max_rate_dps", unit="deg/s"),
                "lockout": Key(bool, True, doc="lock the other interfaces out while connected"),
            }
        ),
        build=_build,
        serve="simulators.rate_table.acutronic_server:serve_station",
        health=table_health,
        health_columns=TABLE_HEALTH_COLUMNS,
        doc="Acutronic ACUTROL3000 table controller, ACL over TCP or GPIB (VISA)",
    )
)
