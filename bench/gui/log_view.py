"""The run's log in the window: each level in its colour, a level filter (what is hidden is kept
and comes back when the filter widens), and it follows the newest line unless the operator
scrolled up to read (or unticked "follow")."""

from __future__ import annotations

import html
from collections import deque

from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QLabel, QPlainTextEdit, QVBoxLayout, QWidget

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
LEVEL_RANK = {"DEBUG": 10, "INFO": 20, "WARNING": 30, "ERROR": 40, "CRITICAL": 50}
LEVEL_STYLES = {"DEBUG": "color:#808080", "INFO": "color:#000000", "WARNING": "color:#9a6200; font-weight:bold",
                "ERROR": "color:#c00000; font-weight:bold", "CRITICAL": "color:#c00000; font-weight:bold"}


def level_rank(level: str) -> int:
    return LEVEL_RANK.get(level.upper(), 20)


class LogPane(QWidget):
    """Lines (t, level, message), newest last, bounded to `max_lines` so a chatty run cannot eat
    the memory; `add` is the only way in."""

    def __init__(self, parent: QWidget | None = None, max_lines: int = 5000) -> None:
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        row = QHBoxLayout()
        row.addWidget(QLabel("show"))
        self.level = QComboBox()
        self.level.setObjectName("log_level")
        for name in LEVELS:
            self.level.addItem(f"{name} and above", name)
        self.level.setCurrentIndex(1)  # INFO and above
        row.addWidget(self.level)
        self.follow = QCheckBox("follow newest")
        self.follow.setObjectName("log_follow")
        self.follow.setChecked(True)
        row.addWidget(self.follow)
        row.addStretch(1)
        lay.addLayout(row)
        self.text = QPlainTextEdit()
        self.text.setReadOnly(True)
        self.text.setMaximumBlockCount(max_lines)
        lay.addWidget(self.text)
        self.entries: deque[tuple[float, str, str]] = deque(maxlen=max_lines)
        self.level.currentIndexChanged.connect(lambda _i: self._rebuild())
        self.follow.toggled.connect(lambda on: on and self._to_end())
        bar = self.text.verticalScrollBar()
        bar.valueChanged.connect(self._scrolled)
        self._appending = False

    def min_rank(self) -> int:
        return level_rank(str(self.level.currentData()))

    def add(self, t_sim_s: float, level: str, message: str) -> None:
        level = level.upper()
        self.entries.append((t_sim_s, level, message))
        if level_rank(level) < self.min_rank():
            return
        self._appending = True
        try:
            self.text.appendHtml(self._html(t_sim_s, level, message))
        finally:
            self._appending = False
        if self.follow.isChecked():
            self._to_end()

    def _html(self, t_sim_s: float, level: str, message: str) -> str:
        style = LEVEL_STYLES.get(level, LEVEL_STYLES["INFO"])
        text = html.escape(f"{t_sim_s:9.3f}  {level:<7} {message}").replace(" ", "&nbsp;")
        return f'<span style="{style}; white-space:pre">{text}</span>'

    def _rebuild(self) -> None:
        rank = self.min_rank()
        self.text.clear()
        self._appending = True
        try:
            for t, level, message in self.entries:
                if level_rank(level) >= rank:
                    self.text.appendHtml(self._html(t, level, message))
        finally:
            self._appending = False
        self._to_end()

    def _to_end(self) -> None:
        bar = self.text.verticalScrollBar()
        bar.setValue(bar.maximum())

    def _scrolled(self, value: int) -> None:
        """Scrolling up to read stops following; back at the bottom, it follows again."""
        if self._appending:
            return
        self.follow.setChecked(value >= self.text.verticalScrollBar().maximum())

    def toPlainText(self) -> str:  # noqa: N802 - as QPlainTextEdit's
        """What is shown (the filtered lines)."""
        return self.text.toPlainText()

    def lines(self) -> list[str]:
        return self.toPlainText().splitlines()
