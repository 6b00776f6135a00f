"""The operator station on a station with slots, live progress, and calibration (issue 32),
offscreen: scans fill the next empty slot (Enter alone leaves one empty), Start runs the batch
through `line run`'s batch path, each slot's verdict shows with its reason, one slot is retested
alone under the routing rules; the running step and its fraction come from the engine's events; a
station past its calibration or locked by its golden unit refuses with one message."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402

from bench.engine import events as ev  # noqa: E402
from bench.gui.unit_progress import UnitProgress  # noqa: E402

WAIT_MS = 300_000


def _scan(qtbot, win, text: str) -> None:
    """A keyboard-wedge scanner: the characters, then Enter."""
    if text:
        qtbot.keyClicks(win.serial_field, text)
    qtbot.keyClick(win.serial_field, Qt.Key.Key_Return)


def _answer_yes_until(qtbot, win, done) -> None:
    def step() -> bool:
        if win.waiting():
            win.yes_button.click()
        return done()

    qtbot.waitUntil(step, timeout=WAIT_MS)


def _open(qtbot, station: str, sequence: str, runs: Path):
    from bench.gui.operator_station import OperatorStation

    win = OperatorStation(station, sequence=sequence, runs_dir=str(runs), seed=0)
    qtbot.addWidget(win)
    win.show()
    return win


def test_progress_follows_the_engine_events():
    p = UnitProgress(2)
    assert p.fraction == 0.0 and p.text == ""
    p.apply(ev.RunStarted("r1", 0.0, procedure="mems-sweep", steps=("a", "b")))
    p.apply(ev.StepStarted("r1", 0.0, name="b", index=1, total=2, title="Sweep up"))
    p.apply(ev.Progress("r1", 1.0, fraction=0.5))
    assert p.fraction == pytest.approx((0 + (1 + 0.5) / 2) / 2)  # 0.375
    assert p.text == "step 1/2 mems-sweep: Sweep up"
    p.apply(ev.RunFinished("r1", 2.0))
    assert p.fraction == pytest.approx(0.5)
    p.apply(ev.RunStarted("r2", 2.0, procedure="hrg-damping", steps=("x",)))
    p.apply(ev.Progress("r2", 3.0, fraction=2.0))  # clipped to the step
    assert p.fraction == pytest.approx(1.0) and p.text == "step 2/2 hrg-damping"
    p.apply(ev.RunFinished("r2", 4.0))
    assert p.finished and p.fraction == 1.0
    cut = UnitProgress(1)  # a run that ends in ERROR keeps the fraction it reached
    cut.apply(ev.RunStarted("r3", 0.0, procedure="mems-sweep", steps=("a", "b")))
    cut.apply(ev.StepStarted("r3", 0.0, name="a", index=0, total=2))
    cut.apply(ev.Progress("r3", 1.0, fraction=0.5))
    cut.apply(ev.RunFinished("r3", 1.0, outcome="ERROR"))
    assert cut.fraction == pytest.approx(0.25)


def test_slots_one_empty_verdicts_and_a_retest_of_one_slot(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    win = _open(qtbot, "sim-mems-4", "ci-mems", tmp_path / "runs")
    assert set(win.slots) == {1, 2, 3, 4} and not win.verdict.isVisible()
    assert "calibration:" in win.calib.text() and "golden unit: not locked" in win.calib.text()
    win.operator.setEditText("Ada L")
    assert win.log_in()
    for text in ("ln-1001", "", "ln-1003", "LN-1001"):  # slot 2 left empty; a serial twice is refused
        _scan(qtbot, win, text)
    assert "already in slot 1" in win.message.text()
    win.serial_field.clear()
    _scan(qtbot, win, "LN-1004")
    assert {n: (p.serial, p.outcome) for n, p in win.slots.items()} == {
        1: ("LN-1001", "PLACED"), 2: (None, "NOT FITTED"), 3: ("LN-1003", "PLACED"), 4: ("LN-1004", "PLACED")}
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)
    _answer_yes_until(qtbot, win, lambda: bool(win.batches_done))
    win._show_progress()
    assert win.batches_done == [{1: "PASS", 3: "PASS", 4: "PASS"}]
    for n in (1, 3, 4):
        panel = win.slots[n]
        assert panel.outcome == "PASS" and "attempt 1: PASS: 3 limit(s) met" in panel.reason.text()
        assert panel.step.text() == "step 1/1 mems-sweep" and panel.bar.value() == 1000
    assert win.slots[2].outcome == "NOT FITTED" and win.slots[2].bar.value() == 0
    recs = {r["serial"]: r for r in win.records}
    assert sorted(recs) == ["LN-1001", "LN-1003", "LN-1004"] and recs["LN-1003"]["slot"] == 3
    assert recs["LN-1003"]["batch"]["not_fitted"] == [2] and recs["LN-1003"]["operator"] == "Ada L"
    on_disk = json.loads(Path(recs["LN-1004"]["record_file"]).read_text())
    assert on_disk["batch"]["serials"] == {"1": "LN-1001", "3": "LN-1003", "4": "LN-1004"}
    # a PASS unit retested without a reason: the line's routing refuses it, the other slots untouched
    assert win.retest_slot(3)
    qtbot.waitUntil(lambda: len(win.batches_done) == 2, timeout=WAIT_MS)
    assert win.slots[3].outcome == "NOT RUN" and "needs --retest-reason" in win.slots[3].reason.text()
    assert win.slots[1].outcome == "PASS" and win.slots[4].outcome == "PASS"
    # with a reason: slot 3 alone, its second attempt recorded as a retest
    win.retest_kind.setCurrentText("retest reason")
    win.retest.setText("fixture reseated")
    assert win.retest_slot(3)
    _answer_yes_until(qtbot, win, lambda: len(win.batches_done) == 3)
    assert win.batches_done[-1] == {3: "PASS"} and "attempt 2 (retest)" in win.slots[3].reason.text()
    last = win.records[-1]
    assert last["serial"] == "LN-1003" and last["attempt"] == 2
    assert last["routing"] == {"prior_attempts": 1, "rework": None, "retest_reason": "fixture reseated",
                               "last_outcome": "PASS"}
    assert last["batch"]["serials"] == {"3": "LN-1003"} and last["batch"]["retest_alone"] is True
    assert last["batch"]["not_fitted"] == [2]
    from bench.line.routing import history

    attempts = history(win.session.ctx.db, win.session.ctx.runs_dir, "LN-1003")
    assert [(r["attempt"], r["outcome"]) for r in attempts] == [(1, "PASS"), (2, "PASS")]
    # the next scan empties the slots for the next batch
    _scan(qtbot, win, "LN-2001")
    assert win.slots[1].serial == "LN-2001" and win.slots[3].serial is None and win.slots[2].outcome == "EMPTY"
    win.close()


def test_one_unit_shows_its_step_and_progress(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    win = _open(qtbot, "sim-hrg", "ci-spin", tmp_path / "runs")
    win.operator.setEditText("Ada L")
    assert win.log_in() and not win.slots and win.bar.value() == 0
    _scan(qtbot, win, "LN-0001")
    _answer_yes_until(qtbot, win, lambda: bool(win.units_done))
    win._show_progress()
    assert win.units_done == [("LN-0001", "PASS")]
    assert win.step_label.text() == "step 1/1 table-spin" and win.bar.value() == 1000
    win.close()


def _station_file(tmp_path: Path, base: str, extra: str) -> str:
    from bench.station_config import find_station_file

    path = tmp_path / f"{base}-cal.toml"
    path.write_text(find_station_file(base).read_text() + extra)
    return str(path)


def test_a_station_past_its_calibration_refuses_to_run_with_one_message(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    st = _station_file(tmp_path, "sim-hrg", "\n[calibration]\ntable = 2020-01-31\nfrontend = 2099-01-01\n")
    win = _open(qtbot, st, "ci-spin", tmp_path / "runs")
    assert "table due 2020-01-31, frontend due 2099-01-01" in win.calib.text()
    assert "#c62020" in win.calib.styleSheet()  # shown red at login
    win.operator.setEditText("Ada L")
    assert win.log_in() and "calibration past due: table (due 2020-01-31" in win.message.text()
    _scan(qtbot, win, "LN-0001")
    assert win.verdict.text() == "REFUSED" and not win.busy() and not win.waiting()
    assert win.message.text() == ""  # one message: under the verdict
    assert win.reason.text().startswith("station 'sim-hrg' refuses line runs: calibration past due: table")
    assert not list((tmp_path / "runs").glob("line/*/*.json"))  # nothing ran, nothing recorded
    from bench.line import LineError

    with pytest.raises(LineError, match="calibration past due"):  # the model refuses too
        win.session.run_serial("LN-0001", None)
    win.close()


def test_a_locked_station_with_slots_refuses_the_batch(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from bench.line.station_state import lock, unlock

    runs = tmp_path / "runs"
    lock(runs, "sim-mems-4", "golden unit MEMS-GOLD-01: f0 drifted +3 Hz (limit 1)")
    win = _open(qtbot, "sim-mems-4", "ci-mems", runs)
    assert "golden unit: LOCKED since" in win.calib.text() and "f0 drifted +3 Hz" in win.calib.text()
    win.operator.setEditText("Ada L")
    assert win.log_in()
    _scan(qtbot, win, "LN-3001")
    assert not win.start_batch() and not win.busy()
    assert "refuses line runs: locked since" in win.message.text()
    assert win.slots[1].outcome == "REFUSED" and win.slots[1].reason.text() == win.message.text()
    unlock(runs, "sim-mems-4", "front end replaced", "Ada L")  # unlocked: the calibration line says so
    assert win.refused() is False and "golden unit: not locked" in win.calib.text()
    win.close()


def test_operators_table_with_a_boolean_active_column_on_postgresql(pg_url):
    """PostgreSQL refused `boolean = integer` when the login listed the active operators."""
    from sqlalchemy import text

    from bench.gui.line_station import known_operators
    from bench.line.db import LineDB

    db = LineDB(pg_url)
    try:
        with db.engine.begin() as conn:
            conn.execute(text("CREATE TABLE operators (name VARCHAR(64), active BOOLEAN)"))
            conn.execute(text("INSERT INTO operators VALUES ('Grace H', TRUE), ('Gone G', FALSE), ('Ada L', NULL)"))
        assert known_operators(db) == ["Grace H"]
    finally:
        db.close()


def test_the_operator_station_opens_on_a_sequence_its_station_can_run():
    """`gui --operator --station sim-hrg-4` used to open on ci-spin, which a station with slots
    refuses (its steps do not say which devices they use): it opens on one that runs there."""
    from bench.gui.line_station import default_sequence

    assert default_sequence("sim-hrg") == "ci-spin"
    assert default_sequence("sim-hrg-4") == "eol-hrg"
    assert default_sequence("sim-mems-4") == "ci-mems"
