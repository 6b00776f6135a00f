"""The operator station (offscreen): log in (a typed name only where the station allows it; the
line database's operators table otherwise), a scanned serial runs the line sequence through
bench.line (a unit record, a certificate, a line database row), the verdict shows large with its
reason, then the next serial is asked for."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402

WAIT_MS = 120_000


def _wait(qtbot, win, cond) -> None:
    """qtbot.waitUntil(cond), and on a timeout what the window showed and where the unit's thread was."""
    import sys
    import traceback

    from pytestqt.exceptions import TimeoutError as QtTimeout

    try:
        qtbot.waitUntil(cond, timeout=WAIT_MS)
    except QtTimeout:
        th = getattr(win, "_thread", None)
        frame = sys._current_frames().get(th.ident) if th is not None and th.is_alive() else None
        where = "".join(traceback.format_stack(frame)) if frame is not None else "no unit thread alive"
        raise AssertionError(f"{WAIT_MS / 1000:g} s: verdict {win.verdict.text()!r}, reason {win.reason.text()!r}, "
                             f"prompt {win.prompt.text()!r}, message {win.message.text()!r}, waiting "
                             f"{win.waiting()}, units done {win.units_done}; the unit's thread:\n{where}") from None


@pytest.fixture
def station(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from bench.gui.operator_station import OperatorStation

    win = OperatorStation("sim-hrg", sequence="ci-spin", runs_dir=str(tmp_path / "runs"), seed=0)
    qtbot.addWidget(win)
    win.show()
    yield win
    win.close()


def test_a_scanned_unit_runs_the_line_sequence_and_is_recorded(station, qtbot, tmp_path):
    win = station
    assert win.verdict.text() == "LOG IN" and not win.serial_field.isEnabled()
    assert win.operator.isEditable()  # no operators table, a simulated station: a typed name
    win.operator.setEditText("Ada L")
    qtbot.mouseClick(win.login_button, Qt.MouseButton.LeftButton)
    assert win.verdict.text() == "READY" and win.serial_field.isEnabled()
    qtbot.keyClicks(win.serial_field, "ln-0001")  # a keyboard-wedge scanner: the serial, then Enter
    qtbot.keyClick(win.serial_field, Qt.Key.Key_Return)
    for _ in range(2):  # the fixture, then the table spin
        _wait(qtbot, win, win.waiting)
        qtbot.mouseClick(win.yes_button, Qt.MouseButton.LeftButton)
    _wait(qtbot, win, lambda: bool(win.units_done))
    assert win.units_done == [("LN-0001", "PASS")]
    assert win.verdict.text() == "PASS" and "limit(s) met" in win.reason.text()
    rec = win.records[-1]
    assert rec["serial"] == "LN-0001" and rec["operator"] == "Ada L" and rec["sequence"] == "ci-spin"
    from pathlib import Path

    assert Path(rec["record_file"]).exists()
    assert rec["documents"] and all(Path(p).exists() for p in rec["documents"].values())
    assert "certificate" in win.files.text()
    from bench.line.routing import history

    assert [r["outcome"] for r in history(win.session.ctx.db, win.session.ctx.runs_dir, "LN-0001")][-1] == "PASS"
    assert win.serial_field.isEnabled() and "Next unit" in win.prompt.text()  # the next serial


def test_no_fixture_means_no_run(station, qtbot):
    win = station
    win.operator.setEditText("Ada L")
    assert win.log_in()
    qtbot.keyClicks(win.serial_field, "LN-0002")
    qtbot.keyClick(win.serial_field, Qt.Key.Key_Return)
    _wait(qtbot, win, win.waiting)
    qtbot.mouseClick(win.no_button, Qt.MouseButton.LeftButton)
    _wait(qtbot, win, lambda: bool(win.units_done))
    assert win.verdict.text() == "NOT RUN" and "fixture was not confirmed" in win.reason.text()


def test_login_refuses_typed_names_where_the_station_does_not_allow_them(station, monkeypatch):
    win = station
    win.session.free_text = False
    win.operator.setEditText("Ada L")
    assert not win.log_in() and "takes operators from the line database" in win.message.text()


def test_login_from_the_operators_table(station, tmp_path):
    from sqlalchemy import text

    win = station
    with win.session.db.engine.begin() as conn:
        conn.execute(text("CREATE TABLE operators (name TEXT, active INTEGER)"))
        conn.execute(text("INSERT INTO operators VALUES ('Grace H', 1), ('Gone G', 0)"))
    win._open_session()
    assert not win.operator.isEditable()
    assert [win.operator.itemText(i) for i in range(win.operator.count())] == ["Grace H"]
    assert win.log_in() and "Grace H" in win.who.text()
    with pytest.raises(ValueError, match="not in the line database's operators table"):
        win.session.log_in("Mallory")


def test_a_retest_after_fail_needs_a_rework_code(station, qtbot):
    """The line's routing, from the window: a FAIL unit is not retested without a rework code."""
    win = station
    win.operator.setEditText("Ada L")
    assert win.log_in()
    from bench.line.record import now_iso

    ctx = win.session.ctx
    ctx.db.save({"schema_version": 1, "serial": "LN-0003", "attempt": 1, "lot": "", "station": "sim-hrg",
                 "operator": "Ada L", "sequence": "ci-spin", "product": "ci-spin", "started_at": now_iso(),
                 "ended_at": now_iso(), "outcome": "FAIL", "measurements": [], "runs": []})
    qtbot.keyClicks(win.serial_field, "LN-0003")
    qtbot.keyClick(win.serial_field, Qt.Key.Key_Return)
    _wait(qtbot, win, lambda: bool(win.units_done))
    assert win.verdict.text() == "NOT RUN" and "needs --rework CODE" in win.reason.text()
    win.retest.setText("RW-12")
    qtbot.keyClicks(win.serial_field, "LN-0003")
    qtbot.keyClick(win.serial_field, Qt.Key.Key_Return)
    for _ in range(2):
        _wait(qtbot, win, win.waiting)
        qtbot.mouseClick(win.yes_button, Qt.MouseButton.LeftButton)
    _wait(qtbot, win, lambda: len(win.units_done) == 2)
    assert win.records[-1]["routing"]["rework"] == "RW-12" and win.verdict.text() == "PASS"


def test_operator_station_screenshot_from_the_command_line(tmp_path, monkeypatch, qapp, capsys):
    """`gyrobench gui --operator --screenshot FILE`: a demonstration unit through ci-spin, headless."""
    monkeypatch.chdir(tmp_path)
    from bench.cli import main

    png = tmp_path / "op.png"
    assert main(["gui", "--operator", "--runs-dir", str(tmp_path / "runs"), "--screenshot", str(png)]) == 0
    assert "unit ('DEMO-0001', 'PASS')" in capsys.readouterr().out
    assert png.stat().st_size > 5_000
    assert list((tmp_path / "runs" / "line" / "no-lot").glob("DEMO-0001-a1*.json"))
