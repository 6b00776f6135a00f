"""Print the declared measurements of every registered procedure as Markdown tables (the README's
"Measurements" section is this output; tests/test_conventions.py checks that they agree).

    .venv/bin/python docs/measurement_tables.py
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def tables() -> str:
    """One table a procedure: name, unit, what it is, truth on a simulated station, condition."""
    from procedures import all_procedures

    out = []
    for name, cls in all_procedures().items():
        out.append(f"`{name}`:\n")
        out.append("| measurement | unit | what it is | simulator truth | measured when |")
        out.append("|---|---|---|---|---|")
        for m in cls.measurements:
            d = m.describe()
            truth = "" if d["truth"] is None else f"`{d['truth']}`" if m.truth == d["truth"] else d["truth"]
            doc = d["doc"].replace("|", "\\|")
            out.append(f"| `{d['name']}` | {d['unit'] or '-'} | {doc} | {truth} | {d['condition'] or 'always'} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(tables(), end="")
