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
    assert _row(t, 0) == {"measurement": "tau_s", "value": "299.90", "95% interval": "[299.50, 300.30]", "unit": "s",
                          "limits": "[250, 350]", "outcome": "PASS", "truth": "300.00 (in the interval)"}
    row = _row(t, 1)
    assert row["value"] == "not measured" and row["outcome"] == "NOT MEASURED" and row["limits"] == "≤ 0.001"
    assert "nan" not in " ".join(row.values()).lower()
    assert _row(t, 2)["truth"] == "20.000 (OUTSIDE the interval)"
    assert t.table.height() > h0
    rows = sum(t.table.rowHeight(r) for r in range(3))
    assert t.table.height() >= rows + t.table.horizontalHeader().height()
    assert t.table.height() <= rows + t.table.horizontalHeader().height() + 40  # no empty rows' worth below
    assert t.table.verticalScrollBar().maximum() == 0  # every row shown


def test_values_follow_the_reports_digit_rule(qtbot):
    """The issue's rows: no '5.18363e+06 [5.18362e+06, 5.18363e+06]' or '300 [300, 300]'."""
    from bench.numbers import with_interval

    t = ResultsTable()
    qtbot.addWidget(t)
    t.add("Q", 5183627.4, "1", None, None, "COMPLETE", ci95=(5183620.1, 5183634.9))
    t.add("tau_s", 300.00123, "s", None, None, "COMPLETE", ci95=(299.99987, 300.00259))
    t.add("arw_deg_rth", 0.0123456, "deg/rt(h)", None, None, "COMPLETE")  # no interval: 4 significant digits
    t.add("theta_tau_deg", 89.9, "deg", None, None, "COMPLETE", ci95=(89.7, 90.1), truth=0.05)
    t.periods = {"theta_tau_deg": 90.0}
    assert (_row(t, 0)["value"], _row(t, 0)["95% interval"]) == with_interval(5183627.4, (5183620.1, 5183634.9))
    assert _row(t, 0)["value"] == "5.1836274e6"  # the report writes it so too
    assert (_row(t, 1)["value"], _row(t, 1)["95% interval"]) == ("300.0012", "[299.9999, 300.0026]")
    assert (_row(t, 2)["value"], _row(t, 2)["95% interval"]) == ("0.01235", "")
    t.add("theta_tau_deg", 89.9, "deg", None, None, "COMPLETE", ci95=(89.7, 90.1), truth=0.05)
    assert _row(t, 4)["truth"] == "0.05 (in the interval)"  # 0.05 deg is 90.05 deg on the axis


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
        assert with_truth
        for r in with_truth:  # the simulator's value, at the measured value's precision (the report's rule)
            text = r["truth"].split()[0].replace("\u2212", "-")
            mant = text.partition("e")[0]
            decimals = len(mant.partition(".")[2])
            scale = 10.0 ** int(text.partition("e")[2] or 0)
            assert float(text) == pytest.approx(truth[r["measurement"]], abs=0.51 * 10.0 ** -decimals * scale), r
        assert any(r["95% interval"] for r in rows)
    finally:
        backend.close()


def test_a_measurement_compared_with_no_truth_says_why_on_a_simulated_station(qtbot):
    """hrg-damping's mean drift has no truth one record can be held to (docs/damping_drift.md): its
    truth cell says "not compared" with the reason as its tooltip, as the report does; on a real
    bench (no truths) the cell stays empty."""
    from procedures import no_truth_reasons

    reasons = no_truth_reasons("hrg-damping")
    t = ResultsTable()
    qtbot.addWidget(t)
    t.set_truth({"drift_before_dph": 29.8}, {}, reasons)
    t.add("drift_before_mean_dph", -0.0066, "deg/h", None, None, "COMPLETE", ci95=(-0.017, 0.004))
    cell = t.table.item(0, t.HEADERS.index("truth"))
    assert cell.text() == "not compared" and cell.toolTip() == reasons["drift_before_mean_dph"]
    t.set_truth({}, {}, reasons)  # a real bench
    t.add("drift_before_mean_dph", -0.0066, "deg/h", None, None, "COMPLETE", ci95=(-0.017, 0.004))
    assert t.table.item(1, t.HEADERS.index("truth")).text() == ""
