"""The Acutrol table: the rate-table behaviour suite of test_rate_table.py run on the ACL driver
against its simulator (TCP, and the VISA path over a socket resource), the bytes the driver sends
pinned to TM-8004's own examples, and the ACL parser's short forms and tree rules."""

from __future__ import annotations

import time

import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError
from drivers.rate_table import acutronic_protocol as ap
from drivers.rate_table import modbus_protocol as mp
from drivers.rate_table.acutronic_driver import AcutrolRateTable
from simulators.physics.params import preset
from simulators.rate_table.acutronic_server import serve_acutrol_table
from simulators.world import World
from tests.test_rate_table import (  # noqa: F401 - collected here again, on the Acutrol bench
    LIMITS,
    test_estop_mid_spin_stops_table_and_driver_raises,
    test_fault_and_interlock_trip,
    test_limit_errors_name_value_and_limit_and_write_nothing,
    test_lost_reply_to_a_motion_command_is_not_retried,
    test_one_bad_reply_is_retried_on_reads,
    test_persistent_bad_replies_raise,
    test_position_move_and_shortest_way,
    test_refused_commands_become_device_errors,
    test_spin_to_500_reaches_at_rate_in_expected_time,
    test_stop_decelerates_within_the_accel_limit,
)


def make_acutrol(model: str = "acutrol-tcp", timeout_s: float = 0.3, axis: int = 1, **server_kw):
    """acutrol-tcp: the Ethernet port (tcp framing); acutrol-gpib: the GPIB code path (gpib
    framing, *ESR?) over the simulator's socket STANDING IN for a GPIB resource; acutrol-visa-tcp:
    the Ethernet port reached through a VISA socket resource."""
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    server = serve_acutrol_table(world, **server_kw)
    kw = dict(limits=LIMITS, clock=clock, timeout_s=timeout_s, axis=axis)
    if model == "acutrol-gpib":
        table = AcutrolRateTable(resource=server.gpib_standin_resource, framing="gpib", **kw)
    elif model == "acutrol-visa-tcp":
        table = AcutrolRateTable(resource=server.resource_name, **kw)
    else:
        table = AcutrolRateTable(server.host, server.port, **kw)
    try:
        table.connect()
    except Exception:
        server.stop()
        clock.close()
        raise
    return world, clock, server, table


@pytest.fixture(params=["acutrol-tcp", "acutrol-gpib"])
def bench(request):
    world, clock, server, table = make_acutrol(request.param)
    yield world, clock, server, table
    table.close()
    server.stop()
    clock.close()


@pytest.fixture
def bench_tcp():
    world, clock, server, table = make_acutrol()
    yield world, clock, server, table
    table.close()
    server.stop()
    clock.close()


# TM-8004's own example strings (section: example), which the driver's formatting must reproduce
MANUAL_EXAMPLES = [
    (lambda: ap.demand_rate(2, 100.0), ":DEM:RATE 2,100.0"),  # 4.3.6
    (lambda: ap.demand_position(1, 135.223), ":DEM:POS 1,135.223"),  # 4.3.5
    (lambda: ap.mode_off(1), ":MODE:OFF 1"),  # 4.7.3
    (lambda: ap.mode_position(3), ":MODE:POS 3"),  # 4.7.4
    (lambda: ap.mode_rate(3), ":MODE:RATE 3"),  # 4.7.5
    (lambda: ap.limit_acceleration("P", 1, 1500.0), ":LIM:ACC P,1,1500.0"),  # 4.6.2
    (lambda: ap.limit_rate("P", 1, 120.0), ":LIM:RATE P,1,120.0"),  # 4.6.8
    (lambda: ap.limit_vtrip("R", 2, 100.0), ":LIM:VTR R,2,100.0"),  # 4.6.9
    (lambda: ap.interlock_open(1), ":INT:OPEN 1"),  # 4.5.5
    (lambda: ap.INTERLOCK_RESET, ":INT:RES"),  # 4.5.6
    (lambda: ap.read_rate(1), ":READ:RATE? 1"),  # 4.10.5
    (lambda: ap.read_position(2), ":READ:POS? 2"),  # 4.10.4
]


@pytest.mark.parametrize("make, example", MANUAL_EXAMPLES)
def test_command_bytes_match_the_manual_examples(make, example):
    assert make().encode("ascii") == example.encode("ascii")


def test_interlock_close_matches_the_manual_up_to_case():
    """4.5.1 writes the example as ':INT:CLOSe 1'; ACL is not case sensitive (2.1)."""
    assert ap.interlock_close(1).upper() == ":INT:CLOSe 1".upper()


@pytest.mark.parametrize(
    "model, expected",
    [
        (  # every message answered with a header: no *ESR? needed; enable reads the interlock back
            "acutrol-tcp",
            [":INT:CLOSE 1\n", ":INT? 1\n", ":LIM:ACC R,1,200.0;:DEM:RATE 1,100.0;:MODE:RATE 1\n",
             ":LIM:ACC O,1,150.0;:MODE:OFF 1\n", ":INT:OPEN 1\n"],
        ),
        (  # only queries answer: every command message ends in *ESR?
            "acutrol-gpib",
            [":INT:CLOSE 1;*ESR?\n", ":INT? 1\n", ":LIM:ACC R,1,200.0;:DEM:RATE 1,100.0;:MODE:RATE 1;*ESR?\n",
             ":LIM:ACC O,1,150.0;:MODE:OFF 1;*ESR?\n", ":INT:OPEN 1;*ESR?\n"],
        ),
    ],
)  # fmt: skip
def test_the_driver_sends_exactly_these_bytes(model, expected):
    world, clock, server, table = make_acutrol(model)
    try:
        server.controller.log.clear()
        table.enable()
        table.set_rate(100.0, 200.0)
        table.stop(150.0)
        table.disable()
        assert server.controller.log == expected
    finally:
        table.close()
        server.stop()
        clock.close()


def test_connect_sets_ascii_numbers_checks_units_and_close_releases_to_local():
    """GPIB: `:U:F F` (the manual's example, 4.14.1) and its read-back, the axis's scaling, the
    lockout; on close the lockout off and the IEEE-488 interface to local (4.4.2)."""
    world, clock, server, table = make_acutrol("acutrol-gpib", number_format=ap.FORMAT_BINARY)
    c = server.controller
    try:
        assert c.log[:5] == ["*IDN?\n", "*CLS;*ESR?\n", ":U:F F;*ESR?\n", ":U:F?\n", ":CONF:SCAL? 1\n"]
        assert c.number_format == ap.FORMAT_FLOAT and table.units == "deg"
        assert c.lockout and c.gpib_remote
    finally:
        table.close()
    assert c.log[-2:] == [":Utility:Lockout OFF;*ESR?\n", ":Interface:IEEE488:Local;*ESR?\n"]
    assert not c.lockout and not c.gpib_remote
    server.stop()
    clock.close()


def test_tcp_cannot_set_the_number_format_so_binary_is_refused_with_a_message():
    """4.14.1: only the IEEE-488 controller in charge may set :U:F; over TCP a controller left in
    BINARY is refused at connect, saying what to do."""
    with pytest.raises(DeviceError, match=r"BINARY format .* ASCII \(FLOAT\) only; set ':U:F F'"):
        make_acutrol("acutrol-tcp", number_format=ap.FORMAT_BINARY)


def test_tcp_close_releases_the_lockout():
    world, clock, server, table = make_acutrol("acutrol-tcp")
    assert server.controller.lockout
    table.close()
    assert not server.controller.lockout and server.controller.log[-1] == ":Utility:Lockout OFF\n"
    server.stop()
    clock.close()


@pytest.mark.parametrize("units, full_scale", [("rad", 360.0), ("rev", 1.0), ("deg", 720.0)])
@pytest.mark.parametrize("model", ["acutrol-tcp", "acutrol-gpib"])
def test_an_axis_not_scaled_in_degrees_is_refused_at_connect(model, units, full_scale):
    with pytest.raises(DeviceError, match=rf"axis 1 is scaled in '{units}' .* degrees over 360 deg"):
        make_acutrol(model, units=units, full_scale_deg=full_scale)


@pytest.mark.parametrize(
    "message, paths",
    [
        (":Demand:Position 3,10.5", [("DEMAND", "POSITION")]),  # 2.1: three spellings, one command
        (":Dem:Pos 3,10.50000", [("DEMAND", "POSITION")]),
        (":D:P 3,10.5", [("DEMAND", "POSITION")]),
        (":Mode:Position 1;Rate 2", [("MODE", "POSITION"), ("MODE", "RATE")]),  # 2.2.2
        (":Dem:Pos 2,0.01;:Mode:Pos 2;Rate 1", [("DEMAND", "POSITION"), ("MODE", "POSITION"), ("MODE", "RATE")]),
        (":R:A 2;R 2;P 2", [("READ", "ACCELERATION"), ("READ", "RATE"), ("READ", "POSITION")]),
        (":I:C 1;C 2", [("INTERLOCK", "CLOSE"), ("INTERLOCK", "CLOSE")]),
        (":L:R R,3,100.0;R R,2,10.0", [("LIMIT", "RATE"), ("LIMIT", "RATE")]),
    ],
)
def test_parser_follows_the_manual_tree_rules(message, paths):
    assert [p for p, _, _ in ap.split_message(message)] == paths


@pytest.mark.parametrize("message", [":Demand:Posn 3,10.5", ":D:Q 3,1"])
def test_parser_rejects_the_manual_error_examples(message):
    with pytest.raises(ValueError):
        ap.split_message(message)


def test_tcp_refusals_come_back_as_error_codes_with_the_controllers_words(bench_tcp):
    world, clock, server, table = bench_tcp
    with pytest.raises(DeviceError, match="error code 1: unknown command"):
        table._send(":FLY 1", idempotent=False)
    with pytest.raises(DeviceError, match="error code 3: axis or value out of range"):
        table._send(":DEM:POS 1,400", idempotent=False)
    with pytest.raises(DeviceError, match="error code 2: bad arguments"):
        table._send(":DEM:RATE 1,fast", idempotent=False)
    assert table._query(":U:L?") == "ON"  # the driver locked the other interfaces out


def test_gpib_refusals_come_back_as_esr_bits():
    world, clock, server, table = make_acutrol("acutrol-gpib")
    try:
        with pytest.raises(DeviceError, match="bit 5"):
            table._send(":FLY 1", idempotent=False)
        with pytest.raises(DeviceError, match="bit 4"):
            table._send(":DEM:POS 1,400", idempotent=False)
        assert table._query("*ESR?") == "0"  # read clears it
    finally:
        table.close()
        server.stop()
        clock.close()


def test_only_bits_2_4_5_are_errors():
    """Errors in the manual's (ACT2000) table and in IEEE 488.2 alike; bit 3 is "all axis profiles
    complete" there, bit 0 a servo fault the driver reads from the interlock instead."""
    assert ap.ESR_ERRORS == 0b110100
    assert not ap.ESR_ERRORS & (ap.ESR_BIT3 | ap.ESR_BIT0)


def test_with_the_act2000_table_a_normal_stop_does_not_raise():
    """The ACT2000 table sets bit 3 when every profile completes: a spin, a stop and a disable
    go through; a refused command (bit 5) and a failed servo attempt (bit 0) still raise."""
    world, clock, server, table = make_acutrol("acutrol-gpib", esr_table="act2000")
    c = server.controller
    try:
        table.enable()
        table.set_rate(100.0, 300.0)
        table.wait_at_rate(0.1, 0.0, 5.0)
        clock.sleep(0.5)
        table.status()  # the profile has completed: bit 3 is waiting in *ESR?
        assert c.esr & ap.ESR_BIT3
        table.stop()
        assert table.wait_at_rest(5.0) is not None
        table.stop()  # *ESR? answers 8 (bit 3 again): not an error
        table.disable()
        table._send(":FLY 1", idempotent=False)  # unknown: ignored silently in this table
        with pytest.raises(DeviceError, match="bit 5"):
            table.set_rate(10.0)  # not servoed: the axis did not respond as commanded
        server.inject("estop")
        with pytest.raises(DeviceError, match="interlock reads Fault"):
            table.enable()  # bit 0 only: the interlock read-back tells
    finally:
        table.close()
        server.stop()
        clock.close()


def test_velocity_trip_shuts_the_axis_down(bench_tcp):
    """A trip set below the demanded rate: the controller shuts the axis down (a software fault)."""
    world, clock, server, table = bench_tcp
    table._send(ap.limit_vtrip("R", 1, 50.0), idempotent=True)
    table.enable()
    table.set_rate(100.0, 300.0)
    with pytest.raises(Exception, match="fault"):
        table.wait_at_rate(0.1, 0.0, 5.0)
    st = table.status()
    assert st.fault and not st.enabled and st.fault_code == mp.FAULT_DRIVE
    assert table.safe_state() is True
    assert table._query(":INT? 1") == "Fault"
    table.fault_reset()
    assert table._query(":INT? 1") == "Open"


def test_limits_are_written_into_the_controller(bench_tcp):
    world, clock, server, table = bench_tcp
    c = server.controller
    assert c.limit_rate["R"] == c.limit_rate["P"] == LIMITS.max_rate_dps
    assert c.limit_acc["O"] == LIMITS.max_accel_dps2
    assert c.limit_vtrip["R"] == pytest.approx(1.1 * LIMITS.max_rate_dps)
    assert float(table._query(":LIM:RATE? R,1")) == LIMITS.max_rate_dps


def test_station_sim_hrg_acutronic_builds_the_acutrol_driver():
    from bench.composition.sim_station import SimStation

    with SimStation("sim-hrg-acutronic").open() as station:
        table = station.devices["table"]
        assert isinstance(table, AcutrolRateTable) and table.idn.startswith("Acutronic")
        table.enable()
        table.set_rate(100.0, 500.0)
        assert abs(table.wait_at_rate(0.1, 0.1, 5.0).rate_dps - 100.0) <= 0.1
        assert station.world.case_rate_dps == pytest.approx(100.0, abs=0.01)
        assert station.safe_state().confirmed


@pytest.mark.parametrize("model", ["acutrol-tcp", "acutrol-gpib", "acutrol-visa-tcp"])
def test_a_late_reply_is_not_taken_for_the_next_answer(model):
    """*IDN? answered 0.5 s late (timeout 0.3 s): the next request gets its own answer."""
    from drivers.errors import LinkLostError

    world, clock, server, table = make_acutrol(model)
    try:
        server.delay_next_reply(0.5)
        with pytest.raises(LinkLostError):
            table._transact("*IDN?")
        time.sleep(0.3)  # the late answer is now waiting in the input
        assert ap.parse_status(table._transact(ap.status_query(1))[1])[2] == "Open"
    finally:
        table.close()
        server.stop()
        clock.close()


# --- axes other than 1; the door told apart from the e-stop ---------------------------------------
@pytest.mark.parametrize("model", ["acutrol-tcp", "acutrol-gpib"])
def test_a_door_is_an_open_interlock_not_an_estop(model):
    """SI bit 0 sums every interlock input and the master interlock: the axis's own register
    (A1INTLK) tells the door (INTLK1) from the e-stop (master interlock)."""
    world, clock, server, table = make_acutrol(model)
    try:
        table.enable()
        server.inject("interlock")
        st = table.status()
        assert st.interlock_open and not st.estop and not st.enabled and st.fault_code == mp.FAULT_INTERLOCK
        assert server.controller.system_interlocks() & ap.SI_G1INTLK  # the summary bit once taken for an e-stop
        server.clear("interlock")
        table.fault_reset()
        server.inject("estop")
        st = table.status()
        assert st.estop and not st.interlock_open and st.fault_code == mp.FAULT_ESTOP
    finally:
        table.close()
        server.stop()
        clock.close()


@pytest.mark.parametrize("model", ["acutrol-tcp", "acutrol-gpib"])
def test_axis_2_reads_its_own_bits_and_moves_its_own_axis(model):
    """The gyro on axis 1, the driver on axis 2: a door on axis 1 is not axis 2's; a door on axis
    2 is; the e-stop (master interlock) is every axis's.  Axis 2 spins without turning the gyro."""
    world, clock, server, table = make_acutrol(model, axis=2)
    c = server.controller
    try:
        assert c.limits["RATE"][2]["R"] == LIMITS.max_rate_dps and c.limit_rate["R"] != LIMITS.max_rate_dps
        table.enable()
        table.set_rate(50.0, 200.0)
        st = table.wait_at_rate(0.1, 0.1, 5.0)
        assert st.rate_dps == pytest.approx(50.0, abs=0.1) and st.enabled
        assert c.axes[2].rate_dps == pytest.approx(50.0, abs=0.01) and world.case_rate_dps == 0.0
        server.inject("interlock", axis=1)
        st = table.status()
        assert st.enabled and not st.interlock_open and not st.estop
        server.inject("interlock", axis=2)
        st = table.status()
        assert st.interlock_open and not st.estop and not st.enabled
        assert table.safe_state() is True
        server.clear("interlock", axis=2)
        table.fault_reset()
        server.inject("estop")
        st = table.status()
        assert st.estop and not st.interlock_open
    finally:
        table.close()
        server.stop()
        clock.close()


def test_the_simulator_serves_axes_1_to_3():
    world, clock, server, table = make_acutrol("acutrol-tcp", axis=3)
    try:
        for axis in (1, 2, 3):
            assert table._query(f":MODE? {axis}") == "O"
        with pytest.raises(DeviceError, match="out of range"):
            table._query(":MODE? 4")
        table.enable()
        assert table._query(":INT? 3") == "Close" and table._query(":INT? 1") == "Open"
    finally:
        table.close()
        server.stop()
        clock.close()


def test_the_ethernet_port_through_a_visa_socket_speaks_the_tcp_framing():
    """A VISA `TCPIP::host::9878::SOCKET` resource reaches the Ethernet port: framing auto -> tcp,
    counted bytes read through pyvisa, a refusal's empty text included."""
    world, clock, server, table = make_acutrol("acutrol-visa-tcp")
    try:
        assert table.framing == "tcp" and table.idn.startswith("Acutronic")
        with pytest.raises(DeviceError, match="error code 3"):
            table._send(":DEM:POS 1,400", idempotent=False)
        table.enable()
        assert table.status().enabled
    finally:
        table.close()
        server.stop()
        clock.close()
