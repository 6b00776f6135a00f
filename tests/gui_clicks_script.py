"""Driven by tests/test_gui_xvfb.py under xvfb-run: the lab engineer's clicks on a real X server
(start, pause, resume, abort, a run to the end) and the station panel against the simulator's
own state after the safe state.  Prints one JSON line of what it saw; argv[1]: screenshot path."""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

from bench.gui.engine_backend import EngineBackend
from bench.gui.main_window import MainWindow


def wait(cond, timeout_s: float = 90.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        QApplication.processEvents()
        if cond():
            return True
        time.sleep(0.01)
    return False


def click(button) -> None:
    QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    QApplication.processEvents()


def main(shot: str) -> int:
    app = QApplication.instance() or QApplication(["gyrobench"])
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.show()
    seen: dict[str, object] = {"platform": app.platformName()}
    world = backend.station.world
    try:
        wait(lambda: win.station.value("fpga", "frames") is not None)
        seen["idle_rate"] = win.station.value("table", "rate_dps")
        win.station.set_speed(100.0)
        win.procedure.setCurrentText("hrg-free-decay")
        win.form.set_value("record_s", "600")
        win.form.set_value("rate_dps", "200")
        click(win.start_button)
        seen["started"] = wait(lambda: win.run_active and win.plots.fpga.total_rows > 2000)
        click(win.pause_button)
        seen["pause_text"] = win.status_line.text()
        wait(lambda: False, 0.5)
        win.plots.refresh(force=True)
        QApplication.processEvents()
        seen["shot"] = win.grab().save(shot, "PNG")
        click(win.pause_button)
        seen["resumed"] = win.status_line.text() != seen["pause_text"]
        click(win.abort_button)
        seen["aborted"] = wait(lambda: win.last_finished is not None)
        fin = win.last_finished
        seen["outcome"], seen["safe_state"] = fin.outcome, fin.safe_state
        seen["panel_at_rest"] = wait(lambda: win.station.value("table", "rate_dps") is not None
                                     and abs(float(win.station.value("table", "rate_dps"))) < 0.1
                                     and win.station.value("frontend", "drive") == "off")
        seen["panel_rate"] = float(win.station.value("table", "rate_dps"))
        seen["sim_rate"] = float(world.case_rate_dps)
        with world.lock:
            seen["sim_drive"] = bool(np.any(world.total_force))
        # a run to the end
        win.station.speed.setCurrentText("max")
        win.procedure.setCurrentText("hrg-free-decay")
        win.form.set_value("record_s", "5")
        win.last_finished = None
        wait(lambda: not backend.running(), 10)
        click(win.start_button)
        seen["completed"] = wait(lambda: win.last_finished is not None) and win.last_finished.outcome
        seen["status_style"] = win.status_line.styleSheet()
        seen["width"] = win.width()
    finally:
        win.close()
        backend.close()
    print(json.dumps(seen))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
