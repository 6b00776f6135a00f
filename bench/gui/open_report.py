"""A run's report: rendered beside its raw file when not yet there (or older than the file), and
opened in the system's browser; where no browser can be started (a server, Xvfb, CI) the window
says so with the file's path and a Copy button, instead of a line on stderr nobody reads."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path
from typing import Any

from PySide6.QtCore import QProcess, QTimer, QUrl
from PySide6.QtGui import QDesktopServices, QGuiApplication
from PySide6.QtWidgets import QDialog, QHBoxLayout, QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget


def ensure_report(raw_file: str | Path, row: dict[str, Any] | None = None) -> Path:
    """The HTML report of a run (`<raw>.html`), rendered now when missing or older than the raw file."""
    from bench.reporting import write_report

    raw = Path(raw_file)
    out = raw.with_suffix(".html")
    if out.exists() and out.stat().st_mtime >= raw.stat().st_mtime:
        return out
    return write_report(raw, row, out)[0]


OPENER_WAIT_S = 3.0  # an opener that has not answered by then has not opened anything we can see


def opener_argv(path: str | Path) -> list[str] | None:
    """The command that opens `path` with the desktop's handler, watched for its exit status
    (Linux: xdg-open); None where Qt's own call is used."""
    if sys.platform.startswith("linux") and shutil.which("xdg-open") is not None:
        return ["xdg-open", str(path)]
    return None


def launcher_missing() -> str | None:
    """Why no browser can be started here (None when one may be): on Linux Qt needs xdg-open."""
    if sys.platform.startswith("linux") and shutil.which("xdg-open") is None:
        return "no launcher (xdg-open) is installed"
    return None


class NoBrowserDialog(QDialog):
    """Says that the report could not be opened, with its path to copy."""

    def __init__(self, path: str | Path, why: str, parent: QWidget | None = None, *, what: str = "report",
                 opener: str = "a browser") -> None:
        super().__init__(parent)
        self.handed_over = False  # the opener said it opened the file (exit status 0)
        self.process: QProcess | None = None
        self.setWindowTitle(f"gyrobench - {what}")
        self.setObjectName("no_browser")
        lay = QVBoxLayout(self)
        self.message = QLabel(f"The {what} could not be opened in {opener}: {why}.\n"
                              f"Its path, to open yourself:")
        self.message.setWordWrap(True)
        lay.addWidget(self.message)
        row = QHBoxLayout()
        self.path = QLineEdit(str(path))
        self.path.setReadOnly(True)
        self.path.setMinimumWidth(420)
        row.addWidget(self.path, 1)
        self.copy_button = QPushButton("Copy")
        self.copy_button.clicked.connect(self.copy)
        row.addWidget(self.copy_button)
        lay.addLayout(row)
        close = QPushButton("Close")
        close.clicked.connect(self.accept)
        lay.addWidget(close)

    def copy(self) -> None:
        QGuiApplication.clipboard().setText(self.path.text())
        self.copy_button.setText("Copied")


def open_in_browser(path: str | Path, parent: QWidget | None = None, *, what: str = "report",
                    opener: str = "a browser") -> NoBrowserDialog | None:
    """Open a file (or a folder) with the system's handler; None when handed over, else the
    (shown, non-modal) dialog that says it was not, with the path to copy."""
    why = launcher_missing()
    argv = opener_argv(Path(path).resolve()) if why is None else None
    if argv is not None:
        return _watched_open(argv, Path(path).resolve(), parent, what=what, opener=opener)
    if why is None and QDesktopServices.openUrl(QUrl.fromLocalFile(str(Path(path).resolve()))):
        return None
    dialog = NoBrowserDialog(Path(path).resolve(), why or "the system refused to open it", parent, what=what,
                             opener=opener)
    dialog.show()
    return dialog


def _watched_open(argv: list[str], path: Path, parent: QWidget | None, *, what: str,
                  opener: str) -> NoBrowserDialog:
    """Start the opener and watch it: a non-zero exit status, a failure to start or no answer within
    OPENER_WAIT_S shows the (until then hidden) dialog with the path and its Copy button."""
    dialog = NoBrowserDialog(path, "", parent, what=what, opener=opener)
    proc = QProcess(dialog)
    dialog.process = proc
    timer = QTimer(dialog)
    timer.setSingleShot(True)
    name = Path(argv[0]).name

    def fail(why: str) -> None:
        timer.stop()
        if dialog.isVisible():
            return
        dialog.message.setText(f"The {what} could not be opened in {opener}: {why}.\nIts path, to open yourself:")
        dialog.show()

    def finished(code: int, status: QProcess.ExitStatus) -> None:
        timer.stop()
        if status != QProcess.ExitStatus.NormalExit:
            fail(f"{name} crashed")
        elif code != 0:
            fail(f"{name} exited with status {code}")
        else:
            dialog.handed_over = True

    def error(err: QProcess.ProcessError) -> None:
        if err == QProcess.ProcessError.FailedToStart:
            fail(f"{name} could not be started")

    proc.finished.connect(finished)
    proc.errorOccurred.connect(error)
    timer.timeout.connect(lambda: fail(f"{name} did not answer within {OPENER_WAIT_S:g} s"))
    timer.start(int(OPENER_WAIT_S * 1000))
    proc.start(argv[0], argv[1:])
    return dialog
