"""The window's log (offscreen): levels in colour, a level filter that hides and brings back
lines, and it follows the newest line until the operator scrolls up to read."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from bench.gui.log_view import LogPane  # noqa: E402


def test_levels_in_colour_filter_and_follow(qtbot):
    log = LogPane()
    qtbot.addWidget(log)
    log.resize(600, 200)
    log.show()
    log.add(1.0, "DEBUG", "a debug line")
    log.add(2.0, "INFO", "an info line")
    log.add(3.0, "WARNING", "a warning line")
    log.add(4.0, "ERROR", "an error line")
    assert log.lines()[0].split() == ["2.000", "INFO", "an", "info", "line"]  # INFO and above by default
    doc = log.text.document().toHtml()
    assert "#c00000" in doc and "#9a6200" in doc  # ERROR red, WARNING amber
    log.level.setCurrentIndex(log.level.findData("WARNING"))
    assert [line.split()[1] for line in log.lines()] == ["WARNING", "ERROR"]
    log.level.setCurrentIndex(log.level.findData("DEBUG"))
    assert len(log.lines()) == 4  # hidden lines were kept
    for k in range(300):
        log.add(5.0 + k, "INFO", f"line {k}")
    bar = log.text.verticalScrollBar()
    assert bar.maximum() > 0 and bar.value() == bar.maximum()  # follows the newest line
    bar.setValue(0)  # the operator scrolls up to read
    assert not log.follow.isChecked()
    log.add(999.0, "INFO", "newer")
    assert bar.value() == 0  # not pulled away from what is being read
    log.follow.setChecked(True)
    assert bar.value() == bar.maximum() and log.lines()[-1].endswith("newer")
