"""The window's DUT serial and operator fields: checked with the line's rules, remembered between
runs (QSettings), and fit for a keyboard-wedge scanner (it types the serial and presses Enter)."""

from __future__ import annotations

from PySide6.QtCore import QSettings, Signal
from PySide6.QtWidgets import QFormLayout, QLabel, QLineEdit, QSizePolicy, QWidget

from bench.line.inputs import check_operator, check_serial
from bench.validation import ValidationError

SETTINGS_ORG = "gyrobench"
SETTINGS_APP = "window"


def settings() -> QSettings:
    """Where the window remembers its fields (tests point QSettings at a temporary folder)."""
    return QSettings(SETTINGS_ORG, SETTINGS_APP)


class UnitFields(QWidget):
    """DUT serial (several: comma-separated) and operator; `scanned` fires on Enter in the serial."""

    scanned = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.dut = QLineEdit()
        self.dut.setObjectName("dut_serial")
        self.dut.setPlaceholderText("scan or type the serial, Enter")
        self.operator = QLineEdit()
        self.operator.setObjectName("operator_name")
        self.operator.setPlaceholderText("your name")
        self.error = QLabel("")
        self.error.setWordWrap(True)
        self.error.setStyleSheet("color: #c00000;")
        self.error.setVisible(False)  # a row only when there is something wrong
        self.error.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        lay = QFormLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addRow("DUT serial", self.dut)
        lay.addRow("Operator", self.operator)
        lay.addRow(self.error)
        s = settings()
        self.dut.setText(str(s.value("dut", "") or ""))
        self.operator.setText(str(s.value("operator", "") or ""))
        self.dut.returnPressed.connect(self._on_enter)
        self.dut.textEdited.connect(lambda _t: self.say(""))
        self.operator.textEdited.connect(lambda _t: self.say(""))

    def _on_enter(self) -> None:
        try:
            duts = self.duts()
        except ValidationError as exc:
            self.say(str(exc))
            return
        self.dut.setText(", ".join(duts))
        self.remember()
        self.scanned.emit(", ".join(duts))

    def say(self, text: str) -> None:
        """What is wrong with the fields (hidden when nothing is)."""
        self.error.setText(text)
        self.error.setVisible(bool(text))

    def duts(self) -> list[str]:
        """The serials typed or scanned, normalised; ValidationError names a bad one."""
        return [check_serial(part) for part in self.dut.text().split(",") if part.strip()]

    def operator_name(self) -> str:
        """The operator's name ('' when none is given); ValidationError when it is not printable."""
        text = self.operator.text().strip()
        return check_operator(text) if text else ""

    def checked(self) -> tuple[list[str], str]:
        """(serials, operator) for a run, or ValidationError (shown under the fields)."""
        try:
            out = self.duts(), self.operator_name()
        except ValidationError as exc:
            self.say(str(exc))
            raise
        self.say("")
        return out

    def remember(self) -> None:
        """Keep the fields for the next run and the next start of the window."""
        s = settings()
        s.setValue("dut", self.dut.text().strip())
        s.setValue("operator", self.operator.text().strip())
        s.sync()

    def set_running(self, running: bool) -> None:
        self.dut.setReadOnly(running)
        self.operator.setReadOnly(running)
