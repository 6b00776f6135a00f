"""A procedure is checked against its station before anything moves: the values it will command
against the station's limits (issue 13 item 12) and the kind of gyro it is for (item 13)."""

from __future__ import annotations

import pytest

from bench.cli import main
from bench.composition import load_station
from bench.composition.sim_station import SimStation
from bench.engine import Runner, StationMismatch
from bench.station_config import load_config
from procedures import find_procedure

SLOW_TABLE = """
[station]
id = "slow-table"
{kind}

[simulation]
preset = "{preset}"

[devices.table]
driver = "modbus-table"
max_rate_dps = 100.0
max_accel_dps2 = 500.0

[devices.frontend]
driver = "scpi-frontend"
max_amplitude_v = 0.5

[devices.fpga]
driver = "fpga-link"
"""


def _station_file(tmp_path, preset="hrg", kind=""):
    path = tmp_path / "slow.toml"
    path.write_text(SLOW_TABLE.format(preset=preset, kind=kind))
    return path


class _Spy:
    """Wraps a device; records every call whose name is in `moves`."""

    def __init__(self, dev, moves, calls):
        self._dev, self._moves, self._calls = dev, moves, calls

    def __getattr__(self, name):
        attr = getattr(self._dev, name)
        if name in self._moves:
            self._calls.append(name)
        return attr


@pytest.mark.parametrize(
    ("procedure", "params", "text"),
    [
        ("hrg-damping", {}, "rate_dps=500 deg/s is above the station's limit 100 deg/s"),
        ("table-spin", {"rate_dps": 500.0}, "rate_dps=500 deg/s is above the station's limit 100 deg/s"),
        ("hrg-free-decay", {"rate_dps": -150.0}, "rate_dps=-150 deg/s is above the station's limit 100 deg/s"),
        ("hrg-free-decay", {"rate_dps": 50.0, "accel_dps2": 900.0}, "accel_dps2=900 deg/s^2 is above the station's "
                                                                    "limit 500 deg/s^2"),
    ],
)
def test_a_demand_above_a_station_limit_is_refused_before_anything_moves(tmp_path, procedure, params, text):
    station = SimStation(load_config(_station_file(tmp_path)))
    with station:
        calls: list[str] = []
        moves = {"enable", "set_rate", "move_to", "set_drive_enabled", "set_agc", "set_drive", "start_stream"}
        for role in list(station.devices):
            station.devices[role] = _Spy(station.devices[role], moves, calls)
        proc = find_procedure(procedure)(params)
        with pytest.raises(StationMismatch) as err:
            Runner(station).run(proc)
        assert text in str(err.value)
        assert calls == []  # the table never enabled, no drive
        assert station.clock.now() == 0.0  # no step ran
        mech = station.handles["table"].mechanics
        assert not mech.enabled and mech.rate_dps == 0.0


def test_amplitude_demands_are_checked_against_the_front_end(tmp_path):
    station = SimStation(load_config(_station_file(tmp_path, preset="mems")))  # not opened: checked from the file
    proc = find_procedure("mems-sweep")({"drive1_v": 0.888})
    with pytest.raises(StationMismatch, match=r"drive1_v=0.888 V is above the station's limit 0.5 V"):
        Runner(station).run(proc)


def test_cli_refuses_a_demand_above_the_limit_with_one_message(tmp_path, capsys):
    path = _station_file(tmp_path)
    rc = main(["run", "table-spin", "--station", str(path), "--set", "rate_dps=500", "--runs-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "rate_dps=500 deg/s is above the station's limit 100 deg/s" in err
    assert "Traceback" not in err
    assert not list(tmp_path.glob("*.h5"))  # no run started


def test_every_procedure_declares_its_demands_and_kinds():
    from procedures import all_procedures

    procs = all_procedures()
    assert procs["table-spin"]({}).demands()[0].value == 100.0
    assert {d.quantity for d in procs["hrg-damping"]({}).demands()} == {"rate_dps", "accel_dps2"}
    assert procs["hrg-damping"].kinds == ("hrg",) and procs["hrg-free-decay"].kinds == ("hrg",)
    assert procs["mems-sweep"].kinds == ("mems-ring",)
    assert procs["table-spin"].kinds == ()  # any gyro


# --- kinds --------------------------------------------------------------------------------------
def test_station_kind_from_its_file_or_its_preset(tmp_path):
    assert SimStation("sim-hrg").kind == "hrg"
    assert SimStation("sim-mems").kind == "mems-ring"
    assert SimStation(load_config(_station_file(tmp_path, preset="mems"))).kind == "mems-ring"  # old file: preset
    assert SimStation(load_config(_station_file(tmp_path, kind='kind = "hrg"', preset="mems"))).kind == "hrg"


def test_a_bad_kind_in_a_station_file_names_the_key(tmp_path):
    from bench.devices import StationError

    with pytest.raises(StationError, match="kind='ring' is not one of '', hrg, mems-ring"):
        load_config(_station_file(tmp_path, kind='kind = "ring"'))


def test_a_procedure_for_another_kind_is_refused_by_the_runner():
    station = SimStation("sim-hrg")  # not even opened
    with pytest.raises(StationMismatch, match="it is for mems-ring gyros and the station's gyro is hrg"):
        Runner(station).run(find_procedure("mems-sweep")({}))
    station.close()


def test_cli_refuses_a_procedure_for_another_kind(tmp_path, capsys):
    assert main(["run", "mems-sweep", "--station", "sim-hrg", "--runs-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "'mems-sweep' cannot run on station 'sim-hrg'" in err and "Traceback" not in err
    assert main(["run", "hrg-damping", "--station", "sim-mems", "--runs-dir", str(tmp_path)]) == 2


def test_the_window_does_not_offer_a_procedure_for_another_kind(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from bench.gui.engine_backend import EngineBackend

    backend = EngineBackend("sim-hrg", seed=0, record=False)
    try:
        offered = backend.procedures()
        assert "hrg-damping" in offered and "table-spin" in offered
        assert "mems-sweep" not in offered
        assert backend.unavailable()["mems-sweep"].startswith("it is for mems-ring gyros and the station's gyro is hrg")
        with pytest.raises(StationMismatch):  # asked for by name anyway: refused before the run starts
            backend.start("mems-sweep", {})
        assert not backend.running()
    finally:
        backend.close()


def test_an_existing_real_station_file_without_kind_takes_any_procedure(tmp_path):
    from bench.engine import check_station

    path = tmp_path / "lab.toml"
    path.write_text('[station]\nid = "lab-1"\n\n[devices.frontend]\ndriver = "scpi-frontend"\n'
                    'resource = "TCPIP::10.0.0.5::5025::SOCKET"\nmax_amplitude_v = 2.0\n')
    station = load_station(path)
    assert station.kind == ""  # not said: nothing refused for its kind
    check_station(find_procedure("mems-sweep")({}), station)
    with pytest.raises(StationMismatch, match="drive1_v=2.5 V is above the station's limit 2 V"):
        check_station(find_procedure("mems-sweep")({"drive1_v": 2.5}), station)
