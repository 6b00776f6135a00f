"""Status polls per second of the rate-table drivers on loopback, beside the raw pymodbus round
trip (the same 6-register FC4 read, no project code) measured in the same run.

Run: .venv/bin/python benchmarks/table_poll.py [seconds_per_run]
"""

from __future__ import annotations

import statistics
import sys
import time

from pymodbus.client import ModbusTcpClient

from bench.clock import SimClock
from drivers.rate_table import AsciiRateTable, ModbusRateTable, TableLimits
from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import preset
from simulators.rate_table import serve_ascii_table, serve_modbus_table
from simulators.world import World


def rate_per_s(fn, seconds: float) -> float:
    n, t0 = 0, time.perf_counter()
    while (dt := time.perf_counter() - t0) < seconds:
        for _ in range(50):
            fn()
        n += 50
    return n / dt


def main(seconds: float = 2.0, runs: int = 5) -> None:
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    limits = TableLimits(500.0, 300.0)
    srv = serve_modbus_table(world)
    raw = ModbusTcpClient(srv.host, port=srv.port, timeout=2.0)
    raw.connect()
    drv = ModbusRateTable(srv.host, srv.port, limits=limits, clock=clock)
    drv.connect()
    asrv = serve_ascii_table(world)
    adrv = AsciiRateTable(asrv.url, limits=limits, clock=clock)
    adrv.connect()
    figures: dict[str, list[float]] = {
        "raw pymodbus FC4 read": [],
        "ModbusRateTable.status": [],
        "AsciiRateTable.status": [],
    }
    for _ in range(runs):  # interleaved, so machine load hits all alike
        figures["raw pymodbus FC4 read"].append(
            rate_per_s(lambda: raw.read_input_registers(0, count=mp.IR_COUNT, device_id=1), seconds)
        )
        figures["ModbusRateTable.status"].append(rate_per_s(drv.status, seconds))
        figures["AsciiRateTable.status"].append(rate_per_s(adrv.status, seconds))
    for name, vals in figures.items():
        print(f"{name:26s} {statistics.median(vals):8.0f} /s  (runs: {', '.join(f'{v:.0f}' for v in vals)})")
    ratio = statistics.median(figures["raw pymodbus FC4 read"]) / statistics.median(figures["ModbusRateTable.status"])
    print(f"raw / driver ratio: {ratio:.2f}x (target <= 1.5x)")
    adrv.close()
    asrv.stop()
    drv.close()
    raw.close()
    srv.stop()
    clock.close()


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 2.0)
