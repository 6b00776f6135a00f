"""The parameter form, generated from a procedure's declared parameters: one field per
parameter with its unit and limits; an invalid value is marked red with the reason, and the
form reports whether every value is valid (the window enables Start on that)."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QFormLayout, QLabel, QLineEdit, QWidget

from .params import ParamSpec

INVALID_STYLE = "QLineEdit { background: #ffd6d6; border: 1px solid #c00000; }"


class ParameterForm(QWidget):
    """Fields for a tuple of ParamSpec; `values()` parses them, `errors` names what is wrong."""

    validity_changed = Signal(bool)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.layout_ = QFormLayout(self)
        self.specs: tuple[ParamSpec, ...] = ()
        self.fields: dict[str, QWidget] = {}
        self.errors: dict[str, str] = {}
        self.error_label = QLabel("")
        self.error_label.setStyleSheet("color: #c00000;")
        self.error_label.setWordWrap(True)

    def set_specs(self, specs: tuple[ParamSpec, ...]) -> None:
        while self.layout_.rowCount():
            self.layout_.removeRow(0)
        self.specs = tuple(specs)
        self.fields = {}
        self.error_label = QLabel("")
        self.error_label.setStyleSheet("color: #c00000;")
        self.error_label.setWordWrap(True)
        for spec in self.specs:
            field = self._make_field(spec)
            self.fields[spec.name] = field
            label = spec.name + (f" [{spec.unit}]" if spec.unit else "")
            lim = []
            if spec.low is not None or spec.high is not None:
                lim.append(f"limits {spec.low if spec.low is not None else '-inf'} .. "
                           f"{spec.high if spec.high is not None else 'inf'}")
            field.setToolTip("; ".join([spec.doc, *lim]).strip("; "))
            self.layout_.addRow(label, field)
        self.layout_.addRow(self.error_label)
        self.validate()

    def _make_field(self, spec: ParamSpec) -> QWidget:
        if spec.kind == "bool":
            box = QCheckBox()
            box.setChecked(bool(spec.default))
            box.stateChanged.connect(lambda _s: self.validate())
            return box
        if spec.kind == "choice":
            combo = QComboBox()
            combo.addItems([str(c) for c in spec.choices])
            if spec.default is not None:
                combo.setCurrentText(str(spec.default))
            combo.currentTextChanged.connect(lambda _t: self.validate())
            return combo
        edit = QLineEdit(spec.format(spec.default))
        edit.setObjectName(f"param_{spec.name}")
        edit.textChanged.connect(lambda _t: self.validate())
        return edit

    def _text(self, spec: ParamSpec) -> str:
        w = self.fields[spec.name]
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
            w.setCurrentText(str(value))
        else:
            w.setText(str(value))  # type: ignore[attr-defined]

    def validate(self) -> bool:
        """Parse every field; mark the invalid ones; emit validity_changed."""
        self.errors = {}
        for spec in self.specs:
            try:
                spec.parse(self._text(spec))
                ok = True
            except ValueError as exc:
                self.errors[spec.name] = str(exc)
                ok = False
            w = self.fields[spec.name]
            if isinstance(w, QLineEdit):
                w.setStyleSheet("" if ok else INVALID_STYLE)
        self.error_label.setText("\n".join(self.errors.values()))
        valid = not self.errors
        self.validity_changed.emit(valid)
        return valid

    def is_valid(self) -> bool:
        return not self.errors

    def values(self) -> dict[str, Any]:
        """The parsed values (ValueError on the first invalid one)."""
        return {spec.name: spec.parse(self._text(spec)) for spec in self.specs}
