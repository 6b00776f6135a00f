"""The line operator's window (bench/gui/operator_view.py), offscreen, driven against short runs
on the simulated station: scan (a bad serial refused), fixture and spin confirmations, the big
verdict, the next unit's prompt; a step that cannot start is the unit's ERROR; the Operator
interface from a worker thread.  With GYROBENCH_DOCS_SCREENSHOTS=1, docs/window_operator.png."""

from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import Qt  # noqa: E402

from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.operator_view import OperatorView, worst  # noqa: E402

DOCS = Path(__file__).resolve().parent.parent / "docs"


@pytest.fixture
def view(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    v = OperatorView(backend, [("table-spin", {"rate_dps": 50.0, "hold_s": 0.5})], operator_name="ada")
    qtbot.addWidget(v)
    v.show()
    yield v
    backend.join(60)
    backend.close()


def _scan(qtbot, v: OperatorView, text: str) -> None:
    v.serial_field.clear()
    qtbot.keyClicks(v.serial_field, text)
    qtbot.keyClick(v.serial_field, Qt.Key.Key_Return)


def test_operator_tests_a_unit_and_is_asked_for_the_next(view, qtbot, tmp_path):
    v = view
    assert v.verdict.text() == "READY" and v.serial_field.isEnabled() and not v.fixture_button.isEnabled()
    _scan(qtbot, v, "x!")
    assert "is not valid" in v.message.text() and not v.fixture_button.isEnabled()
    _scan(qtbot, v, "hrg-2611-0042")
    assert v.serial == "HRG-2611-0042" and v.fixture_button.isEnabled() and not v.spin_button.isEnabled()
    qtbot.mouseClick(v.fixture_button, Qt.MouseButton.LeftButton)
    assert v.spin_button.isEnabled() and "table spins" in v.prompt.text()  # table-spin needs the table
    with qtbot.waitSignal(v.unit_finished, timeout=120_000) as sig:
        qtbot.mouseClick(v.spin_button, Qt.MouseButton.LeftButton)
        assert v.verdict.text() == "RUNNING"
    assert sig.args == ["HRG-2611-0042", "PASS"]
    assert v.verdict.text() == "PASS" and "green" not in v.verdict.styleSheet() and "#1e8c1e" in v.verdict.styleSheet()
    assert v.unit_label.text() == "HRG-2611-0042" and v.summary.text() == "table-spin PASS"
    assert v.prompt.text() == "Next unit: scan its serial" and v.serial_field.isEnabled()
    assert v.backend.runner.duts == ["HRG-2611-0042"] and v.backend.runner.operator == "ada"
    if os.environ.get("GYROBENCH_DOCS_SCREENSHOTS") == "1":
        shot = tmp_path / "window_operator.png"
        assert v.grab().save(str(shot), "PNG")
        shutil.copy(shot, DOCS / "window_operator.png")
    # the next unit: a step the station refuses (above the table's limit) is its ERROR, said once
    v.steps = [("table-spin", {"rate_dps": 900.0, "hold_s": 0.5, "accel_dps2": 5000.0})]
    _scan(qtbot, v, "HRG-2611-0043")
    qtbot.mouseClick(v.fixture_button, Qt.MouseButton.LeftButton)
    with qtbot.waitSignal(v.unit_finished, timeout=60_000) as sig:
        qtbot.mouseClick(v.spin_button, Qt.MouseButton.LeftButton)
    assert sig.args == ["HRG-2611-0043", "ERROR"] and v.verdict.text() == "ERROR"
    assert "did not start" in v.summary.text() and v.units_done[-1] == ("HRG-2611-0043", "ERROR")


def test_gui_operator_answers_a_sequence_in_another_thread(view, qtbot):
    v = view
    op = v.operator()
    answers: dict = {}

    def sequence() -> None:
        answers["serial"] = op.scan_serial()
        answers["fixture"] = op.confirm("Is the unit in the fixture?")
        op.show_outcome(answers["serial"], "MARGINAL", "drift straddles its limit")
        answers["done"] = True

    t = threading.Thread(target=sequence, daemon=True)
    t.start()
    qtbot.waitUntil(lambda: v.waiting() == "serial", timeout=5000)
    assert v.prompt.text() == "Scan the unit's serial"
    _scan(qtbot, v, "u-77")
    qtbot.waitUntil(lambda: v.waiting() == "confirm", timeout=5000)
    assert v.fixture_button.text() == "Is the unit in the fixture?" and v.fixture_button.isEnabled()
    qtbot.mouseClick(v.fixture_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: answers.get("done", False), timeout=5000)
    t.join(5)
    assert answers == {"serial": "U-77", "fixture": True, "done": True}
    assert v.verdict.text() == "MARGINAL" and v.unit_label.text() == "U-77"
    assert v.fixture_button.text() == "Unit is in the fixture, clamped and connected"


def test_worst_outcome():
    assert worst(["PASS", "MARGINAL", "PASS"]) == "MARGINAL"
    assert worst(["PASS", "FAIL"]) == "FAIL" and worst([]) == "ERROR" and worst(["COMPLETE"]) == "COMPLETE"
