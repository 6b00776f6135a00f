"""Any PyMeasure instrument as a station device (`driver = "pymeasure"`): its properties set at
connect (`setup`), logged into every run at each link check (`record`, with units) and set to safe
values and read back when the station goes to its safe state (`safe`).  docs/instruments.md."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.errors import DeviceError, LimitError, ProtocolError

from .pymeasure_adapter import PyMeasureDevice


def column_name(path: str) -> str:
    """The stream column a property path is logged under: `ch_1.current` -> `ch_1_current`."""
    return path.replace(".", "_")


def _resolve(obj: Any, path: str) -> tuple[Any, str]:
    """(owner, attribute) of a dotted property path on an instrument (`ch_1.output_enabled`)."""
    *owners, attr = path.split(".")
    for name in owners:
        obj = getattr(obj, name)
    return obj, attr


def same(asked: Any, read: Any) -> bool:
    """A read-back equals what was written (numbers to 1e-6 relative, as instruments round)."""
    if isinstance(asked, bool) or isinstance(read, bool):
        return bool(asked) == bool(read)
    if isinstance(asked, (int, float)) and isinstance(read, (int, float)):
        return math.isclose(float(asked), float(read), rel_tol=1e-6, abs_tol=1e-12)
    return str(asked).strip().upper() == str(read).strip().upper()


class InstrumentDevice:
    """One PyMeasure instrument on a station, under the role name the station file gives it.

    get/set go through the instrument's own PyMeasure properties (their validators are its limits:
    a refused value is a LimitError naming the value and the instrument's words); every transport
    failure is a LinkLostError (bench safety rules)."""

    def __init__(
        self,
        role: str,
        class_path: str,
        resource: str,
        *,
        setup: Mapping[str, Any] | None = None,
        safe: Mapping[str, Any] | None = None,
        record: Mapping[str, str] | None = None,
        timeout_s: float = 2.0,
    ) -> None:
        self.role, self.class_path = role, class_path
        self.setup, self.safe = dict(setup or {}), dict(safe or {})
        self.record = dict(record or {})
        self.link = PyMeasureDevice(class_path, resource, timeout_s=timeout_s, name=role)

    @property
    def health_columns(self) -> tuple[str, ...]:
        """The columns each link check logs: one per recorded property."""
        return tuple(column_name(p) for p in self.record)

    def connect(self) -> InstrumentDevice:
        self.link.connect()
        for path, value in self.setup.items():
            self.set(path, value)
        return self

    def get(self, path: str) -> Any:
        """A property's value (`voltage_ac`, `ch_1.current`)."""

        def read(inst: Any) -> Any:
            owner, attr = _resolve(inst, path)
            return getattr(owner, attr)

        try:
            return self.link.call(read, f"reading {path}")
        except AttributeError:
            raise DeviceError(f"{self.role}: {self.class_path} has no property {path!r}") from None

    def set(self, path: str, value: Any, *, verify: bool = True) -> None:
        """Write a property through its PyMeasure validator, then read it back (verify)."""

        def write(inst: Any) -> None:
            owner, attr = _resolve(inst, path)
            if not hasattr(type(owner), attr):
                raise AttributeError(attr)
            try:
                setattr(owner, attr, value)
            except (ValueError, TypeError) as exc:  # the instrument's own range/choice check
                msg = f"{self.role}: {path}={value!r} refused by the instrument ({exc})"
                raise LimitError(f"{self.role}.{path}", value, message=msg) from None

        try:
            self.link.call(write, f"writing {path}")
        except AttributeError:
            raise DeviceError(f"{self.role}: {self.class_path} has no property {path!r}") from None
        except ProtocolError as exc:
            if isinstance(exc.__cause__, LimitError):
                raise exc.__cause__ from None
            raise
        if verify:
            read = self.get(path)
            if not same(value, read):
                raise DeviceError(f"{self.role}: {path} reads back {read!r} after writing {value!r}")

    def read_record(self) -> np.ndarray | None:
        """One row of the recorded properties (None when nothing is recorded)."""
        if not self.record:
            return None
        values = []
        for path in self.record:
            v = self.get(path)
            try:
                values.append(float(v))
            except (TypeError, ValueError):
                raise ProtocolError(f"{self.role}: {path} read {v!r}, not a number") from None
        return np.asarray([values], dtype=float)

    def panel_values(self) -> dict[str, str]:
        """The logged properties as the station panel shows them (`ch_1.current`: `0.15 A`)."""
        row = self.read_record()
        if row is None:
            return {}
        return {path: f"{value:.6g} {unit}" for (path, unit), value in zip(self.record.items(), row[0], strict=True)}

    def health(self) -> np.ndarray | None:
        """A sign of life: the recorded properties, or the identity when none is recorded."""
        if self.record:
            return self.read_record()
        self.link.idn  # noqa: B018 - an answer proves the link
        return None

    def safe_state(self) -> bool:
        """Set every `safe` property and read each back: True only when all confirm."""
        ok = True
        for path, value in self.safe.items():
            try:
                self.set(path, value, verify=False)
                ok = same(value, self.get(path)) and ok
            except (DeviceError, LimitError, ConnectionError):
                ok = False
        return ok

    def close(self) -> None:
        self.link.close()
