"""The typed values' lengths (bench.results.lengths) are the store's columns' and load no SQLAlchemy."""

from __future__ import annotations

import subprocess
import sys

import pytest

from bench.results import lengths, limits
from bench.results.schema import run_duts, runs


def test_lengths_are_the_columns_lengths() -> None:
    assert runs.c["operator"].type.length == lengths.OPERATOR_MAX == limits.OPERATOR_MAX
    assert run_duts.c["serial"].type.length == lengths.SERIAL_MAX == limits.SERIAL_MAX


def test_check_inputs_takes_the_longest_and_refuses_one_more() -> None:
    lengths.check_inputs("o" * lengths.OPERATOR_MAX, ["s" * lengths.SERIAL_MAX])
    with pytest.raises(ValueError, match="--operator is 129 characters long"):
        lengths.check_inputs("o" * (lengths.OPERATOR_MAX + 1))
    with pytest.raises(ValueError, match="--dut .* is 129 characters long"):
        lengths.check_inputs("", ["ok", "s" * (lengths.SERIAL_MAX + 1)])


def test_the_check_imports_no_database_stack() -> None:
    code = "import sys, bench.results.lengths; assert 'sqlalchemy' not in sys.modules, 'sqlalchemy imported'"
    subprocess.run([sys.executable, "-c", code], check=True)
