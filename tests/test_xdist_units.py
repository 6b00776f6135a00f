"""The parallel pass's scheduling (tests/xdist_units.py): whole test files, costliest first."""

from __future__ import annotations

from pathlib import Path

from tests.xdist_units import DEFAULT_TEST_COST_S, costliest_first, load_costs, write_costs

ROOT = Path(__file__).resolve().parents[1]


def test_files_go_out_costliest_first_an_unlisted_one_at_the_default_per_test():
    costs = {"a.py": 5.0, "b.py": 7.0, "c.py": 6.0}
    units = {"a.py": {"a.py::t1": False},
             "b.py": {"b.py::t1": False, "b.py::t2": False},
             "c.py": {"c.py::t1": False},
             "d.py": {f"d.py::t{i}": False for i in range(100)},  # 100 x 0.3 s = 30 s
             "e.py": {"e.py::t1": False},  # 0.3 s
             "f.py": {"f.py::t1": False}}  # 0.3 s: a tie keeps the collection's order
    assert DEFAULT_TEST_COST_S == 0.3
    order = costliest_first(units, costs)
    assert list(order) == ["d.py", "b.py", "c.py", "a.py", "e.py", "f.py"]
    assert order["b.py"] == units["b.py"]  # a file's tests stay together, in their order


def test_costs_written_from_cpu_logs_are_read_back_summed_per_file_and_averaged(tmp_path):
    log = tmp_path / "cpu.log"
    log.write_text("t.py::a\t1.00\t0.00\t12.34\tgw0\t1.0\nt.py::b[x::y]\t0.10\t2.00\t0.50\tgw1\t2.0\nu.py::c\t0\t0\t20\n",
                   encoding="utf-8")
    write_costs([log], tmp_path / "costs.tsv")
    assert list(load_costs(tmp_path / "costs.tsv").items()) == [("u.py", 20.0), ("t.py", 12.8)]
    other = tmp_path / "cpu2.log"
    other.write_text("t.py::a\t1.00\t0.00\t7.2\n", encoding="utf-8")  # u.py not in this run: 0 s there
    write_costs([log, other], tmp_path / "costs.tsv")
    assert list(load_costs(tmp_path / "costs.tsv").items()) == [("t.py", 10.0), ("u.py", 10.0)]
    assert load_costs(tmp_path / "missing.tsv") == {}


def test_every_file_in_the_shipped_costs_is_a_test_file():
    costs = load_costs()
    assert len(costs) > 100
    assert [n for n in costs if not (ROOT / n).is_file() or not n.startswith("tests/test_")] == []
