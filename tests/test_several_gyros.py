"""Several gyros on one table (#18): four simulated HRGs with different resonators calibrated in one
batch through the real transports, each judged against its own truth; a link drop aimed at slot 3
ends slot 3 alone in ERROR with its own safe state; an abort stops all four safely; the engine's
lock on a shared instrument never deadlocks; seeded batches are reproducible; station files."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest

from bench.composition import load_station
from bench.devices import StationError
from bench.engine.batch import Batch, BatchError, check_batchable
from bench.slots import BATCH_ROLES, SlotLock
from bench.station_config import load_config
from drivers.fpga import protocol as p
from procedures.hrg_damping import HrgDamping

#: short enough for the tests, long enough that the decay fit's intervals are honest (tau ~ 300 s)
SHORT = {"record_s": 300.0, "verify_s": 30.0}
SEQUENCE = """
[sequence]
name = "eol-hrg-test"

[[step]]
procedure = "hrg-damping"
[step.params]
compensate = true
record_s = 300.0
verify_s = 30.0
"""
#: the shipped HRG limits of the damping step (split_hz is the free decay's, not run here)
LIMITS = """
[product]
name = "hrg-5500-damping"
rule = "guard-band"

[limits.tau_s]
low = 250.0
high = 400.0
unit = "s"

[limits.delta_inv_tau_per_s]
high = 2.5e-4
unit = "1/s"

[limits.drift_after_dph]
high = 8.0
unit = "deg/h"
rule = "value"
marginal_high = 5.0
"""


class _Yes:
    def confirm(self, question: str) -> bool:
        return True

    def show_outcome(self, *args) -> None:
        pass


def _drive_on(station, slot: int) -> bool:
    return bool(int(station.handles[(slot, "fpga")].firmware.regs["CTRL"]) & p.DRIVE_EN)


def _table_rate(station) -> float:
    return station.handles[(None, "table")].mechanics.rate_dps


@pytest.fixture(scope="module")
def line_batch(tmp_path_factory):
    """eol-hrg (damping with compensation) on sim-hrg-4, a link drop into slot 3 at 150 s."""
    from bench.line.batch_run import run_batch_attempt
    from bench.line.db import LineDB
    from bench.line.limits import load_limits
    from bench.line.run import LineContext
    from bench.line.sequence import load_sequence
    from bench.results import ResultsStore

    tmp = tmp_path_factory.mktemp("batch")
    seq_file = tmp / "seq.toml"
    seq_file.write_text(SEQUENCE)
    (tmp / "limits.toml").write_text(LIMITS)
    url = str(tmp / "results.sqlite")
    store, db = ResultsStore(url, offline_ok=True, spool_dir=tmp / "spool"), LineDB(url)
    # no certificate PDFs (LineContext.pdf): no test here reads them (tests/test_certificate.py and
    # test_line_cli.py do); WeasyPrint took ~3 s of CPU for the four
    ctx = LineContext(load_sequence(seq_file), load_limits(tmp / "limits.toml"), "sim-hrg-4", "tester", tmp,
                      store=store, db=db, pdf=False)
    station = load_station("sim-hrg-4", seed=0).open()  # slots in spec: 1, 2 and 4 must PASS
    try:
        station.schedule_fault("link-drop", 150.0, slot=3)
        records = run_batch_attempt(ctx, station, {1: "S1", 2: "S2", 3: "S3", 4: "S4"}, _Yes())
        truths = {n: station.truth(n) for n in station.slots}
        after = {"table_rate_dps": _table_rate(station), "drive_on": {n: _drive_on(station, n) for n in station.slots}}
        yield {"records": records, "truths": truths, "after": after, "store": store, "tmp": tmp}
    finally:
        station.close()
        store.close()
        db.close()


def test_four_hrgs_with_different_resonators_each_match_their_own_truth(line_batch):
    recs = {r["slot"]: r for r in line_batch["records"]}
    truths = line_batch["truths"]
    taus = [truths[n]["tau_s"] for n in (1, 2, 3, 4)]
    assert len({round(t, 3) for t in taus}) == 4  # four different resonators (a seed per slot)
    for n in (1, 2, 4):
        rec = recs[n]
        assert rec["outcome"] == "PASS", rec["summary"]
        assert rec["serial"] == f"S{n}" and rec["batch"]["serials"]["3"] == "S3"
        checked = 0
        for m in rec["measurements"]:
            if m["name"] in ("tau_s", "delta_inv_tau_per_s") and m["value"] is not None:
                assert m["truth"] == pytest.approx(truths[n][m["name"]], rel=1e-12)  # its own slot's truth
                lo, hi = m["interval"]
                assert lo <= m["truth"] <= hi, (n, m)
                checked += 1
        assert checked == 2
        # the unit's run is its own: its raw file holds its own slot's truth
        run = rec["runs"][0]
        assert run["run_id"].endswith(f"-slot{n}") and Path(run["raw_file"]).exists()


def test_link_drop_into_slot_3_ends_slot_3_alone_in_error_with_its_own_safe_state(line_batch):
    recs = {r["slot"]: r for r in line_batch["records"]}
    run3 = recs[3]["runs"][0]
    assert recs[3]["outcome"] == "ERROR"
    assert run3["outcome"] == "ERROR" and run3["end_reason"].startswith("link lost: FPGA link"), run3["end_reason"]
    assert run3["safe_state"] is True
    assert 150.0 <= run3["simulated_s"] <= 150.5  # found within the 0.4 s grid (plus its safe state)
    for n in (1, 2, 4):
        assert recs[n]["runs"][0]["simulated_s"] > 300.0  # the others went on to the end
    after = line_batch["after"]
    assert abs(after["table_rate_dps"]) < 0.05  # the table at rest once no slot needed it
    assert not any(after["drive_on"].values())


def test_the_batch_is_one_run_with_four_duts_in_the_store(line_batch):
    store = line_batch["store"]
    batch_id = line_batch["records"][0]["runs"][0]["batch_run_id"]
    assert all(r["runs"][0]["batch_run_id"] == batch_id for r in line_batch["records"])
    row = store.get_run(batch_id)
    assert row["duts"] == ["S1", "S2", "S3", "S4"]
    assert row["outcome"] == "ERROR"  # the worst slot's
    duts = {m["dut"] for m in row["measurements"]}
    assert duts == {"S1", "S2", "S3", "S4"}
    assert row["truth"]["S2:tau_s"] == pytest.approx(line_batch["truths"][2]["tau_s"])


@pytest.mark.serial  # a watcher thread polling every 5 ms must abort within 0.5 simulated s: run alone
def test_abort_stops_all_four_safely(tmp_path):
    station = load_station("sim-hrg-4", seed=2).open()
    try:
        batch = Batch(station, {1: "A1", 2: "A2", 3: "A3", 4: "A4"}, runs_dir=tmp_path)
        asked: dict[str, float] = {}

        def abort_at(sim_s: float) -> None:  # mid-record, the table at 500 deg/s
            while station.base_clock.now() < sim_s:
                time.sleep(0.005)
            asked["sim_s"], asked["wall_s"] = station.base_clock.now(), time.monotonic()
            batch.abort("operator abort")

        watcher = threading.Thread(target=abort_at, args=(60.0,), daemon=True)
        watcher.start()
        records = batch.run(lambda: HrgDamping(SHORT))
        watcher.join()
        assert set(records) == {1, 2, 3, 4}
        for n, rec in records.items():
            assert rec.outcome == "ABORTED" and rec.end_reason == "aborted: operator abort", (n, rec.end_reason)
            assert rec.safe_state
            assert rec.simulated_s <= asked["sim_s"] + 0.5  # within 0.5 simulated s of the abort
            assert not _drive_on(station, n)
        assert batch.table_report.confirmed and abs(_table_rate(station)) < 0.05
    finally:
        station.close()


def test_seeded_batches_are_the_same_whatever_the_thread_scheduling(tmp_path):
    results = []
    for _ in range(2):
        station = load_station("sim-hrg-4", seed=5).open()
        try:
            recs = Batch(station, {1: "D1", 2: "D2", 3: "D3", 4: "D4"}).run(
                lambda: HrgDamping({"record_s": 30.0, "compensate": False}))
        finally:
            station.close()
        results.append({n: ([(m.name, m.value, m.ci95) for m in r.measurements], r.simulated_s)
                        for n, r in recs.items()})
    assert results[0] == results[1]


@pytest.mark.serial  # lock hand-overs timed to 0.2 s of wall time: run alone
def test_a_slot_that_dies_holding_a_shared_instrument_does_not_deadlock_the_others():
    broken = []
    lock = SlotLock("frontend", deadline_wall_s=0.3, on_break=lambda slot, th, why: broken.append((slot, why)))
    dead = threading.Thread(target=lambda: lock.acquire(1))  # takes the lock and ends without giving it back
    dead.start()
    dead.join()
    t0 = time.monotonic()
    assert lock.acquire(2) and lock.holder == 2
    assert time.monotonic() - t0 < 0.2  # its thread had ended: taken back at once
    assert broken and broken[0][0] == 1 and "ended" in broken[0][1]
    lock.release(2)

    hung = threading.Event()

    def hang() -> None:  # takes the lock and never gives it back while alive
        lock.acquire(3)
        hung.wait(5.0)

    th = threading.Thread(target=hang, daemon=True)
    th.start()
    while lock.holder != 3:
        time.sleep(0.001)
    t0 = time.monotonic()
    assert lock.acquire(4) and lock.holder == 4
    assert 0.25 <= time.monotonic() - t0 < 1.0  # after the deadline, not before, and never a deadlock
    assert broken[-1][0] == 3 and "deadline" in broken[-1][1]
    lock.release(3)  # the slot that lost it gives it back late: a no-op
    assert lock.holder == 4
    hung.set()


def test_a_step_that_mixes_the_table_with_a_slots_devices_is_refused():
    from bench.engine import Procedure, step

    class Mixed(Procedure):
        name = "mixed-test"

        @step("Stop the table and drive", uses=("table", "fpga"))
        def both(self, ctx):
            pass

    with pytest.raises(BatchError, match="split it"):
        check_batchable(Mixed, BATCH_ROLES)
    check_batchable(HrgDamping, BATCH_ROLES)


@pytest.mark.parametrize("body, message", [
    ('[slots.1.fpga]\ndriver = "fpga-link"\n[slots.3.fpga]\ndriver = "fpga-link"\n', "without a gap"),
    ('[slots.1.table]\ndriver = "modbus-table"\n', "share one table"),
    ('[slots.1.frontend]\ndriver = "scpi-frontend"\n', "already shared"),
    ('[slots.1.fpga]\ndriver = "fpga-link"\n[slots.2.fpga]\ndriver = "fpga-link"\n'
     '[slots.2.instr]\ndriver = "pymeasure"\nclass = "x.Y"\n', "every slot the same roles"),
])
def test_station_file_slots_are_checked(tmp_path, body, message):
    path = tmp_path / "bad.toml"
    path.write_text('[station]\nid = "bad"\n[simulation]\n[devices.table]\ndriver = "modbus-table"\n'
                    '[devices.frontend]\ndriver = "scpi-frontend"\n' + body)
    with pytest.raises(StationError, match=message):
        load_config(path)


def test_shipped_several_gyros_stations():
    hrg4, mems4 = load_config("sim-hrg-4"), load_config("sim-mems-4")
    assert sorted(hrg4.slots) == [1, 2, 3, 4] and set(hrg4.devices) == {"table", "frontend"}
    assert all(set(s) == {"fpga"} for s in hrg4.slots.values())
    assert set(mems4.devices) == {"table"} and all(set(s) == {"frontend", "fpga"} for s in mems4.slots.values())
    assert json.dumps(hrg4.slots)  # plain data


class _CountingWorld:
    """The least of a World a SimClock needs, counting the advances it is asked for."""

    sample_period_s = 1e-3

    def __init__(self) -> None:
        self.sample_index = 0
        self.advances: list[int] = []

    @property
    def t_s(self) -> float:
        return self.sample_index * self.sample_period_s

    def add_listener(self, callback, *, each_block: bool = True) -> None:
        pass

    def advance_samples(self, n: int) -> None:
        self.advances.append(n)
        self.sample_index += n


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 1, 0), (1, 2, 0)])
def test_the_shared_clock_advances_to_the_earliest_wake_up_once_every_slot_waits(order):
    from bench.clock import SimClock, SlotClock

    world = _CountingWorld()
    clock = SlotClock(SimClock(world))
    waits = {0: [0.3, 0.3, 0.4], 1: [0.5, 0.5], 2: [0.1, 0.9]}  # simulated seconds, per slot
    woke: dict[int, list[int]] = {k: [] for k in waits}
    start = threading.Barrier(3)

    def slot(k: int) -> None:
        clock.join()
        start.wait()
        time.sleep(0.01 * order.index(k))  # threads come to their waits in a different order each case
        for dt in waits[k]:
            clock.sleep(dt)
            woke[k].append(world.sample_index)
        clock.leave()

    threads = [threading.Thread(target=slot, args=(k,)) for k in order]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert woke == {0: [300, 600, 1000], 1: [500, 1000], 2: [100, 1000]}
    # one advance to each distinct wake-up, whatever the order the threads came in
    assert world.advances == [100, 200, 200, 100, 400]


def test_a_slot_that_dies_holding_the_front_end_lock_in_a_batch_leaves_the_others_their_turn():
    from bench.engine import Procedure, step

    class Grab(Procedure):
        """Slot 2 takes the shared front end's lock and dies holding it; the others then use it."""

        name = "grab-test"
        requires = ("frontend",)

        @step("Use the front end", uses=("frontend",))
        def use(self, ctx):
            st = ctx.station
            if st.slot_number == 2:
                st.batch.locks["frontend"].acquire(2)  # never given back
                raise RuntimeError("slot 2 dies holding the front-end lock")
            ctx.sleep(1.0)
            ctx.devices.frontend.set_drive(1, output_on=False)  # its turn, switched to its slot

    station = load_station("sim-hrg-4", seed=3).open()
    try:
        records = Batch(station, {1: "L1", 2: "L2", 3: "L3", 4: "L4"}).run(Grab)
        lock = station.locks["frontend"]
        assert records[2].outcome == "ERROR" and "dies holding" in records[2].end_reason
        assert all(records[n].outcome == "COMPLETE" for n in (1, 3, 4)), {n: r.end_reason for n, r in records.items()}
        assert lock.broken and "slot 2" in lock.broken[0] and lock.holder is None
    finally:
        station.close()
