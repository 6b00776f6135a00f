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


def make_acutrol(model: str = "acutrol-tcp", timeout_s: float = 0.3):
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    server = serve_acutrol_table(world)
    kw = dict(limits=LIMITS, clock=clock, timeout_s=timeout_s)
    if model == "acutrol-visa":
        table = AcutrolRateTable(resource=server.resource_name, **kw)
    else:
        table = AcutrolRateTable(server.host, server.port, **kw)
    table.connect()
    return world, clock, server, table


@pytest.fixture(params=["acutrol-tcp", "acutrol-visa"])
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


def test_the_driver_sends_exactly_these_bytes():
    world, clock, server, table = make_acutrol()
    try:
        server.controller.log.clear()
        table.enable()
        table.set_rate(100.0, 200.0)
        table.stop(150.0)
        table.disable()
        assert server.controller.log == [
            ":INT:CLOSE 1;*ESR?\n",
            ":LIM:ACC R,1,200.0;:DEM:RATE 1,100.0;:MODE:RATE 1;*ESR?\n",
            ":LIM:ACC O,1,150.0;:MODE:OFF 1;*ESR?\n",
            ":INT:OPEN 1;*ESR?\n",
        ]
    finally:
        table.close()
        server.stop()
        clock.close()


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


def test_errors_come_back_as_esr_bits(bench_tcp):
    world, clock, server, table = bench_tcp
    with pytest.raises(DeviceError, match="command error"):
        table._send(":FLY 1", idempotent=False)
    with pytest.raises(DeviceError, match="execution error"):
        table._send(":DEM:POS 1,400", idempotent=False)
    with pytest.raises(DeviceError, match="command error"):
        table._send(":DEM:RATE 1,fast", idempotent=False)
    assert table._query("*ESR?") == "0"  # read clears it
    assert table._query(":U:L?") == "ON"  # the driver locked the other interfaces out


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


@pytest.mark.parametrize("model", ["acutrol-tcp", "acutrol-visa"])
def test_a_late_reply_is_not_taken_for_the_next_answer(model):
    """*IDN? answered 0.5 s late (timeout 0.3 s): the next request gets its own answer."""
    from drivers.errors import LinkLostError

    world, clock, server, table = make_acutrol(model)
    try:
        server.delay_next_reply(0.5)
        with pytest.raises(LinkLostError):
            table._transact("*IDN?")
        time.sleep(0.3)  # the late answer is now waiting in the input
        assert ap.parse_status(table._transact(ap.status_query(1)))[2] == "Open"
    finally:
        table.close()
        server.stop()
        clock.close()
