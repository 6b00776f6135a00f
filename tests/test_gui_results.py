"""The results table (offscreen): value, 95 % interval, limits, outcome and the simulated truth,
a NOT_MEASURED row said in words (never "nan"), the table as tall as its rows; and after a real
run on the simulated station the truth column holds the simulator's own values."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import Qt  # noqa: E402

from bench.gui.panels import ResultsTable  # noqa: E402


def _row(table: ResultsTable, r: int) -> dict[str, str]:
    return {h: table.table.item(r, c).text() for c, h in enumerate(table.HEADERS)}


def test_columns_not_measured_and_height(qtbot):
    t = ResultsTable()
    qtbot.addWidget(t)
    t.show()
    t.set_truth({"tau_s": 300.0, "D": 1.6e-4})
    h0 = t.table.height()
    t.add("tau_s", 299.9, "s", 250.0, 350.0, "PASS", ci95=(299.5, 300.3))
    t.add("D", math.nan, "1/s", None, 1e-3, "NOT_MEASURED")
    t.add("theta_tau_deg", 20.2, "deg", None, None, "COMPLETE", ci95=(20.1, 20.3), truth=20.0)
    assert t.HEADERS == ("measurement", "value", "95% interval", "unit", "limits", "outcome", "truth")
    assert _row(t, 0) == {"measurement": "tau_s", "value": "299.9", "95% interval": "[299.5, 300.3]", "unit": "s",
                          "limits": "250 to 350", "outcome": "PASS", "truth": "300 (in the interval)"}
    row = _row(t, 1)
    assert row["value"] == "not measured" and row["outcome"] == "NOT MEASURED" and row["limits"] == "<= 0.001"
    assert "nan" not in " ".join(row.values()).lower()
    assert _row(t, 2)["truth"] == "20 (OUTSIDE the interval)"
    assert t.table.height() > h0
    rows = sum(t.table.rowHeight(r) for r in range(3))
    assert t.table.height() >= rows + t.table.horizontalHeader().height()
    assert t.table.height() <= rows + t.table.horizontalHeader().height() + 40  # no empty rows' worth below
    assert t.table.verticalScrollBar().maximum() == 0  # every row shown


def test_truth_column_after_a_run_on_the_simulated_station(qtbot, tmp_path, monkeypatch):
    from bench.gui.engine_backend import EngineBackend
    from bench.gui.main_window import MainWindow

    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    try:
        win = MainWindow(backend)
        qtbot.addWidget(win)
        win.show()
        win.procedure.setCurrentText("hrg-free-decay")
        win.form.set_value("record_s", "20")
        qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: win.last_finished is not None, timeout=120_000)
        t = win.results
        rows = [_row(t, r) for r in range(t.table.rowCount())]
        assert rows and all(r["value"] != "nan" for r in rows)
        from procedures import measurement_truth

        truth = measurement_truth("hrg-free-decay", backend.station.truth())
        with_truth = [r for r in rows if r["truth"]]
        assert with_truth and all(float(r["truth"].split()[0]) == pytest.approx(truth[r["measurement"]], rel=1e-5)
                                  for r in with_truth)
        assert any(r["95% interval"] for r in rows)
    finally:
        backend.close()
