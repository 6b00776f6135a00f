"""The station composes device specs: a new rate-table model is one registered spec (here a toy
one) used from a station file without touching bench/station.py; the safe state visits the
engine's parts in order, each part a list of devices; no attribute is stored on a driver."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from bench.composition import load_station
from bench.composition.sim_station import SimStation
from bench.devices import DRIVERS, SAFE_PARTS, DriverSpec, Key, StationError, register_driver, unregister_driver
from bench.engine.safety import by_part
from bench.station_config import load_config
from drivers.rate_table.station_keys import TABLE_HEALTH_COLUMNS, table_health, table_keys


class _ToyTable:
    """A rate table in memory: it spins at what it is told and stops when made safe."""

    def __init__(self, cfg: dict) -> None:
        self.cfg = cfg
        self.rate_dps = 12.5
        self.calls: list[str] = []

    def status(self):
        self.calls.append("status")
        return SimpleNamespace(tripped=False, rate_dps=self.rate_dps, angle_deg=30.0, trip_reason=lambda: "")

    def safe_state(self) -> bool:
        self.calls.append("safe_state")
        self.rate_dps = 0.0
        return True

    def close(self) -> None:
        self.calls.append("close")


@pytest.fixture
def toy_table():
    spec = register_driver(
        DriverSpec(
            name="toy-table",
            role="table",
            part="table-to-rest",
            keys=table_keys({"bus": Key(str, "", doc="where the toy listens")}),
            build=lambda cfg, clock: _ToyTable(cfg),
            health=table_health,
            health_columns=TABLE_HEALTH_COLUMNS,
            doc="a toy rate table (test only)",
        )
    )
    yield spec
    unregister_driver("toy-table")


def test_a_new_rate_table_model_is_one_registered_spec(toy_table, tmp_path):
    path = tmp_path / "toy.toml"
    path.write_text('[station]\nid = "toy"\n[devices.table]\ndriver = "toy-table"\nbus = "b1"\nmax_rate_dps = 90.0\n')
    config = load_config(path)
    assert config.devices["table"]["max_rate_dps"] == 90.0 and config.devices["table"]["bus"] == "b1"
    recorded: list[tuple[str, tuple, np.ndarray]] = []
    with load_station(path) as station:
        table = station.devices["table"]
        assert isinstance(table, _ToyTable) and table.cfg["bus"] == "b1"
        assert station.limit("table", "max_rate_dps") == 90.0
        station._ctx = SimpleNamespace(record=lambda *a: recorded.append(a))
        station.check_links()
        report = station.safe_state()
    assert report.confirmed and report.order == ["table"] and table.rate_dps == 0.0
    ((role, columns, rows),) = recorded
    assert role == "table" and columns == ("t_s", "rate_dps", "angle_deg")
    np.testing.assert_array_equal(rows[:, 1:], [[12.5, 30.0]])
    assert table.calls[-1] == "close"
    # a key the toy does not declare is refused by the same checks as every built-in model
    path.write_text('[station]\nid = "toy"\n[devices.table]\ndriver = "toy-table"\nport = 1\n')
    with pytest.raises(StationError, match="port"):
        load_config(path)


def test_a_spec_must_say_its_safe_state_part():
    with pytest.raises(ValueError, match="part"):
        register_driver(DriverSpec(name="partless", role="table", keys={}, build=lambda cfg, clock: None))
    assert "partless" not in DRIVERS
    assert {spec.part for spec in DRIVERS.values()} <= set(SAFE_PARTS)


def test_safe_state_parts_in_the_engines_order_each_a_list_of_devices():
    """Several gyros on one table: every slot's drive is cut before the shared table comes to rest,
    then every slot's outputs go off; within a part, the station file's order."""
    parts = {
        "frontend.a": "outputs-off",
        "fpga.a": "drive-cut",
        "table": "table-to-rest",
        "fpga.b": "drive-cut",
        "frontend.b": "outputs-off",
    }
    assert by_part(parts) == [
        ("drive-cut", ["fpga.a", "fpga.b"]),
        ("table-to-rest", ["table"]),
        ("chamber-to-ambient", []),
        ("outputs-off", ["frontend.a", "frontend.b"]),
    ]
    with pytest.raises(ValueError):
        by_part({"x": "somewhere"})


def test_simulated_station_orders_by_part_and_keeps_no_attribute_on_drivers():
    with SimStation("sim-hrg") as station:
        assert station.safe_state_plan() == [
            ("drive-cut", ["fpga"]),
            ("table-to-rest", ["table"]),
            ("chamber-to-ambient", []),
            ("outputs-off", ["frontend"]),
        ]
        link = station.devices["fpga"]
        before = set(vars(link))
        stop = station.start_streams(SimpleNamespace(record=lambda *a: None))
        try:
            assert set(vars(link)) == before, "the station stores nothing on a driver"
            assert station._stream_since["fpga"] == (0, 0, 0)
        finally:
            stop()
        station.ensure_ready()
        assert station._stream_since == {}  # the next run counts from its own stream start
        report = station.safe_state()
    assert report.confirmed and report.order == ["fpga", "table", "frontend"]
