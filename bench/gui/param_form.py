"""The parameter form, built from a procedure's own `Param` declarations: one field per
parameter with its unit and limits; each field's text goes through `Param.convert`, the code the
engine and `gyrobench run --set` use, so the window accepts, refuses and words exactly as they do."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QFormLayout, QLabel, QLineEdit, QSizePolicy, QWidget

from bench.engine.params import Param

INVALID_STYLE = "QLineEdit { background: #ffd6d6; border: 1px solid #c00000; }"
HINT_STYLE = "color: #555555; font-size: 9pt;"
ERROR_STYLE = "color: #c00000;"


def _wrapping(text: str, style: str = "") -> QLabel:
    """A label that wraps to the width it is given (its text never sets the form's width)."""
    label = QLabel(text)
    label.setWordWrap(True)
    label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
    label.setMinimumWidth(60)
    if style:
        label.setStyleSheet(style)
    return label


def format_value(value: Any) -> str:
    """A default as the form shows it: a float in its shortest text that reads back to the same
    float (the run gets exactly the declared default)."""
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


class ParameterForm(QWidget):
    """Fields for a tuple of Param; `values()` converts them, `errors` names what is wrong."""

    validity_changed = Signal(bool)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.layout_ = QFormLayout(self)
        self.specs: tuple[Param, ...] = ()
        self.fields: dict[str, QWidget] = {}
        self.errors: dict[str, str] = {}
        self.error_label = QLabel("")

    def set_specs(self, specs: tuple[Param, ...]) -> None:
        """One row a parameter: its name and unit with the field, under them its limits and what it
        is (wrapped, never scrolled sideways), and the reason a value is refused, right there."""
        while self.layout_.rowCount():
            self.layout_.removeRow(0)
        self.layout_.setRowWrapPolicy(QFormLayout.RowWrapPolicy.WrapAllRows)  # name above its field: never clipped
        self.specs = tuple(specs)
        self.fields = {}
        self.field_errors: dict[str, QLabel] = {}
        self.hints: dict[str, QLabel] = {}
        self.name_labels: dict[str, QLabel] = {}
        self.error_label = QLabel("")  # every refusal at once, kept for callers; each is shown at its field
        for param in self.specs:
            field = self._make_field(param)
            field.setMinimumWidth(70)
            self.fields[param.name] = field
            label = param.name + (f" [{param.unit}]" if param.unit else "")
            hint_text = "; ".join(t for t in (param.limit_text(), param.doc) if t)
            field.setToolTip(hint_text)
            self.name_labels[param.name] = QLabel(label)  # a short identifier: shown whole, above its field
            self.layout_.addRow(self.name_labels[param.name], field)
            hint = _wrapping(hint_text, HINT_STYLE)
            self.hints[param.name] = hint
            self.layout_.addRow(hint)
            error = _wrapping("", ERROR_STYLE)
            error.setObjectName(f"error_{param.name}")
            error.setVisible(False)
            self.field_errors[param.name] = error
            self.layout_.addRow(error)
        self.validate()

    def _make_field(self, param: Param) -> QWidget:
        if param.type is bool:
            box = QCheckBox()
            box.setChecked(bool(param.default))
            box.stateChanged.connect(lambda _s: self.validate())
            return box
        if param.choices is not None:
            combo = QComboBox()
            combo.addItems([format_value(c) for c in param.choices])
            combo.setCurrentText(format_value(param.default))
            combo.currentTextChanged.connect(lambda _t: self.validate())
            return combo
        edit = QLineEdit(format_value(param.default))
        edit.setObjectName(f"param_{param.name}")
        edit.textChanged.connect(lambda _t: self.validate())
        return edit

    def text(self, name: str) -> str:
        """What the field for `name` holds, as the text `--set name=<text>` would give."""
        w = self.fields[name]
        if isinstance(w, QCheckBox):
            return "true" if w.isChecked() else "false"
        if isinstance(w, QComboBox):
            return w.currentText()
        return w.text()  # type: ignore[attr-defined]

    def set_value(self, name: str, value: Any) -> None:
        w = self.fields[name]
        if isinstance(w, QCheckBox):
            w.setChecked(bool(value))
        elif isinstance(w, QComboBox):
            w.setCurrentText(format_value(value))
        else:
            w.setText(value if isinstance(value, str) else format_value(value))  # type: ignore[attr-defined]

    def validate(self) -> bool:
        """Convert every field; mark the invalid ones; emit validity_changed."""
        self.errors = {}
        for param in self.specs:
            try:
                param.convert(self.text(param.name))
                ok = True
            except ValueError as exc:
                self.errors[param.name] = str(exc)
                ok = False
            w = self.fields[param.name]
            if isinstance(w, QLineEdit):
                w.setStyleSheet("" if ok else INVALID_STYLE)
        self.error_label.setText("\n".join(self.errors.values()))
        for name, label in getattr(self, "field_errors", {}).items():
            label.setText(self.errors.get(name, ""))
            label.setVisible(name in self.errors)
        valid = not self.errors
        self.validity_changed.emit(valid)
        return valid

    def is_valid(self) -> bool:
        return not self.errors

    def values(self) -> dict[str, Any]:
        """The converted values (ParamError, a ValueError, on the first invalid one)."""
        return {param.name: param.convert(self.text(param.name)) for param in self.specs}
