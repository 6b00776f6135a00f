"""GUI refresh rate and event-loop latency while a 1 kHz stream runs.

The engine on a simulated station (default sim-hrg: the simulators on loopback transports, one
World at 1 kHz) runs `hrg-damping`'s free decay; first as fast as the CPU allows until the
plots hold `--prefill-s` of history (the issue's 300 s worst case), then at real time (1 kHz,
delivered in 10 ms blocks) for `--measure-s` wall seconds, then again at max speed.  Printed:
redraws per second, redraw cost, lateness of a 10 ms QTimer (event-loop latency) and the delay
from publish in the engine thread to delivery in the GUI thread.

    QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/gui_refresh.py [--measure-s 10]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np


def _pct(values, q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if len(values) else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prefill-s", type=float, default=280.0)
    ap.add_argument("--measure-s", type=float, default=10.0)
    ap.add_argument("--station", default="sim-hrg", help="a simulated station with an FPGA stream (name or file)")
    args = ap.parse_args()
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from bench.gui.engine_backend import EngineBackend
    from bench.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    os.chdir(tempfile.mkdtemp(prefix="gui_refresh_"))  # the run's raw file and results index
    backend = EngineBackend(args.station, seed=0)
    procedure, params = "hrg-damping", {"record_s": "3600", "compensate": "false", "stream_hz": "1000"}  # 1 kHz
    win = MainWindow(backend)
    win.station.set_speed(float("inf"))
    win.show()

    def pump_until(cond, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while not cond() and time.monotonic() < end:
            app.processEvents()
            time.sleep(0.001)

    lateness_ms: list[float] = []
    period_ms = 10
    state = {"last": None}

    def tick() -> None:
        now = time.perf_counter()
        if state["last"] is not None:
            lateness_ms.append((now - state["last"]) * 1e3 - period_ms)
        state["last"] = now

    probe = QTimer()
    probe.setInterval(period_ms)
    probe.timeout.connect(tick)

    def measure(label: str, seconds: float) -> None:
        lateness_ms.clear()
        state["last"] = None
        win.bridge.latency_s.clear()
        n0, rows0 = win.plots.refresh_count, win.plots.fpga.total_rows
        win.plots.refresh_cost_s.clear()
        costs0 = 0
        t0 = time.perf_counter()
        cpu0 = time.process_time()
        probe.start()
        pump_until(lambda: time.perf_counter() - t0 >= seconds, seconds + 5)
        probe.stop()
        wall = time.perf_counter() - t0
        cpu = (time.process_time() - cpu0) / wall
        costs = list(win.plots.refresh_cost_s)[costs0:]
        lat = [x * 1e3 for x in win.bridge.latency_s]
        print(f"{label}:")
        print(f"  stream: {(win.plots.fpga.total_rows - rows0) / wall:,.0f} samples/s into the plots, "
              f"history {len(win.plots.fpga)} rows ({len(win.plots.fpga) / 1000:.0f} s at 1 kHz)")
        print(f"  refresh: {(win.plots.refresh_count - n0) / wall:.1f} redraws/s (timer 25 Hz), "
              f"redraw cost median {_pct(costs, 50) * 1e3:.1f} ms, p99 {_pct(costs, 99) * 1e3:.1f} ms")
        print(f"  event loop: 10 ms timer late by median {_pct(lateness_ms, 50):.1f} ms, "
              f"p99 {_pct(lateness_ms, 99):.1f} ms, max {max(lateness_ms, default=float('nan')):.1f} ms")
        print(f"  process CPU (GUI + simulated world): {cpu:.2f} cores; machine load average {os.getloadavg()[0]:.1f} "
              f"on {os.cpu_count()} cores")
        print(f"  engine -> GUI delivery: median {_pct(lat, 50):.1f} ms, p99 {_pct(lat, 99):.1f} ms")

    win.procedure.setCurrentText(procedure)
    for k, v in params.items():
        win.form.set_value(k, v)
    t0 = time.perf_counter()
    win.start()
    pump_until(lambda: win.t_sim_s >= args.prefill_s, 600)
    print(f"station {args.station}, procedure {procedure}")
    print(f"prefill: {win.t_sim_s:.0f} s of 1 kHz simulated in {time.perf_counter() - t0:.1f} s wall (max speed)")
    measure(f"max speed with {args.prefill_s:.0f} s of history", 3.0)
    win.station.set_speed(1.0)  # the window's control: the clock and the bridge's backpressure follow
    pump_until(lambda: False, 0.5)
    measure(f"real time (1 kHz stream) with ~{args.prefill_s:.0f} s of history", args.measure_s)
    win.abort()
    pump_until(lambda: win.last_finished is not None, 30)
    print(f"abort -> safe state confirmed: {win.last_finished.safe_state if win.last_finished else 'no'}")
    backend.close()
    win.close()


if __name__ == "__main__":
    main()
