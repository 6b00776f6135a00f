"""What several `gyrobench` subcommands share: exit codes, CliError, one-line messages, the store,
the checks of --runs-dir and --speed, and the report writer."""

from __future__ import annotations

import sys
from typing import Any

EXIT_OK, EXIT_BAD_OUTCOME, EXIT_USAGE = 0, 1, 2
EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_TERMINATED, EXIT_BROKEN_PIPE = 70, 130, 143, 141
BAD_OUTCOMES = ("ERROR", "ABORTED", "FAIL")


class CliError(Exception):
    """A failure the user can act on (a path, a store, an option): one line and an exit code."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


def exit_for_signal(signum: int) -> int:
    """The exit code of a command a signal ended (after its safe state): 128 + the signal's number,
    as a shell reports it (SIGINT 130, SIGTERM 143), so a script tells it from a failed run (1)."""
    return 128 + int(signum)


def _err(msg: str) -> None:
    print(f"gyrobench: {msg}", file=sys.stderr)


def _store(url: str | None, **kw: Any):
    """The results store, or CliError naming it (a directory that is a file, a read-only store, a
    missing database driver)."""
    from bench.results import ResultsStore, StoreError

    try:
        return ResultsStore(url, **kw)
    except StoreError as exc:
        raise CliError(str(exc), 1) from exc
    except Exception as exc:  # noqa: BLE001 - OSError, SQLAlchemy's errors, a missing driver: one line
        from bench.results.redact import redact_text

        where = redact_text(str(url or "runs/results.sqlite"))
        raise CliError(f"results store {where}: cannot be opened: {redact_text(_reason(exc))}", 1) from exc


class StoreOpening:
    """The results store opened (`_store`: its SQLAlchemy and alembic imports, the migration check,
    a server's answer) in a thread while the station opens; `result()` waits for it and gives the
    store, or raises what opening it raised (CliError: one line)."""

    def __init__(self, url: str | None, **kw: Any) -> None:
        import threading

        self._store: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._open, args=(url,), kwargs=kw, name="store-open", daemon=True)
        self._thread.start()

    def _open(self, url: str | None, **kw: Any) -> None:
        try:
            self._store = _store(url, **kw)
        except BaseException as exc:  # noqa: BLE001 - raised again by result(), in the command's thread
            self._error = exc

    def result(self) -> Any:
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._store


def _reason(exc: BaseException) -> str:
    """An exception as a short reason: OSError's text and file, SQLAlchemy's original error."""
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.strerror}: {exc.filename}" if exc.filename else exc.strerror
    orig = getattr(exc, "orig", None)  # SQLAlchemy wraps the database driver's error
    if orig is not None:
        return f"{type(orig).__name__}: {orig}"
    return f"{type(exc).__name__}: {exc}"


def _check_runs_dir(path: str) -> None:
    """The raw-data directory exists (or is made) and takes a file, before any device moves."""
    import os
    import tempfile
    from pathlib import Path

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise CliError(f"--runs-dir {path}: is a file, not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=p, prefix=".gyrobench-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise CliError(f"--runs-dir {path}: raw data cannot be written there ({_reason(exc)})") from None


def _speed(value: float | None) -> float | None:
    """--speed checked here, naming the option (not the station file)."""
    if value is None:
        return None
    from bench.validation import ValidationError, convert

    try:
        return convert("--speed", value, float, low=0.0, high=1e6)
    except ValidationError as exc:
        raise CliError(f"{exc} (allowed: 0 = lockstep, or 0 to 1e6 x real time)") from None


def _write_report(raw_file: str, row: dict[str, Any] | None, output: str | None = None, pdf: bool = False) -> Any:
    """Render the HTML report (and with pdf the PDF) of a recorded run beside its raw file (or
    to output); their paths."""
    import os

    from bench.pdf import PdfUnavailable
    from bench.reporting import write_report

    workers = min(2, os.cpu_count() or 1)  # the figures built and drawn by two processes at once
    try:
        return write_report(raw_file, row, output, pdf=pdf, workers=workers)
    except PdfUnavailable as exc:  # checked before anything is written: the HTML alone, and why
        _err(str(exc))
        return write_report(raw_file, row, output, workers=workers)
