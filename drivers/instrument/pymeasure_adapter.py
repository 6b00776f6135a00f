"""Any PyMeasure instrument as a gyrobench device: built from a class path and a VISA resource,
with its transport errors turned into ours (LinkLostError, ProtocolError) so the engine's safety
rules hold (docs/frontend_sr865.md).  PyMeasure is an optional extra: `gyrobench[pymeasure]`."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

from drivers.errors import DeviceError, LinkLostError, ProtocolError

T = TypeVar("T")


def load_class(path: str) -> type:
    """ "pymeasure.instruments.srs.SR860" -> the class; DeviceError names a missing package."""
    module, _, name = path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except ModuleNotFoundError as exc:
        raise DeviceError(
            f"instrument class {path!r}: module {exc.name!r} is not installed (pip install 'gyrobench[pymeasure]')"
        ) from None
    except AttributeError:
        raise DeviceError(f"instrument class {path!r}: {module} has no {name!r}") from None


class PyMeasureDevice:
    """One PyMeasure instrument on a VISA resource; `call(fn)` runs fn(instrument) with our errors."""

    def __init__(self, class_path: str, resource: str, *, timeout_s: float = 2.0, name: str = "", **kwargs: Any):
        self.class_path, self.resource, self.timeout_s = class_path, resource, float(timeout_s)
        self.name = name or resource
        self.kwargs = kwargs
        self.instrument: Any = None

    def connect(self) -> PyMeasureDevice:
        cls = load_class(self.class_path)
        kw: dict[str, Any] = {
            "read_termination": "\n",
            "write_termination": "\n",
            "timeout": int(round(self.timeout_s * 1000)),
            **self.kwargs,
        }
        if "::SOCKET" in self.resource.upper():
            kw.setdefault("visa_library", "@py")  # pyvisa-py speaks raw sockets without a vendor VISA
        try:
            with warnings.catch_warnings():  # PyMeasure warns that it does not know if a class speaks SCPI
                warnings.simplefilter("ignore", FutureWarning)
                self.instrument = cls(self.resource, **kw)
        except Exception as exc:  # noqa: BLE001 - pyvisa/pymeasure raise many kinds on a bad address
            raise LinkLostError(f"{self.name}: cannot open {self.resource} ({exc})") from exc
        return self

    def call(self, fn: Callable[[Any], T], what: str = "") -> T:
        """fn(instrument) with a lost link as LinkLostError and an unreadable answer as ProtocolError."""
        import pyvisa

        if self.instrument is None:
            raise LinkLostError(f"{self.name}: not connected")
        try:
            return fn(self.instrument)
        except (pyvisa.errors.VisaIOError, OSError, ConnectionError) as exc:
            raise LinkLostError(f"{self.name}: {what or 'I/O'} failed ({exc})") from exc
        except (ValueError, TypeError, IndexError) as exc:
            raise ProtocolError(f"{self.name}: {what or 'reply'} unreadable ({exc})") from exc

    def ask(self, command: str) -> str:
        return self.call(lambda inst: inst.ask(command).strip(), command)

    def write(self, command: str) -> None:
        self.call(lambda inst: inst.write(command), command)

    @property
    def idn(self) -> str:
        return self.ask("*IDN?")

    def close(self) -> None:
        if self.instrument is not None:
            try:
                self.instrument.adapter.close()
            except Exception:  # noqa: BLE001 - closing must not raise
                pass
            self.instrument = None
