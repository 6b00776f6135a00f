"""What the window shows is true (offscreen, pytest-qt): the station panel is read from the
devices between runs and after the safe state (checked against the simulator's own state), a
device that stops answering is shown down, the FPGA row has its link counters, colours follow the
outcome, a long error wraps instead of widening the window, pause says the table keeps its rate,
and closing during a run asks first, then aborts to the safe state."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import Qt  # noqa: E402
from PySide6.QtWidgets import QMessageBox  # noqa: E402

from bench.engine import events as ev  # noqa: E402
from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402

WAIT_MS = 60_000


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.ask_close_during_run = lambda: True  # a test that fails mid-run must not wait on a question box
    qtbot.addWidget(win)
    win.show()
    yield win
    backend.close()


def _start(qtbot, win: MainWindow, procedure: str, **values) -> None:
    win.procedure.setCurrentText(procedure)
    for k, v in values.items():
        win.form.set_value(k, v)
    assert win.start_button.isEnabled(), win.form.errors
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)


def _panel_rate(win: MainWindow) -> float | None:
    text = win.station.value("table", "rate_dps")
    return None if text is None else float(text)


def test_panel_is_filled_before_any_run_with_link_counters(window, qtbot):
    win = window
    qtbot.waitUntil(lambda: win.station.value("fpga", "frames") is not None, timeout=WAIT_MS)
    assert win.station.state("table") == "connected"
    assert _panel_rate(win) is not None and abs(_panel_rate(win)) < 0.1
    assert win.station.value("frontend", "drive") == "off"
    for key in ("frames", "lost", "crc_errors"):
        assert win.station.value("fpga", key) is not None


def test_panel_after_the_safe_state_matches_the_simulator(window, qtbot):
    win = window
    win.station.speed.setCurrentText("max")
    _start(qtbot, win, "hrg-free-decay", record_s=3600.0, rate_dps=500.0)
    world = win.backend.station.world
    qtbot.waitUntil(lambda: (_panel_rate(win) or 0.0) > 400.0, timeout=WAIT_MS)  # the run's table readings
    qtbot.mouseClick(win.abort_button, Qt.MouseButton.LeftButton)
    assert "aborting" in win.status_line.text() and "9a6200" in win.status_line.styleSheet()  # amber
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.safe_state
    # the panel is refreshed from the devices after the safe state: at rest, drive off
    qtbot.waitUntil(lambda: _panel_rate(win) is not None and abs(_panel_rate(win)) < 0.1, timeout=WAIT_MS)
    qtbot.waitUntil(lambda: win.station.value("frontend", "drive") == "off", timeout=WAIT_MS)
    assert abs(world.case_rate_dps) < 0.1  # the simulator's own state agrees
    with world.lock:
        assert not np.any(world.total_force)
    handle = win.backend.station.handles["frontend"]
    model = getattr(handle, "model", None)
    if model is not None and hasattr(model, "channels"):
        assert not any(ch.output_on for ch in model.channels.values())
    frames = int(win.station.value("fpga", "frames"))
    assert frames > 0 and win.station.value("fpga", "lost") == "0" and win.station.value("fpga", "crc_errors") == "0"
    assert "9a6200" in win.status_line.styleSheet() and win.status_line.text().startswith("ABORTED")


def test_a_device_that_stops_answering_is_shown_down(window, qtbot):
    win = window
    qtbot.waitUntil(lambda: win.station.state("table") == "connected", timeout=WAIT_MS)
    win.backend.station.handles["table"].stop()  # the simulator goes away: the link is lost
    qtbot.waitUntil(lambda: (win.station.state("table") or "").startswith("DOWN"), timeout=WAIT_MS)
    assert win.station.value("table", "rate_dps") is None  # no stale reading


def test_colours_follow_the_outcome_and_a_long_error_wraps(window, qtbot):
    win = window
    run_ok = ev.RunFinished("r1", 1.0, outcome="COMPLETE", safe_state=True, end_reason="completed")
    win.on_events([run_ok])
    assert "1a6b1a" in win.status_line.styleSheet()  # green
    win.results.add("tau_s", 1.0, "s", None, None, "COMPLETE")
    reason = "device error: " + "x" * 2000
    win.on_events([ev.RunFinished("r2", 2.0, outcome="ERROR", safe_state=True, end_reason=reason)])
    qtbot.wait(50)
    assert "c00000" in win.status_line.styleSheet() and reason in win.status_line.text()  # red, with its reason
    assert win.results.table.item(0, win.results.HEADERS.index("outcome")).text() == "not confirmed (run ERROR)"
    assert win.width() <= 1280 and win.minimumSizeHint().width() <= 1280
    assert win.results.report_button.geometry().right() <= win.results.width()
    win.on_events([ev.RunFinished("r3", 3.0, outcome="MARGINAL", safe_state=True, end_reason="")])
    assert "9a6200" in win.status_line.styleSheet()


def test_pause_says_the_table_keeps_its_rate_and_close_asks_first(window, qtbot, monkeypatch):
    win = window
    win.station.speed.setCurrentText("max")
    _start(qtbot, win, "hrg-free-decay", record_s=3600.0)
    qtbot.waitUntil(lambda: win.steps.progress.value() > 0, timeout=WAIT_MS)
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    assert win.status_line.text() == "Paused \u2014 the table keeps its rate"
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    answers = []

    def answer(*_a, **_k):
        answers.append(1)
        return QMessageBox.StandardButton.No if len(answers) == 1 else QMessageBox.StandardButton.Yes

    monkeypatch.setattr(QMessageBox, "question", answer)
    del win.ask_close_during_run  # the fixture's always-yes answer off: this test asks the real question
    assert not win.close()  # "No": the window stays, the run goes on
    assert win.backend.running() and win.isVisible()
    assert win.close()  # "Yes": abort, wait for the safe state, close
    assert len(answers) == 2 and not win.backend.running()
    assert win.last_finished is not None and win.last_finished.outcome == "ABORTED" and win.last_finished.safe_state


def test_time_axes_start_at_the_run_and_the_run_shows_its_progress(window, qtbot):
    win = window
    win.station.speed.setCurrentText("max")
    win.backend.station.clock.sleep(50.0)  # the bench has been on for a while before this run
    _start(qtbot, win, "hrg-free-decay", record_s=5.0)
    qtbot.waitUntil(lambda: win.run_active and win.plots.fpga.total_rows > 500, timeout=WAIT_MS)
    t0 = win.run_t0_s
    assert t0 >= 50.0
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    win.plots.refresh(force=True)
    x, _ = win.plots.c_q[0].getData()
    assert 0.0 <= x[0] < 5.0 and x[-1] < win.t_sim_s - t0 + 1.0  # seconds since the run started
    assert win.run_id and win.run_id in win.run_info.text() and "elapsed" in win.run_info.text()
    assert win.run_progress.value() == 1000 and win.run_fraction() == 1.0
    for p in (win.plots.p_q, win.plots.p_e, win.plots.p_rate, win.plots.p_amp):
        assert p.getAxis("left").labelUnits  # units on every axis
    assert win.plots.p_e.getAxis("left").labelUnits == "1"  # E = cx^2+..: the square of the declared "1"
