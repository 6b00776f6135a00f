"""The window's DUT serial and operator fields (offscreen): a keyboard-wedge scan (typed text and
Enter) is normalised and remembered between runs; a window run is stored with its DUT and
operator, so the history's DUT filter finds it."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QSettings, Qt  # noqa: E402

from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402

WAIT_MS = 60_000


@pytest.fixture
def settings_dir(tmp_path):
    """QSettings in this test's own folder (conftest keeps the session's apart from the user's)."""
    path = tmp_path / "settings"
    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, str(path))
    yield path
    QSettings("gyrobench", "window").clear()


def test_scanner_input_is_normalised_and_remembered(qtbot, settings_dir):
    from bench.gui.unit_fields import UnitFields

    fields = UnitFields()
    qtbot.addWidget(fields)
    assert fields.dut.text() == ""
    with qtbot.waitSignal(fields.scanned, timeout=2000) as got:
        qtbot.keyClicks(fields.dut, " hrg-0042 ")  # what a wedge scanner types ...
        qtbot.keyClick(fields.dut, Qt.Key.Key_Return)  # ... and its Enter
    assert got.args == ["HRG-0042"]
    assert fields.dut.text() == "HRG-0042"
    qtbot.keyClicks(fields.operator, "Ada L")
    fields.remember()
    again = UnitFields()  # the next start of the window
    qtbot.addWidget(again)
    assert (again.dut.text(), again.operator.text()) == ("HRG-0042", "Ada L")
    again.dut.setText("bad serial\x1b[31m")
    qtbot.keyClick(again.dut, Qt.Key.Key_Return)
    assert "serial" in again.error.text()  # refused, saying why
    with pytest.raises(ValueError):
        again.checked()


def test_window_run_is_stored_with_its_dut_and_operator(qtbot, tmp_path, monkeypatch, settings_dir):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.ask_close_during_run = lambda: True
    qtbot.addWidget(win)
    try:
        win.station.speed.setCurrentText("max")
        qtbot.keyClicks(win.unit.dut, "sn-7")
        qtbot.keyClick(win.unit.dut, Qt.Key.Key_Return)
        win.unit.operator.setText("Grace H")
        win.procedure.setCurrentText("table-spin")
        win.form.set_value("rate_dps", 20.0)
        win.form.set_value("hold_s", 0.2)
        qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
        assert backend.join(60)
        assert "DUT SN-7, operator Grace H" in win.log.toPlainText()
        from bench.results.query import RunFilter, find_runs

        rows, _n = find_runs(backend.runner.store, RunFilter(dut="SN-7"))
        assert [r["run_id"] for r in rows] == [win.last_finished.run_id]
        assert rows[0]["duts"] == "SN-7"
        assert backend.runner.store.get_run(rows[0]["run_id"])["operator"] == "Grace H"
        assert QSettings("gyrobench", "window").value("dut") == "SN-7"
    finally:
        backend.close()


def test_the_engines_safe_state_report_shows_at_once(qtbot, tmp_path, monkeypatch, settings_dir):
    """The engine logs its safe-state report before it closes the run's files and says RunFinished:
    the window shows the confirmation from that report, not from RunFinished."""
    from bench.engine import events as ev

    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    qtbot.addWidget(win)
    try:
        win.run_active, win.aborting = True, True  # as after Abort, before the engine has finished
        win.on_events([ev.Log("r1", 12.0, level="INFO", message="safe state confirmed: {'table': 'rest'}")])
        assert win.safe_label.text() == "safe state confirmed"
        assert win.status_line.text().startswith("aborted: safe state confirmed")
        win.on_events([ev.Log("r1", 12.0, level="ERROR", message="safe state NOT confirmed: {} errors {'t': 'x'}")])
        assert win.safe_label.text() == "SAFE STATE NOT CONFIRMED"
    finally:
        win.run_active = False
        backend.close()
