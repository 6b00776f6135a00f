"""A lab's own station file (no [simulation]) pointing gyrobench at an Acutrol controller and two
SR865 lock-ins: the standalone simulators stand in for the instruments at their addresses."""

from __future__ import annotations

import pytest

from bench.composition import load_station
from bench.devices import StationError
from drivers.frontend.sr865_pair import Sr865PairFrontEnd
from drivers.rate_table.acutronic_driver import AcutrolRateTable
from simulators.frontend.sr865_server import serve_sr865_pair
from simulators.physics.params import preset
from simulators.rate_table.acutronic_server import serve_acutrol_table
from simulators.world import World

LAB_FILE = """
[station]
id = "lab-hrg-acutrol"

[devices.table]
driver = "acutrol-table"
{table_address}
max_rate_dps = 500.0
max_accel_dps2 = 200.0

[devices.frontend]
driver = "sr865-pair-frontend"
resource = "{master}"
resource2 = "{slave}"
max_amplitude_v = 1.0
"""


@pytest.fixture
def instruments():
    world = World(preset("mems"), seed=1)
    table = serve_acutrol_table(world, max_rate_dps=1000.0, max_accel_dps2=500.0)
    lockins = serve_sr865_pair(world)
    yield world, table, lockins
    table.stop()
    lockins.stop()


@pytest.mark.parametrize("via", ["tcp", "visa"])
def test_a_lab_station_file_opens_its_instruments(tmp_path, instruments, via):
    world, table, lockins = instruments
    address = (
        f'host = "{table.host}"\nport = {table.port}' if via == "tcp" else f'visa_resource = "{table.resource_name}"'
    )
    path = tmp_path / "lab.toml"
    master, slave = lockins.resources
    path.write_text(LAB_FILE.format(table_address=address, master=master, slave=slave))
    station = load_station(path)
    with station.open():
        t, fe = station.devices["table"], station.devices["frontend"]
        assert isinstance(t, AcutrolRateTable) and isinstance(fe, Sr865PairFrontEnd)
        assert t.limits.max_rate_dps == 500.0
        assert table.controller.limit_rate["R"] == 500.0  # the station's limit is in the controller
        assert table.controller.lockout
        assert fe.limits.max_amplitude_v == 1.0
        assert station.safe_state().confirmed
    assert not table.controller.lockout  # released on close


def test_a_table_without_an_address_is_one_clear_message(tmp_path, instruments):
    world, table, lockins = instruments
    master, slave = lockins.resources
    path = tmp_path / "lab.toml"
    path.write_text(LAB_FILE.format(table_address="", master=master, slave=slave))
    with pytest.raises(StationError, match="needs host"):
        load_station(path).open()


def test_the_example_in_docs_real_instruments_is_a_valid_station_file(tmp_path):
    from pathlib import Path

    from bench.station_config import load_config

    text = (Path(__file__).resolve().parents[1] / "docs" / "real_instruments.md").read_text()
    example = text.split("```toml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "lab.toml"
    path.write_text(example)
    cfg = load_config(path)
    assert cfg.simulation is None
    assert cfg.devices["table"]["host"] == "192.168.53.1" and cfg.devices["table"]["port"] == 9878
    assert cfg.devices["frontend"]["resource2"].startswith("TCPIP::")
