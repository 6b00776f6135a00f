"""Station files: bad ones are refused naming file, key, value and range; the simulated station
runs the example procedure through the real drivers; abort at each step leaves the table at rest,
the drive cut and the outputs off (read from the simulators' own state, not the drivers)."""

from __future__ import annotations

import pytest

from bench.composition import load_station
from bench.composition.sim_station import SimStation
from bench.devices import StationError
from bench.engine import Runner, events
from bench.fault_kinds import FAULTS, parse_fault
from bench.station_config import load_config
from procedures.examples.table_spin import TableSpin
from simulators.physics.params import preset

GOOD = """
[station]
id = "lab-1"
[devices.table]
driver = "modbus-table"
host = "10.0.0.5"
max_rate_dps = 800.0
max_accel_dps2 = 200.0
"""


def _write(tmp_path, text):
    path = tmp_path / "station.toml"
    path.write_text(text)
    return path


def test_real_station_file_is_checked_not_connected(tmp_path):
    cfg = load_config(_write(tmp_path, GOOD))
    assert cfg.id == "lab-1" and cfg.simulation is None
    assert cfg.devices["table"]["max_rate_dps"] == 800.0 and cfg.devices["table"]["port"] == 502
    st = load_station(_write(tmp_path, GOOD))
    assert not st.simulated and st.truth() is None


@pytest.mark.parametrize(
    "change, expect",
    [
        (("max_rate_dps = 800.0", "max_rate_dps = 50000.0"), ["max_rate_dps=50000 deg/s is above the limit 20000"]),
        (("max_accel_dps2 = 200.0", "max_accel_dps2 = -1.0"), ["max_accel_dps2=-1 deg/s^2 is below the limit 0.001"]),
        (("max_rate_dps = 800.0", 'max_rate_dps = "fast"'), ["max_rate_dps='fast' is not a number"]),
        (
            ('driver = "modbus-table"', 'driver = "telnet-table"'),
            ["driver='telnet-table' is not one of", "ascii-table, modbus-table"],
        ),
        (('driver = "modbus-table"', 'driver = "fpga-link"'), ["(it is a fpga driver)"]),
        (('host = "10.0.0.5"', 'hots = "10.0.0.5"'), ["hots: unknown key (allowed: device_id, driver, host,"]),
        (("[devices.table]", "[devices.turntable]"), ["unknown role 'turntable'"]),
        (('id = "lab-1"', 'name = "lab-1"'), ["[station] name: unknown key (allowed: axis_azimuth_deg,"]),
        (("[station]", "[station\n"), ["not valid TOML"]),
        (("[station]", "[simulation]\nseed = -3\n[station]"), ["[simulation] seed=-3 is below the limit 0"]),
        (("[station]", "[simulation]\npreset = 'fog'\n[station]"),
         ["preset='fog' is not one of hrg, hrg-wa, hrg-selfcal, hrg-selfcal-gains, mems"]),
    ],
)
def test_bad_station_files_name_file_key_value_and_range(tmp_path, change, expect):
    path = _write(tmp_path, GOOD.replace(*change))
    with pytest.raises(StationError) as info:
        load_config(path)
    msg = str(info.value)
    assert str(path) in msg
    for part in expect:
        assert part in msg, msg


def test_real_devices_need_an_address(tmp_path):
    path = _write(tmp_path, GOOD + '\n[devices.fpga]\ndriver = "fpga-link"\n')
    with pytest.raises(StationError, match=r"\[devices.fpga\] url: missing key \(a real device needs its address\)"):
        load_config(path)


def test_unknown_station_and_faults():
    with pytest.raises(StationError, match=r"built-in: .*\bsim-hrg, .*\bsim-mems\)"):
        load_config("no-such-station")
    assert parse_fault("link-drop@2.5") == ("link-drop", 2.5)
    for bad, part in (
        ("link-drop", "KIND@SECONDS"),
        ("meteor@1", "not one of"),
        ("table-estop@-1", "time=-1 s is below the limit 0 s"),
        ("table-estop@soon", "not a number"),
    ):
        with pytest.raises(StationError, match=part.replace("[", r"\[").replace(")", r"\)")):
            parse_fault(bad)
    assert set(FAULTS) == {"link-drop", "link-corrupt", "table-estop", "table-fault", "frontend-hang"}


@pytest.mark.parametrize("name, key", [("sim-hrg", "hrg"), ("sim-mems", "mems")])
def test_builtin_sim_stations_truth_is_the_preset(name, key):
    st = SimStation(name, seed=3)
    try:
        assert st.truth() == preset(key).truth() and st.seed == 3
    finally:
        st.close()


def _at_rest_and_safe(st: SimStation) -> None:
    mech = st.handles["table"].mechanics
    # simulator ground truth: the table is at rest and the drive is cut
    assert abs(mech.rate_dps) < 0.05
    fw = st.handles["fpga"].firmware
    from drivers.fpga import protocol as p

    assert not int(fw.regs["CTRL"]) & p.DRIVE_EN


def test_table_spin_on_the_simulated_station(run_procedure, sim_station):
    rec = run_procedure(TableSpin, {"rate_dps": 150.0, "hold_s": 1.0})
    assert rec.outcome == "PASS" and rec.safe_state, rec.end_reason
    # the table's rate readback against the commanded rate: the simulated table's rate noise is
    # 0.002 deg/s rms, so the mean of 10 readings is within 0.01 of the command
    assert rec.measurements[0].value == pytest.approx(150.0, abs=0.01)
    _at_rest_and_safe(sim_station)
    from bench.recorder import open_run

    with open_run(rec.raw_file) as d:
        assert "fpga" in d and "table" in d
        t = d.table("fpga")["t_s"]
        # the stream covers the run up to its end (spin-up + 1 s hold), every sample once
        assert t[-1] == pytest.approx(rec.simulated_s, abs=0.05)
        assert (abs(t[1:] - t[:-1] - 1e-3) < 1e-9).all()
        assert d.truth == preset("hrg").truth()


@pytest.mark.parametrize("abort_at", ["spin_up", "hold"])
def test_abort_at_each_step_reaches_safe_state(sim_station, tmp_path, abort_at):
    runner = Runner(sim_station, runs_dir=tmp_path)

    def on_event(e):
        if isinstance(e, events.StepStarted) and e.name == abort_at:
            runner.abort("operator")

    runner.bus.subscribe(on_event)
    rec = runner.run(TableSpin, {"rate_dps": 300.0, "hold_s": 2.0})
    assert rec.outcome == "ABORTED" and rec.end_reason == "aborted: operator" and rec.safe_state
    assert rec.safe_detail["order"] == ["fpga", "table", "frontend"]
    _at_rest_and_safe(sim_station)


def test_same_procedure_on_an_ascii_table_only_station(tmp_path):
    """A new table model is a registry entry: the same procedure runs on the ASCII controller."""
    path = _write(
        tmp_path,
        '[station]\nid = "ascii"\n[simulation]\npreset = "mems"\n'
        '[devices.table]\ndriver = "ascii-table"\nmax_rate_dps = 500.0\nmax_accel_dps2 = 300.0\n',
    )
    st = load_station(path)
    assert isinstance(st, SimStation)
    with st:
        rec = Runner(st, runs_dir=tmp_path / "runs").run(TableSpin, {"rate_dps": -80.0, "hold_s": 0.5})
        assert rec.outcome == "PASS" and rec.safe_state and rec.safe_detail["order"] == ["table"]
        assert abs(st.handles["table"].mechanics.rate_dps) < 0.05


def test_opening_an_open_station_keeps_its_devices_and_simulators():
    """`with SimStation(...).open() as st` used to open twice: a second set of simulators and
    drivers, the first table's heartbeat left beating against a stopped simulator."""
    from bench.composition.sim_station import SimStation

    with SimStation("sim-hrg").open() as station:
        devices, handles = dict(station.devices), dict(station.handles)
        assert station.open() is station
        assert station.devices == devices and station.handles == handles
    assert not station.devices and not devices["table"].heartbeat.running


@pytest.mark.parametrize(
    "extra, expect",
    [
        ('output_mode = "rate"', "output_mode='rate' is not one of whole-angle, force-to-rebalance"),
        ("ftr_angle_deg = 50.0", "ftr_angle_deg=50 deg is above the limit 45"),
    ],
)
def test_the_fpga_output_mode_keys_are_checked(tmp_path, extra, expect):
    path = _write(tmp_path, GOOD + f'\n[devices.fpga]\ndriver = "fpga-link"\nurl = "socket://127.0.0.1:1"\n{extra}\n')
    with pytest.raises(StationError) as info:
        load_config(path)
    assert str(path) in str(info.value) and "[devices.fpga]" in str(info.value)
    assert expect in str(info.value), str(info.value)


def test_the_force_to_rebalance_station_sets_the_fpga_at_connect():
    """sim-hrg-ftr: its output mode, hold angle and gain reach the FPGA when the link connects; its
    truth carries them (the scale factor G K follows), sim-hrg's truth has none of them."""
    from bench.composition.sim_station import SimStation

    cfg = load_config("sim-hrg-ftr")
    assert cfg.devices["fpga"]["output_mode"] == "force-to-rebalance" and cfg.devices["fpga"]["ftr_gain"] == 3.6
    assert load_config("sim-hrg").devices["fpga"]["output_mode"] == "whole-angle"
    with SimStation("sim-hrg-ftr", seed=0) as st:
        assert st.devices["fpga"].output_mode() == "force-to-rebalance"
        truth = st.truth()
        assert (truth["cvg_output_mode"], truth["ftr_gain"], truth["ftr_angle_deg"]) == (1.0, 3.6, 0.0)
    with SimStation("sim-hrg", seed=0) as st:
        assert "ftr_gain" not in st.truth()
