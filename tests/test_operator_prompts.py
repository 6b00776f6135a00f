"""The line operator's CLI prompts (bench/line/prompts.py): on a real pty (a child process whose
terminal is a pty we type into), pre-answered by flags, and headless with one clear message."""

from __future__ import annotations

import io
import os
import select
import subprocess
import sys
import time

import pytest

from bench.line.prompts import OperatorError, check_serial, make_operator

SCRIPT = """
from bench.line.prompts import make_operator
op = make_operator(serial=None, assume_yes=False, interactive=True)
serial = op.scan_serial()
fixture = op.confirm("Is the unit in the fixture?")
spin = op.confirm("Spin the table?")
op.show_outcome(serial, "MARGINAL" if fixture and not spin else "FAIL", "drift_after_dph straddles 0.5")
print("DONE", serial, fixture, spin)
"""


class _Pty:
    """A child python running SCRIPT with a pty as its terminal."""

    def __init__(self) -> None:
        self.master, slave = os.openpty()
        env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "60", "NO_COLOR": ""}
        env.pop("NO_COLOR")
        self.proc = subprocess.Popen([sys.executable, "-c", SCRIPT], stdin=slave, stdout=slave, stderr=slave,
                                     env=env, close_fds=True)
        os.close(slave)
        self.out = b""

    def expect(self, text: bytes, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while text not in self.out:
            left = deadline - time.monotonic()
            assert left > 0, f"{text!r} not seen in {self.out!r}"
            ready, _, _ = select.select([self.master], [], [], left)
            if ready:
                try:
                    self.out += os.read(self.master, 4096)
                except OSError:
                    break
        assert text in self.out, self.out

    def send(self, line: str) -> None:
        os.write(self.master, line.encode() + b"\r")

    def close(self) -> int:
        try:
            return self.proc.wait(timeout=20)
        finally:
            os.close(self.master)


def test_prompts_on_a_pty_reprompt_a_bad_serial_and_show_a_big_coloured_outcome():
    pty = _Pty()
    try:
        pty.expect(b"Scan the unit's serial:")
        pty.send("x!")  # not a serial: said so, asked again
        pty.expect(b"serial 'x!' is not valid")
        pty.expect(b"Scan the unit's serial:", 5)
        pty.send("hrg-2611-0042")
        pty.expect(b"Is the unit in the fixture?")
        pty.expect(b"[y/n]")
        pty.send("maybe")
        pty.expect(b"answer y or n")
        pty.send("y")
        pty.expect(b"Spin the table?")
        pty.send("n")
        pty.expect(b"DONE HRG-2611-0042 True False")
    finally:
        code = pty.close()
    assert code == 0
    text = pty.out.decode(errors="replace")
    assert "MARGINAL" in text and "drift_after_dph straddles 0.5" in text
    assert "\x1b[" in text and ";43m" in text  # coloured: a yellow background for MARGINAL


def test_headless_is_pre_answered_by_flags():
    op = make_operator(serial=" hrg-7 ", assume_yes=True, interactive=False)
    assert op.scan_serial() == "HRG-7"
    assert op.confirm("Spin the table?") is True


def test_headless_without_pre_answers_names_the_flag(capsys):
    op = make_operator(serial=None, assume_yes=False, interactive=True)  # pytest's stdin is no terminal
    with pytest.raises(OperatorError) as err:
        op.scan_serial()
    assert str(err.value) == "no serial to test: give --dut SERIAL (no terminal to scan it on)"
    with pytest.raises(OperatorError) as err:
        op.confirm("Spin the table?")
    assert str(err.value) == "'Spin the table?' needs an answer: give --yes (no terminal to ask on)"
    op.show_outcome("HRG-7", "PASS", "8 measurements")
    out = capsys.readouterr()
    assert out.err == "PASS HRG-7  8 measurements\n" and out.out == ""  # stdout may carry --json


@pytest.mark.parametrize("bad", ["", "-AB1", "A B1", "A" * 41, "HRG/1", "_X"])
def test_serial_rule(bad):
    assert check_serial(" x ") == "X" and check_serial("sn-9.b_2") == "SN-9.B_2"
    with pytest.raises(OperatorError, match="is not valid: "):
        check_serial(bad)
    with pytest.raises(OperatorError):
        make_operator(serial=bad, assume_yes=True, interactive=False)


def test_input_closed_names_the_flag():
    from bench.line.prompts import CliOperator

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    op = CliOperator(serial=None, assume_yes=False, interactive=True, stdin=Tty(""), stdout=Tty())
    with pytest.raises(OperatorError, match="input closed.*give --dut SERIAL"):
        op.scan_serial()
