"""Open report / Raw file folder when an opener exists but opens nothing: its exit status, a failure
to start or no answer within the wait shows the path with a Copy button; exit status 0 shows nothing."""

from __future__ import annotations

import sys

import pytest

pytest.importorskip("pytestqt")


@pytest.fixture
def page(tmp_path):
    p = tmp_path / "report.html"
    p.write_text("<html></html>")
    return p


def _opener(monkeypatch, code: str) -> None:
    from bench.gui import open_report

    monkeypatch.setattr(open_report, "launcher_missing", lambda: None)
    monkeypatch.setattr(open_report, "opener_argv", lambda p: [sys.executable, "-c", code, str(p)])


def test_opener_exit_status_shows_the_path(qtbot, monkeypatch, page):
    from PySide6.QtGui import QGuiApplication

    from bench.gui import open_report

    _opener(monkeypatch, "import sys; sys.exit(3)")  # xdg-open's 'no application' status
    dialog = open_report.open_in_browser(page)
    qtbot.addWidget(dialog)
    qtbot.waitUntil(dialog.isVisible, timeout=20_000)
    assert "exited with status 3" in dialog.message.text()
    assert dialog.path.text() == str(page.resolve())
    dialog.copy_button.click()
    assert QGuiApplication.clipboard().text() == str(page.resolve())


def test_opener_that_does_not_answer_shows_the_path(qtbot, monkeypatch, page):
    from bench.gui import open_report

    monkeypatch.setattr(open_report, "OPENER_WAIT_S", 0.5)
    _opener(monkeypatch, "import time; time.sleep(60)")
    dialog = open_report.open_in_browser(page, what="raw file's folder", opener="a file manager")
    qtbot.addWidget(dialog)
    try:
        qtbot.waitUntil(dialog.isVisible, timeout=20_000)
        assert "did not answer within 0.5 s" in dialog.message.text()
        assert "file manager" in dialog.message.text()
    finally:
        dialog.process.kill()
        dialog.process.waitForFinished(5000)


def test_opener_that_opened_shows_nothing(qtbot, monkeypatch, page):
    from bench.gui import open_report

    _opener(monkeypatch, "pass")
    dialog = open_report.open_in_browser(page)
    qtbot.addWidget(dialog)
    qtbot.waitUntil(lambda: dialog.handed_over, timeout=20_000)
    assert not dialog.isVisible()


def test_opener_that_cannot_start_shows_the_path(qtbot, monkeypatch, page):
    from bench.gui import open_report

    monkeypatch.setattr(open_report, "launcher_missing", lambda: None)
    monkeypatch.setattr(open_report, "opener_argv", lambda p: ["/nonexistent/xdg-open", str(p)])
    dialog = open_report.open_in_browser(page)
    qtbot.addWidget(dialog)
    qtbot.waitUntil(dialog.isVisible, timeout=20_000)
    assert "could not be started" in dialog.message.text()
