"""The Modbus TCP table's link-check read (`probe_status`: one prebuilt FC4 frame on the client's
socket): the same status as pymodbus's read, and a spoiled, lost or refused reply handled as
status() handles it, never taken for the next transaction's."""

from __future__ import annotations

import time

import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LinkLostError
from drivers.rate_table import ModbusRateTable, TableLimits
from simulators.physics.params import preset
from simulators.rate_table import serve_modbus_table
from simulators.world import World

pytestmark = pytest.mark.serial  # a 0.3 s wall-clock reply timeout and a 1.3 s bound: run alone

LIMITS = TableLimits(max_rate_dps=500.0, max_accel_dps2=300.0)


@pytest.fixture
def spinning():
    """A table at 40 deg/s (the simulator's own state is the truth)."""
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    server = serve_modbus_table(world, framer="tcp")
    table = ModbusRateTable(server.host, server.port, limits=LIMITS, clock=clock, timeout_s=0.3)
    table.connect()
    table.enable()
    table.set_rate(40.0, accel_dps2=200.0)
    clock.sleep(1.0)
    yield world, server, table
    table.close()
    server.stop()
    clock.close()


#: the simulator's rate read noise (0.002 deg/s rms) and ripple (1e-3 deg at 40 deg/s: 7e-4 deg/s)
RATE_TOL_DPS = 0.015


def _truth(server) -> tuple[float, float]:
    """The table's actual rate and angle (the simulator's state, no read noise)."""
    with server.world.lock:
        return server.mechanics.rate_dps, server.mechanics.angle_deg


def _alike(a, b) -> bool:
    """Two reads at one simulated time: the same angle and bits, rates within the read noise."""
    return (a.angle_deg == b.angle_deg and abs(a.rate_dps - b.rate_dps) < RATE_TOL_DPS
            and (a.enabled, a.at_rate, a.tripped, a.fault_code) == (b.enabled, b.at_rate, b.tripped, b.fault_code))


def test_probe_reads_what_status_reads(spinning):
    world, server, table = spinning
    probe, full = table.probe_status(), table.status()
    assert _alike(probe, full)  # the world has not moved between them
    rate, angle = _truth(server)
    assert probe.rate_dps == pytest.approx(rate, abs=RATE_TOL_DPS) and rate == pytest.approx(40.0, abs=1e-6)
    assert probe.angle_deg == pytest.approx(angle, abs=2e-3)  # ripple 1.5e-3 deg at most, float32
    assert probe.enabled and probe.at_rate and not probe.tripped


@pytest.mark.parametrize("kind", ["garbage", "short", "drop"])
def test_a_spoiled_reply_falls_back_to_status_and_the_next_reads_are_in_step(spinning, kind):
    world, server, table = spinning
    server.corrupt_replies(kind, count=1)
    t0 = time.monotonic()
    st = table.probe_status()  # its own reply spoiled: status() on a fresh connection reads it
    assert st.rate_dps == pytest.approx(_truth(server)[0], abs=RATE_TOL_DPS)
    assert time.monotonic() - t0 < 0.3 + 1.0  # at most one timeout_s waited for the lost reply
    for _ in range(5):  # a late or partial reply is never taken for a later transaction's
        assert _alike(table.probe_status(), table.status())
    table.set_rate(-15.0, accel_dps2=200.0)  # and a command after it is answered as its own
    assert server.mechanics.target_rate_dps == -15.0


def test_a_link_that_stays_silent_is_reported_lost(spinning):
    world, server, table = spinning
    server.corrupt_replies("drop", count=100)
    with pytest.raises(LinkLostError, match="no valid reply to status read"):
        table.probe_status()


def test_a_refused_read_names_the_modbus_exception():
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    server = serve_modbus_table(world, framer="tcp", device_id=1)
    table = ModbusRateTable(server.host, server.port, limits=LIMITS, clock=clock, device_id=5, timeout_s=0.3)
    try:
        table.client.connect()  # connect() itself would be refused at its watchdog write
        with pytest.raises(DeviceError, match=r"refused status read: Modbus exception 11 \(gateway target"):
            table.probe_status()
    finally:
        table.close()
        server.stop()
        clock.close()
