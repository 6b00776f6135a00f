"""The manual-control panel (offscreen, pytest-qt) on the simulated station: a rate beyond the
table's limit is refused at its field naming the limit, a rate is reached (the panel against the
simulator's own state), SAFE STATE brings the table to rest with the drive cut, closing the dock
ends the session in the safe state, and a run and a session exclude each other with one message."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import Qt  # noqa: E402

from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402

WAIT_MS = 60_000


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.ask_close_during_run = lambda: True
    qtbot.addWidget(win)
    win.show()
    yield win
    backend.close()


def _open_and_start(qtbot, win):
    win.findChild(type(win.menuBar().actions()[0]), "manual_action").trigger()
    panel = win.manual_dock.panel
    assert win.manual_dock.isVisible()
    qtbot.mouseClick(panel.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: panel.active() and panel.rate_button.isEnabled(), timeout=WAIT_MS)
    return panel


def test_manual_panel_refuses_at_the_field_spins_and_safe_state_brings_rest(window, qtbot):
    win = window
    world = win.backend.station.world
    panel = _open_and_start(qtbot, win)
    assert win.station.speed.currentText() == "real time"  # an operator acts in real time
    panel.rate_edit.setText("1500")
    assert "rate_dps=1500 deg/s is above the station's limit 1000 deg/s" in panel.rate_error.text()
    qtbot.mouseClick(panel.rate_button, Qt.MouseButton.LeftButton)
    assert panel.session.state.rate_cmd_dps == 0.0  # nothing was sent
    panel.agc_edit.setText("50")
    assert "agc_setpoint=50 is above the limit 10" in panel.agc_error.text()
    panel.agc_edit.setText("1")
    qtbot.mouseClick(panel.drive_on_button, Qt.MouseButton.LeftButton)
    panel.rate_edit.setText("100")
    assert panel.rate_error.text() == ""
    qtbot.mouseClick(panel.rate_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: abs(panel.table_rate_shown() - 100.0) < 0.5, timeout=WAIT_MS)
    assert abs(world.case_rate_dps - panel.table_rate_shown()) < 1.0  # the panel agrees with the simulator
    assert panel.readings["drive_on"].text() == "on"
    with world.lock:
        assert np.any(world.total_force)
    # a run cannot start meanwhile: one message saying why
    with pytest.raises(RuntimeError, match="manual control holds station 'sim-hrg'"):
        win.backend.start("hrg-free-decay", {})
    assert not win.start_button.isEnabled()
    qtbot.mouseClick(win.safe_state_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.safe_state and win.last_finished.outcome == "ABORTED"
    assert "safe state button" in win.last_finished.end_reason
    assert abs(world.case_rate_dps) < 0.1
    with world.lock:
        assert not np.any(world.total_force)
    qtbot.waitUntil(lambda: not panel.active() and math.isnan(panel.table_rate_shown()), timeout=WAIT_MS)
    qtbot.waitUntil(lambda: panel.start_button.isEnabled(), timeout=WAIT_MS)


def test_closing_the_dock_ends_the_session_in_the_safe_state(window, qtbot):
    win = window
    world = win.backend.station.world
    panel = _open_and_start(qtbot, win)
    panel.rate_edit.setText("50")
    qtbot.mouseClick(panel.rate_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: abs(world.case_rate_dps - 50.0) < 0.5, timeout=WAIT_MS)
    win.manual_dock.close()
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.outcome == "COMPLETE" and win.last_finished.safe_state
    assert abs(world.case_rate_dps) < 0.1


def test_manual_control_cannot_start_during_a_run(window, qtbot):
    win = window
    win.procedure.setCurrentText("hrg-free-decay")
    win.form.set_value("record_s", 3600.0)
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: win.backend.runner.record is not None and win.run_active, timeout=WAIT_MS)
    win.manual_dock.show()
    panel = win.manual_dock.panel
    assert not panel.start() and "holds station 'sim-hrg': manual control needs an idle station" in panel.message.text()
    qtbot.mouseClick(win.safe_state_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.outcome == "ABORTED" and win.last_finished.safe_state


def test_closing_the_window_during_a_session_ends_it_in_the_safe_state(window, qtbot):
    win = window
    world = win.backend.station.world
    panel = _open_and_start(qtbot, win)
    qtbot.mouseClick(panel.drive_on_button, Qt.MouseButton.LeftButton)
    panel.rate_edit.setText("80")
    qtbot.mouseClick(panel.rate_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: abs(world.case_rate_dps - 80.0) < 0.5, timeout=WAIT_MS)
    win.close()  # asks first (answered yes by the fixture), then aborts to the safe state and waits
    assert not win.backend.running()
    rec = win.backend.runner.record
    assert rec.procedure == "manual" and rec.outcome == "ABORTED" and rec.safe_state
    assert abs(world.case_rate_dps) < 0.1
    with world.lock:
        assert not np.any(world.total_force)


def test_safe_state_on_an_idle_station_is_done_and_said(window, qtbot):
    win = window
    station = win.backend.station
    with win.backend._io_gate:  # the panel's poller talks to the devices too
        station.devices["table"].enable()
        station.devices["table"].set_rate(30.0)  # left turning by hand, outside any run or session
    qtbot.waitUntil(lambda: abs(station.world.case_rate_dps - 30.0) < 0.5 or station.clock.sleep(0.1), timeout=WAIT_MS)
    qtbot.mouseClick(win.safe_state_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "safe state button: safe state confirmed" in win.log.toPlainText(), timeout=WAIT_MS)
    assert abs(station.world.case_rate_dps) < 0.1


def test_refused_value_is_logged_and_recorded_and_the_dock_says_when_safe(window, qtbot):
    """A value refused at its field is in the log and in `manual_actions` (accepted 0); after
    SAFE STATE the dock shows the engine's confirmation, not "aborting..." for ever."""
    win = window
    panel = _open_and_start(qtbot, win)
    panel.rate_edit.setText("1500")
    qtbot.mouseClick(panel.rate_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "manual: table_rate '1500' refused" in win.log.toPlainText(), timeout=WAIT_MS)
    assert "above the station's limit 1000 deg/s" in win.log.toPlainText()
    assert panel.session.state.rate_cmd_dps == 0.0  # nothing was sent
    qtbot.mouseClick(panel.safe_button, Qt.MouseButton.LeftButton)
    assert "aborting to the safe state" in panel.message.text()
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: "safe state confirmed" in panel.message.text(), timeout=WAIT_MS)
    assert "aborting" not in panel.message.text()
    assert win.backend.join(60)
    from bench.engine.manual import ACTION_CODES
    from bench.recorder import open_run

    with open_run(win.last_finished.raw_file) as data:
        cols = data.columns("manual_actions")
        rows = data.array("manual_actions")
    is_rate = rows[:, cols.index("action")] == ACTION_CODES["table_rate"]
    refused = rows[is_rate & (rows[:, cols.index("accepted")] == 0)]
    assert len(refused) == 1 and refused[0, cols.index("rate_cmd_dps")] == 0.0
