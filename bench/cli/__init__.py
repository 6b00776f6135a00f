"""The `gyrobench` command line: run, design, list, runs, show, analyze, report, campaign, fpga, sim, gui, line.

This module is the entry point and the one error boundary (messages, signals, exit codes); each
subcommand lives in its own module (run, design, listing, store, analysis, sim) with
`add_parser(sub)` and its command, importing what it alone uses when it runs.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import Any


def _interrupted_early(signum: int, _frame: Any) -> None:
    """SIGINT/SIGTERM while the CLI is still importing (before main()'s error boundary): one line and
    the conventional exit code, no traceback; nothing has been opened yet, so nothing to make safe."""
    import os

    name = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
    os.write(2, f"gyrobench: interrupted ({name}) before anything started\n".encode())
    os._exit(128 + signum)


# installed before the subcommands' modules are imported (a Ctrl-C during those imports gave
# importlib's traceback, a SIGTERM a silent -15); only in the CLI's own process, not an importer:
# `gyrobench`, or `python -m bench.cli` (whose package is imported while sys.argv[0] is still "-m")
if sys.argv[0] == "-m" or sys.argv[0].endswith("gyrobench"):
    for _sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_sig, _interrupted_early)

from . import analysis, campaign, check, design, listing, run, sim, store  # noqa: E402 - after the handlers above
from .common import (  # noqa: E402
    BAD_OUTCOMES,
    EXIT_BAD_OUTCOME,
    EXIT_BROKEN_PIPE,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    _err,
    _reason,
    exit_for_signal,
)

__all__ = [
    "BAD_OUTCOMES", "EXIT_BAD_OUTCOME", "EXIT_BROKEN_PIPE", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_OK",
    "EXIT_USAGE", "CliError", "build_parser", "main",
]


_SIGNALLED: list[str] = []  # the signal that interrupted main(), if any


def _interrupt(signum: int, _frame: Any) -> None:
    """Inside main(): SIGINT and SIGTERM raise KeyboardInterrupt (the boundary prints one line); a
    run installs its own handlers that abort it into the safe state, and puts these back after.
    The signal is remembered: a library that turns the interrupt into its own error (numpy's
    import wraps it in an ImportError) is still reported as the interruption it was."""
    _SIGNALLED.append(signal.Signals(signum).name)
    raise KeyboardInterrupt(_SIGNALLED[-1])


def build_parser() -> argparse.ArgumentParser:
    """The parser of every subcommand, in the order `gyrobench --help` lists them."""
    parser = argparse.ArgumentParser(prog="gyrobench", description="Calibrate Coriolis vibratory gyroscopes.")
    parser.add_argument("--debug", action="store_true", help="print the traceback of an unexpected error")
    sub = parser.add_subparsers(dest="command", required=True)
    run.add_parser(sub)
    design.add_parser(sub)
    listing.add_parser(sub)
    check.add_parser(sub)  # check-station
    store.add_parser(sub)  # runs, show
    analysis.add_parser(sub)  # analyze, report
    campaign.add_parser(sub)  # many simulated runs on Dask
    from bench.line.fpga_cli import add_fpga_subcommand

    add_fpga_subcommand(sub)  # fpga load|show: trims in NVM (bench/line/fpga_cli.py)
    sim.add_parser(sub)
    from bench.gui.cli_args import add_gui_subcommand

    add_gui_subcommand(sub)
    from bench.line.cli import add_line_subcommand  # the production line's commands

    add_line_subcommand(sub)
    return parser


def entry() -> None:
    """The `gyrobench` command: `main()`, then exit without the interpreter's teardown of every
    module (~0.5-0.7 s after a run: numba's and LLVM's finalizers; issue 36) when no other thread
    is left: stdio flushed and the atexit handlers run (multiprocessing's, logging's, temporary
    directories') as at a normal exit."""
    import atexit
    import os

    code = main()
    if threading.active_count() > 1:  # a thread still running is joined by the normal exit
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader that left (the pipe), a closed stream
            pass
    atexit._run_exitfuncs()
    os._exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run one command.  The one error boundary: a known failure is one line and an exit code;
    anything else is one line and a saved traceback (printed with --debug), never a bare trace."""
    import os

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or bool(os.environ.get("GYROBENCH_DEBUG"))  # anywhere on the line
    argv = [a for a in argv if a != "--debug"]
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, _interrupt)
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        args = build_parser().parse_args(argv)
        code = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, inside the boundary, not at interpreter exit
        return code
    except BrokenPipeError:  # `gyrobench runs | head`: the reader left; say nothing more
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt as exc:
        return _interrupted("SIGTERM" if str(exc) == "SIGTERM" else "SIGINT")
    except CliError as exc:
        _err(str(exc))
        return exc.code
    except Exception as exc:  # noqa: BLE001 - the boundary: classify, never print a bare traceback
        if _SIGNALLED:  # the interrupt surfaced as another error (inside an import, a library)
            return _interrupted(_SIGNALLED[-1])
        return _report_exception(exc, debug)


def _interrupted(name: str) -> int:
    """One line for an interrupted command and the shell's code for it: 130 for SIGINT, 143 for SIGTERM."""
    _err("interrupted (SIGTERM)" if name == "SIGTERM" else "interrupted (Ctrl-C)")
    return exit_for_signal(signal.Signals[name])


def _known_error(exc: BaseException) -> str | None:
    """The one-line message of an error the user can act on, or None for an unexpected one."""
    from bench.validation import ValidationError

    station_error = getattr(sys.modules.get("bench.devices"), "StationError", ())  # where it lives
    param_error = getattr(sys.modules.get("bench.engine.params"), "ParamError", ())
    not_found = getattr(sys.modules.get("procedures"), "ProcedureNotFound", ())
    if isinstance(exc, (ValidationError, *[c for c in (station_error, param_error, not_found) if c])):
        return str(exc)
    if isinstance(exc, OSError) and exc.strerror:
        return _reason(exc)
    sa_exc = sys.modules.get("sqlalchemy.exc")
    if sa_exc is not None and isinstance(exc, sa_exc.SQLAlchemyError):
        return f"results store: {_reason(exc)}"
    return None


def _report_exception(exc: BaseException, debug: bool) -> int:
    import traceback

    text = "".join(traceback.format_exception(exc))
    known = _known_error(exc)
    if debug:
        print(text, file=sys.stderr, end="")
    if known is not None:
        _err(known)
        return EXIT_USAGE if isinstance(exc, ValueError | LookupError) else EXIT_BAD_OUTCOME
    saved = _save_traceback(text)
    where = f"traceback saved to {saved}" if saved else "the traceback could not be saved"
    _err(f"internal error: {type(exc).__name__}: {exc} ({where}; --debug prints it)")
    return EXIT_INTERNAL


def _save_traceback(text: str) -> str | None:
    """Write a traceback to a file in the temporary directory; its path (None if that failed)."""
    import os
    import tempfile
    from pathlib import Path

    try:
        folder = Path(tempfile.gettempdir()) / "gyrobench"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
        path.write_text(" ".join(sys.argv) + "\n\n" + text)
        return str(path)
    except OSError:
        return None


def _silence_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so the interpreter's exit flush is quiet."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
