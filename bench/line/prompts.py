"""The line operator's prompts on the command line: scan the serial, confirm the fixture and a
table spin, show the unit's outcome as one big coloured line (rich).

Headless runs are pre-answered by flags (`--dut SERIAL`, `--yes`); a prompt that is needed with
neither a terminal nor a pre-answer is one clear error naming the flag to pass (OperatorError).

A serial is upper-cased, stripped of spaces and checked against the product's format (its limits
file's `serial_format`; by default 1 to 40 letters, digits, '.', '_' or '-', starting with a letter
or digit: what a barcode scanner types), within 40 characters, no control character (bench/line/inputs.py)."""

from __future__ import annotations

import sys
from typing import Protocol, TextIO

from rich.markup import escape

from bench.validation import ValidationError

OUTCOME_STYLES = {"PASS": "bold white on green", "FAIL": "bold white on red", "MARGINAL": "bold black on yellow"}


class OperatorError(ValidationError):
    """A prompt that cannot be answered (no terminal, no flag) or a serial that is not valid."""


class Operator(Protocol):
    """What a line sequence asks of its operator."""

    def scan_serial(self) -> str: ...

    def confirm(self, question: str) -> bool: ...

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None: ...


def check_serial(text: str, fmt: str | None = None) -> str:
    """The serial, normalised (stripped, upper case); OperatorError names it and the rule."""
    from . import LineError
    from .inputs import check_serial as checked

    try:
        return checked(text, fmt)
    except LineError as exc:
        raise OperatorError(str(exc)) from None


class CliOperator:
    """The operator at a terminal, or none (headless: only pre-answers)."""

    def __init__(self, *, serial: str | None, assume_yes: bool, interactive: bool,
                 stdin: TextIO | None = None, stdout: TextIO | None = None, serial_format: str | None = None) -> None:
        self.serial_format = serial_format
        self.serial = None if serial is None else check_serial(serial, serial_format)  # a bad --dut is refused at once
        self.assume_yes = bool(assume_yes)
        self.stdin = stdin or sys.stdin
        self.stdout = stdout or sys.stdout
        self.interactive = bool(interactive) and _isatty(self.stdin) and _isatty(self.stdout)
        from rich.console import Console

        self.console = Console(file=self.stdout, force_terminal=self.interactive or None, highlight=False)

    def scan_serial(self) -> str:
        if self.serial is not None:
            return self.serial
        if not self.interactive:
            raise OperatorError("no serial to test: give --dut SERIAL (no terminal to scan it on)")
        while True:
            self.console.print("[bold]Scan the unit's serial:[/bold] ", end="")
            line = self.stdin.readline()
            if not line:  # end of input: nobody is there
                raise OperatorError("no serial scanned (input closed): give --dut SERIAL")
            try:
                self.serial = check_serial(line, self.serial_format)
                return self.serial
            except OperatorError as exc:
                self.console.print(f"[red]{escape(str(exc))}[/red]")

    def confirm(self, question: str) -> bool:
        if self.assume_yes:
            return True
        if not self.interactive:
            raise OperatorError(f"{question!r} needs an answer: give --yes (no terminal to ask on)")
        while True:
            self.console.print(f"[bold]{escape(question)}[/bold] {escape('[y/n]')} ", end="")
            line = self.stdin.readline()
            if not line:
                raise OperatorError(f"{question!r} was not answered (input closed): give --yes")
            answer = line.strip().lower()
            if answer in ("y", "yes"):
                return True
            if answer in ("n", "no"):
                return False
            self.console.print("[red]answer y or n[/red]")

    def show_outcome(self, serial: str, outcome: str, summary: str) -> None:
        if not self.interactive:  # headless: one line on stderr (stdout may carry --json)
            print(f"{outcome} {serial}" + (f"  {summary}" if summary else ""), file=sys.stderr, flush=True)
            return
        from rich.panel import Panel
        from rich.text import Text

        style = OUTCOME_STYLES.get(outcome, "bold white on blue")
        big = Text(f"  {outcome}  ", style=style, justify="center")
        body = Text.assemble(big, "\n", (serial, "bold"), ("\n" + summary if summary else ""))
        body.justify = "center"
        self.console.print(Panel(body, border_style=style.split(" on ")[-1], expand=True))


def stdin_is_terminal() -> bool:
    """Whether standard input is a terminal (an operator could answer there)."""
    return _isatty(sys.stdin)


def _isatty(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def make_operator(*, serial: str | None, assume_yes: bool, interactive: bool,
                  serial_format: str | None = None) -> Operator:
    """The line's operator: pre-answered by `serial` (--dut) and `assume_yes` (--yes); asks on the
    terminal only when `interactive` and stdin/stdout are one; serials in the product's format."""
    return CliOperator(serial=serial, assume_yes=assume_yes, interactive=interactive, serial_format=serial_format)
