"""The lengths the results store keeps (its varchar columns): checked where a value is typed (the
run refuses a too-long DUT serial or operator before anything moves) and before a record is sent
(a record the store would refuse is named and quarantined, never retried forever)."""

from __future__ import annotations

from typing import Any

from sqlalchemy import String, Table

from .lengths import check_inputs  # typed values: checked without SQLAlchemy (bench.results.lengths)
from .schema import measurements, run_duts, runs, truth


class RecordRefused(Exception):
    """The store will never take this record as it is (a value too long, a broken constraint)."""


def max_chars(table: Table, column: str) -> int | None:
    """The longest text `table.column` keeps (None: unbounded)."""
    col_type = table.c[column].type
    return col_type.length if isinstance(col_type, String) else None


OPERATOR_MAX = max_chars(runs, "operator")
SERIAL_MAX = max_chars(run_duts, "serial")
__all__ = ["OPERATOR_MAX", "SERIAL_MAX", "RecordRefused", "check_doc", "check_inputs", "max_chars"]


def _check_row(table: Table, row: dict[str, Any], where: str) -> None:
    for name, value in row.items():
        if not isinstance(value, str) or name not in table.c:
            continue
        limit = max_chars(table, name)
        if limit is not None and len(value) > limit:
            raise RecordRefused(f"{where}{name} is {len(value)} characters long; the store keeps at most {limit}")


def check_doc(doc: dict[str, Any]) -> None:
    """RecordRefused when a store document holds a text longer than its column keeps."""
    _check_row(runs, doc["run"], "")
    for serial in doc.get("duts") or ():
        _check_row(run_duts, {"serial": serial}, "DUT ")
    for name in doc.get("truth") or {}:
        _check_row(truth, {"name": name}, "truth ")
    for m in doc.get("measurements") or ():
        _check_row(measurements, m, "measurement ")
