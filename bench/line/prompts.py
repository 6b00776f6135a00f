"""The operator's prompts at a line station: scan the serial, confirm the fixture, confirm before
the table spins, show the outcome.  Headless runs are pre-answered by flags (--dut, --yes); a
prompt that is needed when standard input is not a terminal is refused with one message."""

from __future__ import annotations

import sys
from typing import Protocol

from . import LineError


class Operator(Protocol):
    def scan_serial(self) -> str: ...
    def confirm(self, question: str) -> bool: ...
    def show_outcome(self, serial: str, outcome: str, summary: str) -> None: ...


class ConsoleOperator:
    """Prompts on the terminal, answered in advance by the serial given and --yes."""

    def __init__(self, serial: str | None, assume_yes: bool, interactive: bool) -> None:
        self.serial, self.assume_yes, self.interactive = serial, assume_yes, interactive

    def _need_terminal(self, what: str, flag: str) -> None:
        if not self.interactive:
            raise LineError(f"{what}: standard input is not a terminal; give {flag} in a headless run")

    def scan_serial(self) -> str:
        if self.serial:
            return self.serial
        self._need_terminal("the unit's serial is needed", "--dut SERIAL")
        serial = input("scan the unit's serial: ").strip()
        if not serial:
            raise LineError("no serial scanned; the unit is not tested")
        return serial

    def confirm(self, question: str) -> bool:
        if self.assume_yes:
            return True
        self._need_terminal(f"{question!r} needs an answer", "--yes")
        return input(f"{question} [y/N] ").strip().lower() in ("y", "yes")

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        print(f"{serial}: {outcome}  {summary}", flush=True)


def make_operator(*, serial: str | None, assume_yes: bool, interactive: bool) -> Operator:
    """The operator of `gyrobench line run` (interactive: stdin is a terminal)."""
    return ConsoleOperator(serial, assume_yes, interactive)


def stdin_is_terminal() -> bool:
    try:
        return sys.stdin.isatty()
    except (AttributeError, ValueError):
        return False
