"""Calibration procedures, one module a procedure, and the registry that finds them.

`all_procedures()` walks this package for `Procedure` subclasses (by their `name`);
`procedure_named(name)` finds one, looking first in the module its name gives (`hrg-damping` in
`procedures/hrg_damping.py`, `table-spin` in `procedures/examples/table_spin.py`: a run imports only
its own procedure, ~0.8 s of CPU less than all of them);
`find_procedure(text)` takes a registered name or a path to a `.py` file anywhere
(`gyrobench run path/to/file.py`).
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import sys
from pathlib import Path
from typing import Any


class ProcedureNotFound(LookupError):
    """No procedure by that name or in that file."""


def _procedures_in(module) -> list[type]:
    from bench.engine import Procedure

    return [
        obj
        for obj in vars(module).values()
        if isinstance(obj, type)
        and issubclass(obj, Procedure)
        and obj is not Procedure
        and obj.__module__ == module.__name__
    ]


def all_procedures() -> dict[str, type]:
    """Every procedure in this package by name; a module that fails to import is skipped."""
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(__path__, prefix=__name__ + "."):
        if info.name.startswith(f"{__name__}.figures"):  # the procedures' figures: no procedure there
            continue
        try:
            module = importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - one broken module must not hide the others
            continue
        for cls in _procedures_in(module):
            found.setdefault(cls.name, cls)
    return dict(sorted(found.items()))


#: subpackages whose modules are procedures too (`table-spin` in `procedures/examples/table_spin.py`)
_SUBPACKAGES = ("", "examples.")


def procedure_named(name: str) -> type | None:
    """The registered procedure called `name`, or None: its own module (the name with '_' for
    '-', in this package or its examples) when that defines it, else every module's (all_procedures)."""
    for sub in _SUBPACKAGES:
        module_name = f"{__name__}.{sub}{name.replace('-', '_')}"
        if not (name and all(part.isidentifier() for part in module_name.split("."))):
            break
        try:
            spec = importlib.util.find_spec(module_name)
        except (ImportError, ValueError):
            spec = None
        if spec is None:
            continue
        try:
            module = importlib.import_module(module_name)
        except Exception:  # noqa: BLE001 - a broken module: all_procedures skips it and says so
            module = None
        for cls in _procedures_in(module) if module is not None else ():
            if cls.name == name:
                return cls
    return all_procedures().get(name)


#: how long a procedure file may take to import (wall seconds); $GYROBENCH_IMPORT_TIMEOUT_S overrides
IMPORT_TIMEOUT_S = 30.0


def import_timeout_s() -> float:
    """The import bound: $GYROBENCH_IMPORT_TIMEOUT_S if set (a positive number), else IMPORT_TIMEOUT_S."""
    import os

    text = os.environ.get("GYROBENCH_IMPORT_TIMEOUT_S", "")
    try:
        value = float(text) if text else IMPORT_TIMEOUT_S
    except ValueError:
        raise ProcedureNotFound(f"GYROBENCH_IMPORT_TIMEOUT_S={text!r} is not a number of seconds") from None
    if not 0 < value < 1e6:
        raise ProcedureNotFound(f"GYROBENCH_IMPORT_TIMEOUT_S={text!r} is not between 0 and 1e6 s")
    return value


def _exec_bounded(spec: Any, module: Any, timeout_s: float) -> None:
    """Run a procedure file's module code on a daemon thread, at most timeout_s: a file that hangs
    (a blocking read, an endless loop) or calls sys.exit() at import is an error, not the
    end of the command. The error it raised, if any, is raised here."""
    import threading

    failure: list[BaseException] = []

    def body() -> None:
        try:
            spec.loader.exec_module(module)
        except BaseException as exc:  # noqa: BLE001 - SystemExit too: handed to the caller
            failure.append(exc)

    worker = threading.Thread(target=body, name=f"import {module.__name__}", daemon=True)
    worker.start()
    worker.join(timeout_s)
    if worker.is_alive():
        raise TimeoutError(f"its import did not finish within {timeout_s:g} s (set GYROBENCH_IMPORT_TIMEOUT_S "
                           "for a slower one)")
    if failure:
        raise failure[0]


def load_file(path: str | Path, timeout_s: float | None = None) -> type:
    """The procedure defined in a Python file (the only one, or the last one defined); importing it
    may take at most timeout_s (default `import_timeout_s()`)."""
    path = Path(path).resolve()
    if not path.is_file():
        raise ProcedureNotFound(f"{path}: no such file")
    mod_name = f"gyrobench_user_{path.stem}_{abs(hash(str(path))) & 0xFFFFFF:x}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        _exec_bounded(spec, module, import_timeout_s() if timeout_s is None else timeout_s)
    except TimeoutError as exc:
        sys.modules.pop(mod_name, None)
        raise ProcedureNotFound(f"{path}: {exc}") from None
    except SystemExit as exc:
        sys.modules.pop(mod_name, None)
        raise ProcedureNotFound(f"{path}: it called sys.exit({exc.code!r}) while being imported; a procedure "
                                "file only defines procedures") from None
    except SyntaxError as exc:
        sys.modules.pop(mod_name, None)
        raise ProcedureNotFound(f"{path}, line {exc.lineno}: {exc.msg} (not a valid Python file)") from None
    except Exception as exc:  # noqa: BLE001 - an import error or any failure of the file's own code
        sys.modules.pop(mod_name, None)
        raise ProcedureNotFound(f"{path}: loading it failed: {type(exc).__name__}: {exc}") from exc
    procs = _procedures_in(module)
    if not procs:
        raise ProcedureNotFound(f"{path}: defines no Procedure subclass")
    return procs[-1]


def find_procedure(text: str) -> type:
    """A registered procedure name or a path to a .py file."""
    if text.endswith(".py") or "/" in text:
        return load_file(text)
    cls = procedure_named(text)
    if cls is not None:
        return cls
    procs = all_procedures()
    raise ProcedureNotFound(f"no procedure {text!r}; known: {', '.join(procs) or '(none)'}; or give a .py file")


def measurement_truth(procedure: str | None, truth: dict[str, float] | None) -> dict[str, float]:
    """The simulator's true value of each measurement of a registered procedure, by measurement name,
    as its declarations say (not by matching names); {} without truth or for an unknown procedure."""
    if not truth or not procedure:
        return {}
    cls = procedure_named(procedure)
    return {} if cls is None else cls.truth_for(truth)


def measurement_periods(procedure: str | None) -> dict[str, float]:
    """The period of each periodic measurement of a registered procedure (an axis angle: 90 deg)."""
    cls = procedure_named(procedure) if procedure else None
    return {} if cls is None else cls.truth_periods()


def no_interval_reasons(procedure: str | None) -> dict[str, str]:
    """Why each measurement of a registered procedure that has no 95 % interval has none."""
    cls = procedure_named(procedure) if procedure else None
    return {} if cls is None else cls.no_interval_reasons()


def no_truth_reasons(procedure: str | None) -> dict[str, str]:
    """Why each measurement of a registered procedure that no simulator truth is compared with is not."""
    cls = procedure_named(procedure) if procedure else None
    return {} if cls is None else cls.no_truth_reasons()
