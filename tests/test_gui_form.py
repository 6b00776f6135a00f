"""The parameter form in the window (offscreen): every parameter's label, unit and limits are
visible without scrolling sideways at the default window size, for every procedure of both
built-in stations, and a refused value's reason is shown right at its field."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402


@pytest.mark.parametrize("station", ["sim-hrg", "sim-mems"])
def test_form_fits_the_default_window_and_refusals_show_at_the_field(qtbot, tmp_path, monkeypatch, station):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend(station, seed=0)
    try:
        win = MainWindow(backend)
        qtbot.addWidget(win)
        win.show()
        qtbot.wait(50)
        default_w = win.width()
        assert default_w <= 1280
        scroll = win.left_scroll  # the form is in the left column, which scrolls as a whole
        assert scroll.widget().isAncestorOf(win.form)
        for name in backend.procedures():
            win.procedure.setCurrentText(name)
            qtbot.wait(20)
            # the form's minimum width fits the room the default window gives it: no sideways scroll
            assert win.form.minimumSizeHint().width() <= scroll.viewport().width(), name
            assert not scroll.horizontalScrollBar().isVisible(), name
            assert win.minimumSizeHint().width() <= default_w
            for param in win.form.specs:
                name = win.form.name_labels[param.name]  # the name is never clipped
                assert name.width() >= name.fontMetrics().horizontalAdvance(param.name), param.name
                hint = win.form.hints[param.name]
                assert param.limit_text() in hint.text()
                assert hint.width() <= scroll.viewport().width()
        win.procedure.setCurrentText("hrg-free-decay" if station == "sim-hrg" else "mems-sweep")
        spec = next(p for p in win.form.specs if p.high is not None and p.type is float)
        win.form.set_value(spec.name, str(spec.high * 10 + 1))
        error = win.form.field_errors[spec.name]
        assert error.isVisible() and "is above the limit" in error.text() and spec.name in error.text()
        assert not win.start_button.isEnabled()
        win.form.set_value(spec.name, str(spec.high))
        assert not error.isVisible()
    finally:
        backend.close()
