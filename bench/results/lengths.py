"""The lengths of the store's columns a user types (operator, DUT serial), without SQLAlchemy:
`gyrobench run` checks them before anything opens, and importing the database stack there cost
the command ~0.15 s CPU on its main thread (issue 36); the store's thread imports it meanwhile.
`bench.results.schema` declares its columns with these numbers, so they cannot drift apart."""

from __future__ import annotations

#: `runs.operator`'s varchar length
OPERATOR_MAX = 128
#: `run_duts.serial`'s varchar length
SERIAL_MAX = 128


def check_inputs(operator: str = "", duts: list[str] | tuple[str, ...] = ()) -> None:
    """ValueError naming the option and the limit when the operator or a DUT serial is too long."""
    if len(operator or "") > OPERATOR_MAX:
        raise ValueError(f"--operator is {len(operator)} characters long; the results store keeps at most "
                         f"{OPERATOR_MAX}")
    for serial in duts:
        if len(serial) > SERIAL_MAX:
            raise ValueError(f"--dut {serial[:20]!r}... is {len(serial)} characters long; the results store keeps at "
                             f"most {SERIAL_MAX}")
