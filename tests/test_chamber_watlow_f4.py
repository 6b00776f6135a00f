"""The Watlow F4 chamber against its simulator over Modbus TCP: the protocol module's scaling,
a stock pymodbus client reading and writing the registers, the driver, the thermal model's
ramp and case lag in virtual time, and the safe state."""

from __future__ import annotations

import math

import pytest
from pymodbus.client import ModbusTcpClient

from drivers.chamber import watlow_f4_protocol as fp
from drivers.chamber.watlow_f4_driver import WatlowF4Chamber
from drivers.errors import DeviceError
from simulators.chamber.thermal import ChamberThermal
from simulators.chamber.watlow_f4_server import serve_watlow_f4
from simulators.physics.params import preset
from simulators.world import World


def test_temperature_words_are_signed_tenths():
    assert fp.encode_temperature(-40.0, 1) == 0x10000 - 400
    assert fp.decode_temperature(0x10000 - 400, 1) == -40.0
    assert fp.decode_temperature(fp.encode_temperature(85.3, 1), 1) == pytest.approx(85.3)
    assert fp.encode_ramp_rate(2.5) == 25
    with pytest.raises(ValueError):
        fp.to_word(40000)


def test_case_follows_a_ramped_air_through_its_time_constant():
    th = ChamberThermal(setpoint_c=25.0, ramp_c_per_min=1.0, case_tau_s=600.0)
    th.setpoint_c = 35.0
    for _ in range(300):  # 300 s at 1 s steps
        th.step(1.0)
    assert th.air_c == pytest.approx(30.0)  # 1 deg/min for 5 min
    # case behind a ramp of slope r: r (t - tau (1 - exp(-t / tau)))
    r, tau, t = 1.0 / 60.0, 600.0, 300.0
    assert th.case_c - 25.0 == pytest.approx(r * (t - tau * (1 - math.exp(-t / tau))), rel=1e-9)
    for _ in range(20000):
        th.step(1.0)
    assert th.air_c == 35.0 and th.case_c == pytest.approx(35.0, abs=1e-6)


@pytest.fixture
def served():
    world = World(preset("hrg"), seed=1)
    server = serve_watlow_f4(world, ramp_c_per_min=3.0, case_tau_s=1200.0, low_c=-70.0, high_c=180.0)
    yield world, server
    server.stop()


def test_a_stock_modbus_client_reads_and_writes_the_registers(served):
    world, server = served
    client = ModbusTcpClient(server.host, port=server.port, timeout=1.0)
    assert client.connect()
    try:
        rr = client.read_holding_registers(fp.HR_PV_AIR, count=1, device_id=1)
        assert fp.decode_temperature(rr.registers[0], 1) == pytest.approx(25.0)
        assert client.read_holding_registers(fp.HR_UNITS, count=1, device_id=1).registers == [fp.UNITS_C]
        assert not client.write_register(fp.HR_SETPOINT, fp.encode_temperature(-40.0, 1), device_id=1).isError()
        sp = client.read_holding_registers(fp.HR_SETPOINT, count=1, device_id=1).registers[0]
        assert fp.decode_temperature(sp, 1) == -40.0
        # out of range and a read-only register: Modbus exceptions 3 and 2
        rr = client.write_register(fp.HR_SETPOINT, fp.encode_temperature(-90.0, 1), device_id=1)
        assert rr.isError() and rr.exception_code == fp.EXC_ILLEGAL_VALUE
        rr = client.write_register(fp.HR_PV_AIR, 0, device_id=1)
        assert rr.isError() and rr.exception_code == fp.EXC_ILLEGAL_ADDRESS
        rr = client.read_holding_registers(fp.HR_PV_AIR, count=2, device_id=1)  # 101 is not in the map
        assert rr.isError() and rr.exception_code == fp.EXC_ILLEGAL_ADDRESS
        # 10 simulated minutes at 3 deg/min: the air is 30 deg colder, the case lags it
        world.advance(600.0)
        air = fp.decode_temperature(client.read_holding_registers(fp.HR_PV_AIR, count=1, device_id=1).registers[0], 1)
        part = fp.decode_temperature(client.read_holding_registers(fp.HR_PV_PART, count=1, device_id=1).registers[0], 1)
        assert air == pytest.approx(-5.0, abs=0.05)
        r, tau, t = 3.0 / 60.0, 1200.0, 600.0
        assert part == pytest.approx(25.0 - r * (t - tau * (1 - math.exp(-t / tau))), abs=0.05)
        assert world.temperature_c == pytest.approx(server.mechanics.case_c)
    finally:
        client.close()


def test_driver_sets_ramp_and_reaches_the_safe_state(served):
    world, server = served
    chamber = WatlowF4Chamber(server.host, server.port)
    chamber.connect()
    try:
        assert chamber.range_c == (-70.0, 180.0)
        chamber.set_ramp_rate(5.0)
        assert chamber.ramp_rate_c_per_min() == 5.0
        chamber.set_setpoint(85.0)
        world.advance(3600.0)
        st = chamber.status()
        assert st.air_c == 85.0 and st.setpoint_c == 85.0
        assert st.part_c > 80.0
        with pytest.raises(ValueError):
            chamber.set_setpoint(200.0)
        assert chamber.safe_state()
        assert chamber.setpoint_c() == 25.0
    finally:
        chamber.close()


def test_a_refused_write_is_a_device_error(served):
    _, server = served
    chamber = WatlowF4Chamber(server.host, server.port)
    chamber.connect()
    try:
        with pytest.raises(DeviceError):
            chamber._write(fp.HR_PV_PART, 0)
    finally:
        chamber.close()


def test_the_driver_over_rtu_frames():
    world = World(preset("hrg"), seed=1)
    server = serve_watlow_f4(world, framer="rtu", device_id=3)
    chamber = WatlowF4Chamber.rtu(server.url, device_id=3)
    try:
        chamber.connect()
        chamber.set_setpoint(-40.0)
        assert chamber.setpoint_c() == -40.0 and chamber.air_c() == 25.0
    finally:
        chamber.close()
        server.stop()


def _word(client, address):
    rr = client.read_holding_registers(address, count=1, device_id=1)
    assert not rr.isError(), rr
    return rr.registers[0]


def test_a_stock_client_writes_and_runs_a_ramp_rate_profile(served):
    """The profile registers as ChamberConnectLibrary's F4 interface uses them, written by pymodbus's
    own client: create, a ramp-rate step (4003 = 2, rate 4043 in tenths, target 4044) before the
    End-Hold, start (4000..4002 = N, 1, 5); the set point (4122) moves at the step's rate, the air
    follows it, status 200 reads 2 until the target, then the controller holds it."""
    world, server = served
    client = ModbusTcpClient(server.host, port=server.port, timeout=1.0)
    assert client.connect()
    try:
        assert _word(client, fp.HR_STEPS_AVAILABLE) == 256
        assert not client.write_register(fp.HR_PROFILE_ACTION, fp.ACTION_CREATE, device_id=1).isError()
        n = _word(client, fp.HR_EDIT_PROFILE)
        assert n == 1 and _word(client, fp.HR_STEP_TYPE) == fp.STEP_END  # a new profile: its End step
        assert not client.write_registers(fp.HR_EDIT_STEP, [1, fp.ACTION_INSERT_STEP], device_id=1).isError()
        for address, word in ((fp.HR_STEP_TYPE, fp.STEP_RAMP_RATE), (fp.HR_RAMP_RATE, 20),
                              (fp.HR_STEP_TARGET, fp.encode_temperature(45.0, 1))):
            assert not client.write_register(address, word, device_id=1).isError()
        assert _word(client, fp.HR_RAMP_RATE) == 20 and _word(client, fp.HR_STEPS_AVAILABLE) == 254
        rr = client.write_register(fp.HR_STEP_TARGET, fp.encode_temperature(500.0, 1), device_id=1)
        assert rr.isError() and rr.exception_code == fp.EXC_ILLEGAL_VALUE  # outside the range
        assert not client.write_registers(fp.HR_EDIT_PROFILE, [n, 1, fp.ACTION_START], device_id=1).isError()
        assert _word(client, fp.HR_PROFILE_STATUS) == fp.PROFILE_RUNNING and _word(client, fp.HR_RUN_PROFILE) == n
        world.advance(300.0)  # 5 min at 2 deg/min: the set point at 35; the air (3 deg/min limit) on it
        assert fp.decode_temperature(_word(client, fp.HR_RUN_SETPOINT), 1) == pytest.approx(35.0, abs=0.05)
        assert fp.decode_temperature(_word(client, fp.HR_PV_AIR), 1) == pytest.approx(35.0, abs=0.05)
        assert _word(client, fp.HR_RUN_STEP_LEFT + 1) == 5  # 10 K to go at 2 deg/min
        assert fp.decode_temperature(_word(client, fp.HR_SETPOINT), 1) == 25.0  # the constant one, untouched
        world.advance(600.0)
        assert _word(client, fp.HR_PROFILE_STATUS) == fp.PROFILE_CONSTANT  # ended: End-Hold holds 45
        assert fp.decode_temperature(_word(client, fp.HR_PV_AIR), 1) == 45.0
        assert not client.write_registers(fp.HR_EDIT_PROFILE, [n, 1, fp.ACTION_DELETE], device_id=1).isError()
        assert _word(client, fp.HR_STEPS_AVAILABLE) == 256
    finally:
        client.close()


def test_the_driver_ramps_on_the_controller_and_the_safe_state_stops_it(served):
    world, server = served
    chamber = WatlowF4Chamber(server.host, server.port)
    chamber.connect()
    try:
        assert chamber.supports_profiles()
        n = chamber.start_ramp(-15.0, 1.0)
        world.advance(600.0)
        assert chamber.ramp_running() and chamber.running_setpoint_c() == pytest.approx(15.0, abs=0.05)
        assert chamber.air_c() == pytest.approx(15.0, abs=0.05)  # 1 deg/min under the chamber's 3
        chamber.end_ramp(n, 15.0)  # early: the constant set point takes over where the ramp was
        assert not chamber.ramp_running() and chamber.setpoint_c() == 15.0 and chamber.ramp_profile is None
        chamber.start_ramp(85.0, 2.0)
        world.advance(60.0)
        assert chamber.ramp_running()
        assert chamber.safe_state()  # the ramp stopped and its profile deleted, ambient set
        assert not chamber.ramp_running() and chamber.running_setpoint_c() == 25.0 and chamber.ramp_profile is None
        assert server.mechanics.profile_ramps == [] and chamber._read(fp.HR_STEPS_AVAILABLE)[0] == 256
        with pytest.raises(ValueError):
            chamber.start_ramp(300.0, 1.0)
    finally:
        chamber.close()


def test_a_controller_without_profiles_says_so():
    world = World(preset("hrg"), seed=1)
    server = serve_watlow_f4(world, profiles=False)
    chamber = WatlowF4Chamber(server.host, server.port)
    try:
        chamber.connect()
        assert not chamber.supports_profiles()
    finally:
        chamber.close()
        server.stop()
