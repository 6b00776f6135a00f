"""Any PyMeasure instrument on a station (driver "pymeasure"): set up at connect, logged into every
run with its declared units, made safe by read-back, its limits and lost links reported like every
other device's; checked against the simulated Keithley 2200 supply and 34410A multimeter."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.composition.sim_station import SimStation
from bench.devices import StationError
from bench.engine import Runner
from bench.recorder import open_run
from bench.station_config import load_config
from drivers.errors import DeviceError, LimitError, LinkLostError
from drivers.instrument.station_device import InstrumentDevice
from simulators.instruments import keithley2200 as k2200
from simulators.instruments.agilent34410a import DRIVE_VOLTS_PER_FORCE

STATION = "sim-hrg-instruments"
SUPPLY_SIM = "simulators.instruments.keithley2200:serve_station"


@pytest.fixture
def station():
    with SimStation(STATION).open() as st:
        yield st


def test_the_station_file_builds_an_instrument_under_its_own_name(station):
    supply, dmm = station.devices["supply"], station.devices["dmm"]
    assert isinstance(supply, InstrumentDevice) and isinstance(dmm, InstrumentDevice)
    assert supply.link.idn.startswith("KEITHLEY")
    model = station.handles["supply"].model
    ch1 = model.channels[1]  # `setup` was written and read back at connect
    assert ch1.enabled and ch1.voltage_v == 15.0 and ch1.current_limit_a == 1.0
    assert supply.health_columns == ("ch_1_voltage", "ch_1_current")


def test_readings_follow_the_simulated_world_through_pymeasure(station):
    """Truth: the simulator's wiring constants and the FPGA's open-loop drive force."""
    fpga, world = station.devices["fpga"], station.world
    assert station.devices["supply"].get("ch_1.current") == pytest.approx(k2200.QUIESCENT_A, abs=1e-5)
    assert station.devices["dmm"].get("voltage_ac") == pytest.approx(0.0, abs=1e-9)
    fpga.write_register("DRIVE_FORCE", 2.0)
    fpga.set_drive_enabled(True)
    station.clock.sleep(0.2)
    with world.lock:
        force = world.total_force.copy()
    assert np.abs(force).sum() > 0.5  # the drive is on
    volts = DRIVE_VOLTS_PER_FORCE * math.hypot(force[0], force[1]) / math.sqrt(2.0)
    assert station.devices["dmm"].get("voltage_ac") == pytest.approx(volts, rel=1e-6)
    amps = k2200.QUIESCENT_A + k2200.AMPS_PER_FORCE * np.abs(force).sum()
    assert station.devices["supply"].get("ch_1.current") == pytest.approx(amps, abs=1e-5)


def test_a_value_the_instrument_refuses_names_it_and_nothing_is_written(station):
    supply = station.devices["supply"]
    with pytest.raises(LimitError, match=r"supply: ch_1.voltage_setpoint=80 refused.*70"):
        supply.set("ch_1.voltage_setpoint", 80)
    assert station.handles["supply"].model.channels[1].voltage_v == 15.0
    with pytest.raises(Exception, match="has no property 'ch_1.nonsense'"):
        supply.get("ch_1.nonsense")


def test_safe_state_sets_and_reads_back_the_safe_values(station):
    supply = station.devices["supply"]
    supply.set("ch_2.voltage_setpoint", 5.0)
    supply.set("ch_2.output_enabled", True)
    model = station.handles["supply"].model
    assert model.channels[2].enabled
    report = station.safe_state()
    assert report.confirmed and report.devices["supply"] and report.devices["dmm"]
    assert not model.channels[2].enabled and not model.channels[3].enabled
    assert model.channels[1].enabled  # the gyro's own supply stays on: the station file says so


def test_a_hung_instrument_is_a_lost_link_named_by_its_role(station):
    supply = station.devices["supply"]
    supply.link.instrument.adapter.connection.timeout = 300  # ms: keep the test short
    station.handles["supply"].inject("hang")
    with pytest.raises(LinkLostError, match="supply"):
        supply.health()
    assert supply.safe_state() is False  # its safe values cannot be confirmed
    station.handles["supply"].inject("none")
    assert supply.safe_state() is True
    dmm = station.devices["dmm"]
    assert dmm.safe == {} and dmm.safe_state() is True  # nothing to make safe is not a failure


def test_a_run_logs_each_instrument_with_its_units(tmp_path):
    """A short run (table-spin) on the station with the two instruments: both logged, with units."""
    from procedures.examples.table_spin import TableSpin

    with SimStation(STATION, seed=0).open() as station:
        record = Runner(station, runs_dir=tmp_path / "runs").run(TableSpin, {})
    assert record.outcome == "PASS", record.traceback
    data = open_run(record.raw_file)
    supply = data.table("supply")
    assert tuple(supply) == ("t_s", "ch_1_voltage", "ch_1_current")
    assert len(supply["t_s"]) >= 5 and np.allclose(supply["ch_1_voltage"], 15.0)
    assert np.allclose(supply["ch_1_current"], k2200.QUIESCENT_A)
    assert data.units("supply") == {"t_s": "s", "ch_1_voltage": "V", "ch_1_current": "A"}
    assert data.units("dmm") == {"t_s": "s", "voltage_ac": "V"}


@pytest.mark.parametrize(
    "table, error",
    [
        ('driver = "modbus-table"', "unknown role 'lab': a table driver goes under [devices.table]"),
        ('driver = "pymeasure"', "class"),
        ('driver = "pymeasure"\nclass = "x.Y"\nrecord = { v = 3 }', "record: v = 3 must be"),
        ('driver = "pymeasure"\nclass = "x.Y"', 'simulator = "module:function"'),
        (f'driver = "pymeasure"\nclass = "no_such_module.Y"\nsimulator = "{SUPPLY_SIM}"', "no_such_module"),
        ('driver = "pymeasure"\nclass = "Y"', "class = 'Y' must be module.Class"),
        ('driver = "pymeasure"\nclass = "x.Y"\nsafe = { "a b" = 1 }', "safe: 'a b' is not a property path"),
    ],
)
def test_station_file_mistakes_are_named(tmp_path, table, error):
    base = Path(load_config("sim-hrg").source).read_text()
    path = tmp_path / "st.toml"
    path.write_text(base + "\n[devices.lab]\n" + table + "\n")
    with pytest.raises((StationError, DeviceError)) as info:
        SimStation(str(path)).open().close()
    assert error in str(info.value), str(info.value)


def test_the_window_panel_shows_the_logged_properties(station):
    from bench.gui.engine_backend import _read_device

    shown = _read_device("supply", station.devices["supply"], talk=True)
    assert shown == {"ch_1.voltage": "15 V", "ch_1.current": "0.15 A"}
    assert _read_device("supply", station.devices["supply"], talk=False) == {}  # no I/O during a run
