"""The whole reliability audit (issue 13): runs each class's script in turn and prints one table,
class by class, of the cases tried and the cases that ended clean (safe state, one clear message,
no record lost).  Each script can also be run on its own; see its docstring for what "clean" means.

    sudo .venv/bin/python benchmarks/reliability_audit.py          # about 15 minutes on 2 cores

Issue 39 added the class "bad inputs to every command" (reliability_commands.py: runs, show,
analyze, report, check-station, line run --window, run's labels and procedure files, signals at
import and on sim): 23 cases, 23 clean on 2026-11-28 (60 s on 2 shared cores).

The disk cases need root (tmpfs mounts); the PostgreSQL writers need $GYROBENCH_TEST_PG_URL (for
example from .ci/start-postgres), else only SQLite is tried.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: script -> the summary line's class name(s) it prints as "<class>: tried N, clean M"
SCRIPTS = (
    "reliability_faults.py",
    "reliability_inputs.py",
    "reliability_commands.py",
    "reliability_replies.py",
    "reliability_disks.py",
    "reliability_writers.py",
)
#: the audit's classes (issue 13's table); the scripts' other summary lines are subtotals
CLASSES = (
    "injected faults",
    "signals",
    "signals before the run began",
    "bad station files and parameters",
    "bad inputs to every command",
    "malformed device replies",
    "full or read-only disks",
    "concurrent writers",
)
SUMMARY = re.compile(r"^(?P<cls>[a-z][a-z ,/-]+): tried (?P<tried>\d+), clean (?P<clean>\d+)(?P<rest>.*)$")


def main() -> int:
    rows: list[tuple[str, int, int, str, float]] = []
    for script in SCRIPTS:
        t0 = time.monotonic()
        proc = subprocess.run([sys.executable, str(HERE / script)], capture_output=True, text=True)
        wall_s = time.monotonic() - t0
        found = [SUMMARY.match(line.strip()) for line in proc.stdout.splitlines()]
        found = [m for m in found if m and m["cls"] in CLASSES]
        if not found:
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["(no output)"]
            rows.append((f"{script} (no summary, exit {proc.returncode})", 0, 0, tail[0][:80], wall_s))
        for m in found:
            rows.append((m["cls"], int(m["tried"]), int(m["clean"]), m["rest"].strip(), wall_s))
        print(f"{script}: {wall_s:.0f} s", file=sys.stderr)
    width = max(len(r[0]) for r in rows)
    print(f"{'class':<{width}}  {'tried':>6}  {'clean':>6}  note")
    for cls, tried, clean, rest, _ in rows:
        print(f"{cls:<{width}}  {tried:>6}  {clean:>6}  {rest}")
    total_tried, total_clean = sum(r[1] for r in rows), sum(r[2] for r in rows)
    print(f"{'all classes':<{width}}  {total_tried:>6}  {total_clean:>6}")
    return 0 if total_tried == total_clean and total_tried > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
