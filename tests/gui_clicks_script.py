"""Driven by tests/test_gui_xvfb.py under xvfb-run: the lab engineer's clicks on a real X server
(start, pause, resume, abort, a run to the end) and the station panel against the simulator's
own state after the safe state; then manual control (spin, panel against the simulator, SAFE
STATE) and the results table's columns.  Prints one JSON line of what it saw; argv[1]: screenshot path."""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QToolButton

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


def manual_clicks(win, backend, world, seen: dict, shot: str) -> None:
    """Open manual control from the toolbar, spin the table, check the panel against the
    simulator, press SAFE STATE, check both at rest; screenshot next to `shot` (_manual.png)."""
    wait(lambda: not backend.running(), 30)
    toolbar_button = win.findChild(QToolButton, "")  # the first toolbar button is "Manual control"
    for b in win.findChildren(QToolButton):
        if b.defaultAction() is not None and b.defaultAction().objectName() == "manual_action":
            toolbar_button = b
    click(toolbar_button)
    panel = win.manual_dock.panel
    seen["manual_shown"] = win.manual_dock.isVisible()
    wait(lambda: panel.start_button.isEnabled() and panel.start_button.isVisible(), 10)
    wait(lambda: False, 0.3)  # the dock laid out
    click(panel.start_button)
    seen["manual_active"] = wait(lambda: panel.active() and panel.rate_button.isEnabled(), 30)
    seen["manual_message"] = panel.message.text()
    panel.rate_edit.setText("1500")
    seen["manual_refusal"] = panel.rate_error.text()
    panel.rate_edit.setText("120")
    click(panel.drive_on_button)
    click(panel.rate_button)
    seen["manual_at_rate"] = wait(lambda: abs(panel.table_rate_shown() - 120.0) < 0.5, 60)
    seen["manual_panel_rate"] = panel.table_rate_shown()
    seen["manual_sim_rate"] = float(world.case_rate_dps)
    with world.lock:
        seen["manual_sim_drive"] = bool(np.any(world.total_force))
    wait(lambda: False, 1.0)
    win.plots.refresh(force=True)
    QApplication.processEvents()
    seen["manual_shot"] = win.grab().save(shot.replace(".png", "_manual.png"), "PNG")
    click(win.safe_state_button)
    seen["manual_finished"] = wait(lambda: win.last_finished is not None and not backend.running(), 60)
    fin = win.last_finished
    seen["manual_outcome"], seen["manual_safe_state"] = fin.outcome, fin.safe_state
    seen["manual_rest"] = wait(lambda: win.station.value("table", "rate_dps") is not None
                               and abs(float(win.station.value("table", "rate_dps"))) < 0.1, 30)
    seen["manual_sim_rate_after"] = float(world.case_rate_dps)
    with world.lock:
        seen["manual_sim_drive_after"] = bool(np.any(world.total_force))


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
        seen["end_reason"] = fin.end_reason
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
        res = win.results
        seen["result_headers"] = list(res.HEADERS)
        seen["result_rows"] = [{h: res.table.item(r, c).text() for c, h in enumerate(res.HEADERS)}
                               for r in range(res.table.rowCount())]
        wait(lambda: False, 0.3)
        seen["results_h"] = [res.table.height(), res.table.maximumHeight(), win.height()]
        manual_clicks(win, backend, world, seen, shot)
    finally:
        win.close()
        backend.close()
    print(json.dumps(seen))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
