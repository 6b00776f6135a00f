"""The lab station files of docs/acutrol_connection.md (docs/stations/lab-acutrol-*.toml) open
against the simulated Acutrol: the TCP one at the simulator's Ethernet port, the GPIB one through
a local socket STANDING IN for the GPIB bus (pyvisa-py has no GPIB in CI), with the file's
framing otherwise untouched."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from bench.composition import load_station
from drivers.errors import LinkLostError
from drivers.rate_table.acutronic_driver import AcutrolRateTable
from simulators.physics.params import preset
from simulators.rate_table.acutronic_server import serve_acutrol_table
from simulators.world import World

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture
def acutrol():
    world = World(preset("hrg"), seed=1)
    server = serve_acutrol_table(world, max_rate_dps=1000.0, max_accel_dps2=500.0)
    yield server
    server.stop()


def _pointed(name: str, tmp_path: Path, replacements: dict[str, str]) -> Path:
    """The doc's station file with its address lines replaced (everything else as written)."""
    text = (DOCS / "stations" / name).read_text()
    for key, value in replacements.items():
        text, n = re.subn(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
        assert n == 1, key
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["lab-acutrol-tcp.toml", "lab-acutrol-gpib.toml"])
def test_the_docs_station_files_open_and_release_the_controller(tmp_path, acutrol, name):
    if "tcp" in name:
        path = _pointed(name, tmp_path, {"host": f'"{acutrol.host}"', "port": str(acutrol.port)})
        framing = "tcp"
    else:  # the GPIB file, its resource swapped for the stand-in and its framing named
        path = _pointed(name, tmp_path, {"visa_resource": f'"{acutrol.gpib_standin_resource}"',
                                         "framing": '"gpib"'})  # fmt: skip
        framing = "gpib"
    station = load_station(path)
    c = acutrol.controller
    with station.open():
        table = station.devices["table"]
        assert isinstance(table, AcutrolRateTable) and table.framing == framing
        assert c.lockout and c.limit_rate["R"] == 1000.0 and c.limit_vtrip["R"] == pytest.approx(1100.0)
        assert c.gpib_remote == (framing == "gpib")
        table.enable()  # (a real station's clock is the wall's: the simulated world stands still)
        assert table.status().enabled and c.axes[1].enabled
        assert station.safe_state().confirmed
    assert not c.lockout and not c.gpib_remote  # released to local on close


def test_the_gpib_file_as_written_picks_the_gpib_framing():
    from bench.station_config import load_config

    config = load_config(DOCS / "stations" / "lab-acutrol-gpib.toml")
    table = config.devices["table"]
    assert table["visa_resource"] == "GPIB0::1::INSTR" and table["framing"] == "auto"
    from drivers.rate_table import acutronic_protocol as ap

    assert ap.framing_for(table["visa_resource"], table["framing"]) == "gpib"


def test_gpib_through_pyvisa_py_without_a_gpib_library_names_what_to_install():
    """What docs/acutrol_connection.md says a lab sees without linux-gpib or gpib-ctypes."""
    try:
        import gpib  # noqa: F401  (linux-gpib's binding, or gpib-ctypes' stand-in)

        pytest.skip("a GPIB library is installed here: pyvisa-py would try the bus")
    except ImportError:
        pass
    from bench.clock import SimClock
    from tests.test_rate_table import LIMITS

    world = World(preset("hrg"), seed=1)
    clock = SimClock(world)
    table = AcutrolRateTable(resource="GPIB0::1::INSTR", limits=LIMITS, clock=clock)
    table._link.io.open = _open_with_pyvisa_py(table._link.io)
    try:
        with pytest.raises(LinkLostError, match="cannot open GPIB0::1::INSTR: .*linux-gpib.*gpib-ctypes"):
            table.connect()
    finally:
        clock.close()


def _open_with_pyvisa_py(io):
    """VisaBytes.open, with pyvisa-py forced (a machine with a vendor VISA would use that)."""

    def open_() -> None:
        import pyvisa

        io._inst = pyvisa.ResourceManager("@py").open_resource(io.resource)

    return open_
