"""Any PyMeasure instrument as a gyrobench device: built from a class path and a VISA resource,
with its transport errors turned into ours (LinkLostError, ProtocolError) so the engine's safety
rules hold (docs/frontend_sr865.md).  PyMeasure is an optional extra: `gyrobench[pymeasure]`."""

from __future__ import annotations

import importlib
import re
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

from drivers.errors import DeviceError, LinkLostError, ProtocolError

T = TypeVar("T")
#: `TCPIP[n]::host,port::...INSTR`: pyvisa-py's VXI-11 resource with the core channel's port
_INSTR_WITH_PORT = re.compile(r"^TCPIP\d*::[^:]+,\d+::", re.IGNORECASE)
#: IEEE 488.2 *ESR? bit 5: a command (or query) the instrument could not parse
ESR_COMMAND_ERROR = 1 << 5


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
    """One PyMeasure instrument on a VISA resource; `call(fn)` runs fn(instrument) with our errors.

    `status_query` (an IEEE 488.2 instrument's `*ESR?`): after a query goes unanswered, ask it;
    an answer with the command-error bit means the instrument did not know the query (it keeps
    silent, as 488.2 says) - a ProtocolError naming it, not a lost link."""

    def __init__(self, class_path: str, resource: str, *, timeout_s: float = 2.0, name: str = "",
                 status_query: str | None = None, **kwargs: Any):
        self.class_path, self.resource, self.timeout_s = class_path, resource, float(timeout_s)
        self.name = name or resource
        self.status_query = status_query
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
        if "::SOCKET" in self.resource.upper() or _INSTR_WITH_PORT.match(self.resource):
            # raw sockets, and VXI-11 with the core channel's port given (no portmapper): pyvisa-py's
            # resource forms, spoken without a vendor VISA
            kw.setdefault("visa_library", "@py")
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
        except pyvisa.errors.VisaIOError as exc:
            esr = self._status_after_silence(exc)
            if esr is not None and esr & ESR_COMMAND_ERROR:
                raise ProtocolError(
                    f"{self.name}: {what or 'a query'} went unanswered and {self.status_query} = {esr} "
                    "(command error): the instrument does not know it"
                ) from exc
            raise LinkLostError(f"{self.name}: {what or 'I/O'} failed ({exc})") from exc
        except (OSError, ConnectionError) as exc:
            raise LinkLostError(f"{self.name}: {what or 'I/O'} failed ({exc})") from exc
        except (ValueError, TypeError, IndexError) as exc:
            raise ProtocolError(f"{self.name}: {what or 'reply'} unreadable ({exc})") from exc

    def _status_after_silence(self, exc: Exception) -> int | None:
        """The status register after a timed-out query (None: no status query, or no answer)."""
        import pyvisa

        if self.status_query is None or getattr(exc, "error_code", None) != pyvisa.constants.StatusCode.error_timeout:
            return None
        try:
            return int(float(self.instrument.ask(self.status_query)))
        except Exception:  # noqa: BLE001 - no answer either: the link is what failed
            return None

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
