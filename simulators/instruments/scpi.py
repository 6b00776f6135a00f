"""The SCPI parts every simulated bench instrument shares: `;`-separated commands, IEEE 488.2
common commands and an error queue (`SYST:ERR?`), so each model only says what its own commands do."""

from __future__ import annotations

from collections import deque


class ScpiError(Exception):
    """A command the instrument refuses: its SCPI error number and text go to the error queue."""

    def __init__(self, code: int, text: str) -> None:
        super().__init__(text)
        self.code = code


UNDEFINED_HEADER = -113
DATA_OUT_OF_RANGE = -222
ILLEGAL_PARAMETER = -224


class ScpiInstrument:
    """One instrument: `execute(line)` runs each `;`-separated command and joins the answers."""

    idn = "SIMULATED,INSTRUMENT,0,0"

    def __init__(self) -> None:
        self.errors: deque[tuple[int, str]] = deque(maxlen=20)

    def execute(self, line: str) -> str | None:
        answers = []
        for part in line.strip().split(";"):
            command = part.strip()
            if not command:
                continue
            try:
                answer = self.common(command)
                if answer is NotImplemented:
                    answer = self.command(command.upper().split(None, 1)[0], command.split(None, 1)[1:])
            except ScpiError as exc:
                self.errors.append((exc.code, str(exc)))
                continue
            if answer is not None:
                answers.append(answer)
        return ";".join(answers) if answers else None

    def common(self, command: str) -> str | None:
        head = command.upper()
        if head == "*IDN?":
            return self.idn
        if head == "*RST":
            self.reset()
            return None
        if head == "*CLS":
            self.errors.clear()
            return None
        if head in ("SYST:ERR?", "SYSTEM:ERROR?", "SYST:ERR:NEXT?"):
            code, text = self.errors.popleft() if self.errors else (0, "No error")
            return f'{code},"{text}"'
        if head == "*OPC?":
            return "1"
        return NotImplemented

    def reset(self) -> None:
        """*RST: the model's power-on state."""

    def command(self, header: str, args: list[str]) -> str | None:
        """One non-common command (header upper-cased, args the rest of it)."""
        raise ScpiError(UNDEFINED_HEADER, f"Undefined header {header}")

    @staticmethod
    def number(args: list[str], low: float, high: float) -> float:
        """The one numeric argument, within [low, high] (the instrument's range)."""
        try:
            value = float(args[0].split(",")[0])
        except (IndexError, ValueError):
            raise ScpiError(ILLEGAL_PARAMETER, f"Illegal parameter value {args!r}") from None
        if not low <= value <= high:
            raise ScpiError(DATA_OUT_OF_RANGE, f"Data out of range {value:g} (allowed {low:g}..{high:g})")
        return value
