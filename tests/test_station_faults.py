"""Each --fault kind, injected at a simulated second mid-run, gives ERROR, a confirmed safe state
(checked against the simulators' own state) and the raw data up to the fault."""

from __future__ import annotations

import pytest

from bench.recorder import open_run
from drivers.fpga import protocol as p
from procedures.examples.table_spin import TableSpin

FAULT_AT_S = 1.5  # spin-up to 100 deg/s at 500 deg/s^2 takes ~0.4 s: the fault hits during the hold


@pytest.mark.parametrize(
    "kind, reason",
    [
        ("link-drop", "link lost: FPGA link"),
        ("link-corrupt", "link lost: FPGA link"),
        ("table-estop", "safety trip: rate table tripped: estop"),
        ("table-fault", "safety trip: rate table tripped: fault"),
        ("frontend-hang", "link lost: front end"),
    ],
)
def test_fault_gives_error_safe_state_and_data_up_to_the_fault(run_procedure, sim_station, kind, reason):
    rec = run_procedure(TableSpin, {"rate_dps": 100.0, "hold_s": 4.0}, faults=[(kind, FAULT_AT_S)])
    assert rec.outcome == "ERROR" and rec.end_reason.startswith(reason), rec.end_reason
    assert rec.failed_step == "hold"
    assert rec.safe_state and rec.safe_detail["devices"] == {"fpga": True, "table": True, "frontend": True}
    assert sim_station.faults.fired and sim_station.faults.fired[0][1] == kind
    # the fault fired at the first sample boundary at or after FAULT_AT_S
    assert sim_station.faults.fired[0][0] == pytest.approx(FAULT_AT_S, abs=1e-9)
    # simulator ground truth: table at rest, drive cut
    assert abs(sim_station.handles["table"].mechanics.rate_dps) < 0.05
    assert not int(sim_station.handles["fpga"].firmware.regs["CTRL"]) & p.DRIVE_EN
    with open_run(rec.raw_file) as d:
        t = d.table("fpga")["t_s"]
        assert t[0] < 0.05 and t[-1] >= FAULT_AT_S - 0.01  # the stream up to the fault is on disk
        assert d.attrs["outcome"] == "ERROR" and d.attrs["safe_state"] is True
        log = d.log()
        assert any("safe state confirmed" in r["msg"] for r in log)
        # detected promptly: the step ended within 0.5 simulated seconds of the fault (health
        # checks every 0.2 s, clock waits sliced at 0.1 s)
        t_err = next(r["t_sim_s"] for r in log if r["msg"] == "step_error hold")
        assert FAULT_AT_S <= t_err <= FAULT_AT_S + 0.5
