"""The declared measurements of every registered procedure as Markdown tables: the reference page
docs/reference/procedures.md is built from them (docs/reference_pages.py, at `mkdocs build`).

    .venv/bin/python docs/measurement_tables.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def table(cls: type) -> str:
    """One procedure's table: name, unit, what it is, truth on a simulated station, condition."""
    out = ["| measurement | unit | what it is | simulator truth | measured when |", "|---|---|---|---|---|"]
    for m in cls.measurements:
        d = m.describe()
        truth = "" if d["truth"] is None else f"`{d['truth']}`" if m.truth == d["truth"] else d["truth"]
        doc = d["doc"].replace("|", "\\|")
        out.append(f"| `{d['name']}` | {d['unit'] or '-'} | {doc} | {truth} | {d['condition'] or 'always'} |")
    return "\n".join(out) + "\n"


def tables() -> str:
    """One table a procedure, each under its name."""
    from procedures import all_procedures

    return "".join(f"`{name}`:\n\n{table(cls)}\n" for name, cls in all_procedures().items())


if __name__ == "__main__":
    print(tables(), end="")
