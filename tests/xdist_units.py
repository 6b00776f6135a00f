"""The parallel pass's scheduling (pytest-xdist, `--dist loadfile`): a test file is one unit run by
one worker, so its module-scoped fixtures (often simulated runs of tens of seconds) are set up once,
not once on each worker that got some of its tests (as under worksteal); and the files are handed
out costliest first (costs from tests/costs_s.tsv), so the pass does not end with one long file alone.
(`--dist loadgroup` with xdist_group marks would group finer, but pytest 9 ignores the `@group`
that xdist 3.8 writes into an item's private `_nodeid`: every test is its own unit there.)"""

from __future__ import annotations

import sys
from collections import OrderedDict
from pathlib import Path

import pytest

#: `test_file<TAB>seconds`: each test file's wall in a parallel pass (its tests' setup to teardown),
#: written by `python tests/xdist_units.py CPU_LOG...` from $GYROBENCH_TEST_CPU_LOG files (tests/conftest.py);
#: only the order of the pass depends on it, never which tests run
COSTS_FILE = Path(__file__).with_name("costs_s.tsv")

#: the cost of a test of a file missing from COSTS_FILE (most tests take a fraction of a second)
DEFAULT_TEST_COST_S = 0.3


def load_costs(path: Path = COSTS_FILE) -> dict[str, float]:
    """test file -> seconds, from COSTS_FILE (empty when the file is missing)."""
    if not path.is_file():
        return {}
    costs = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if line and not line.startswith("#"):
            name, seconds = line.rsplit("\t", 1)
            costs[name] = float(seconds)
    return costs


def costliest_first(units: dict[str, dict[str, bool]], costs: dict[str, float]) -> OrderedDict:
    """The work units (test file -> its tests) by estimated cost, highest first (ties keep their order)."""
    return OrderedDict(sorted(units.items(), key=lambda kv: -costs.get(kv[0], DEFAULT_TEST_COST_S * len(kv[1]))))


def make_scheduler(config: pytest.Config, log):
    """loadfile's scheduler with its work queue sorted costliest first before the first unit is sent."""
    from xdist.scheduler import LoadFileScheduling

    class CostliestFirstFiles(LoadFileScheduling):
        """LoadFileScheduling whose queue of units (test files) starts with the costliest."""

        _ordered = False

        def _assign_work_unit(self, node) -> None:
            if not self._ordered:
                self.workqueue = costliest_first(self.workqueue, load_costs())
                self._ordered = True
            super()._assign_work_unit(node)

    return CostliestFirstFiles(config, log)


def file_costs(cpu_log: Path) -> dict[str, float]:
    """Each test file's summed wall seconds, from a CPU log's `nodeid cpu_self cpu_children wall ...` lines."""
    costs: dict[str, float] = {}
    for line in cpu_log.read_text(encoding="utf-8").splitlines():
        nodeid, _, _, wall_s = line.split("\t")[:4]
        name = nodeid.split("::", 1)[0]
        costs[name] = costs.get(name, 0.0) + float(wall_s)
    return costs


def write_costs(cpu_logs: list[Path], path: Path = COSTS_FILE) -> None:
    """COSTS_FILE from one or more $GYROBENCH_TEST_CPU_LOG files (a file's mean over them), costliest first."""
    runs = [file_costs(log) for log in cpu_logs]
    names = sorted({n for run in runs for n in run})
    mean = {n: sum(run.get(n, 0.0) for run in runs) / len(runs) for n in names}
    lines = ["# each test file's wall (s) in a parallel pass: `python tests/xdist_units.py CPU_LOG...` writes it"]
    lines += [f"{n}\t{s:.1f}" for n, s in sorted(mean.items(), key=lambda kv: (-kv[1], kv[0]))]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    write_costs([Path(a) for a in sys.argv[1:]])
