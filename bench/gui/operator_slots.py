"""The operator station's slot panels (a station with several gyros a table): each slot's serial,
its verdict large with its reason, its live step and progress, and Clear / Retest buttons."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QFont
from PySide6.QtWidgets import QFrame, QHBoxLayout, QLabel, QProgressBar, QPushButton, QSizePolicy, QVBoxLayout

from .operator_view import COLOURS
from .unit_progress import UnitProgress

COLOURS = {**COLOURS, "CONDITIONAL": COLOURS["MARGINAL"], "EMPTY": ("#f0f0f0", "#777"),
           "NOT FITTED": ("#f0f0f0", "#777"), "PLACED": ("#d8d8d8", "#333"), "NOT RUN": ("#c62020", "white")}


def font(pt: int, bold: bool = False) -> QFont:
    f = QFont()
    f.setPointSize(pt)
    f.setBold(bold)
    return f


def paint(label: QLabel, outcome: str) -> str:
    """Show `outcome` on `label` in its colours (MARGINAL reads CONDITIONAL); the text shown."""
    shown = "CONDITIONAL" if outcome == "MARGINAL" else outcome
    bg, fg = COLOURS.get(shown, ("#c62020", "white"))
    label.setText(shown)
    label.setStyleSheet(f"background: {bg}; color: {fg}; border-radius: 10px; padding: 4px;")
    return shown


class SlotPanel(QFrame):
    """One slot of the station: its unit, verdict, reason, step and progress."""

    def __init__(self, slot: int, n_steps: int) -> None:
        super().__init__()
        self.slot = slot
        self.serial: str | None = None
        self.tested = False  # a unit of this slot ran in the last batch (it may be retested)
        self.progress = UnitProgress(n_steps)
        self.setFrameShape(QFrame.Shape.StyledPanel)
        self.setObjectName(f"slot{slot}")
        self.title = QLabel(f"slot {slot}")
        self.title.setFont(font(12, True))
        self.title.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.serial_label = QLabel("empty")
        self.serial_label.setFont(font(16, True))
        self.serial_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.verdict = QLabel()
        self.verdict.setFont(font(26, True))
        self.verdict.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.verdict.setMinimumHeight(80)
        self.reason = QLabel("")
        self.reason.setWordWrap(True)
        self.reason.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.reason.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.reason.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.step = QLabel("")
        self.step.setWordWrap(True)
        self.step.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.step.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setTextVisible(False)
        self.bar.setValue(0)
        self.clear_button = QPushButton("Clear")
        self.retest_button = QPushButton("Retest")
        buttons = QHBoxLayout()
        buttons.addWidget(self.clear_button)
        buttons.addWidget(self.retest_button)
        lay = QVBoxLayout(self)
        for w in (self.title, self.serial_label, self.verdict, self.reason, self.step, self.bar):
            lay.addWidget(w)
        lay.addStretch(1)
        lay.addLayout(buttons)
        self.empty()

    @property
    def outcome(self) -> str:
        return self.verdict.text()

    def empty(self) -> None:
        """No unit in the slot (it is not run; its batch records it as not fitted)."""
        self.serial, self.tested = None, False
        self.serial_label.setText("-")
        self.set_verdict("EMPTY", "")
        self.reset_progress()
        self.retest_button.setEnabled(False)
        self.clear_button.setEnabled(False)

    def place(self, serial: str) -> None:
        self.serial, self.tested = serial, False
        self.serial_label.setText(serial)
        self.set_verdict("PLACED", "")
        self.reset_progress()
        self.retest_button.setEnabled(False)
        self.clear_button.setEnabled(True)

    def set_verdict(self, outcome: str, reason: str) -> None:
        paint(self.verdict, outcome)
        self.reason.setText(reason)

    def reset_progress(self) -> None:
        self.progress.detach()
        self.progress.reset()
        self.step.setText("")
        self.bar.setValue(0)

    def show_progress(self) -> None:
        """Draw the queued progress (GUI thread)."""
        if self.progress.drain():
            self.step.setText(self.progress.text)
            self.bar.setValue(int(round(1000 * self.progress.fraction)))
