"""Rate-table drivers against their simulators over real transports, one behaviour suite run on
both controller models (Modbus TCP and RTU framing, ASCII over TCP and over a pty)."""

from __future__ import annotations

import math
import time

import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError, SafetyTripError
from drivers.rate_table import AsciiRateTable, ModbusRateTable, TableLimits, angle_error_deg
from drivers.rate_table import modbus_protocol as mp
from simulators.physics.params import preset
from simulators.rate_table import serve_ascii_table, serve_modbus_table
from simulators.world import World

LIMITS = TableLimits(max_rate_dps=500.0, max_accel_dps2=300.0)
TAU_S = 0.02  # the simulator's rate-loop lag (TableMechanics default)
MODELS = ["modbus-tcp", "modbus-rtu", "ascii-tcp", "ascii-pty"]


#: the drivers' own reply timeout (1 s): with 0.3 s a reply delayed by a loaded machine (the parallel
#: pass, load 4-7 on two cores) timed out three times and its late line spoiled the retries
#: ("more than one reply line to 'STAT?'" in a position move that is not about timeouts)
def make_bench(model: str, *, watchdog_s: float = 2.0, timeout_s: float = 1.0):
    world = World(preset("hrg"), seed=3)
    clock = SimClock(world)
    kw = dict(limits=LIMITS, clock=clock, timeout_s=timeout_s, watchdog_s=watchdog_s)
    if model.startswith("modbus"):
        framer = model.split("-")[1]
        server = serve_modbus_table(world, framer=framer, use_pty=framer == "rtu")
        if framer == "tcp":
            table = ModbusRateTable(server.host, server.port, **kw)
        else:
            # RTU framing over a pty: pymodbus's serial client polls in_waiting, which a pty
            # reports in full (on socket:// it says only 0 or 1: ~8 ms a transaction)
            table = ModbusRateTable.rtu(server.url, baudrate=921600, **kw)
    else:
        server = serve_ascii_table(world, use_pty=model.endswith("pty"))
        table = AsciiRateTable(server.url, **kw)
    table.connect()
    return world, clock, server, table


@pytest.fixture(params=MODELS)
def bench(request):
    world, clock, server, table = make_bench(request.param)
    yield world, clock, server, table
    table.close()
    server.stop()
    clock.close()


@pytest.fixture(params=["modbus-tcp", "ascii-tcp"])
def bench_tcp(request):
    """The two models over TCP: for checks made before any I/O."""
    world, clock, server, table = make_bench(request.param)
    yield world, clock, server, table
    table.close()
    server.stop()
    clock.close()


def test_spin_to_500_reaches_at_rate_in_expected_time(bench):
    """Truth: a ramp at a limited acceleration a through a first-order lag tau is within tol of
    the setpoint at T = R/a + tau ln(a tau / tol).  Tolerance 0.03 s: one 10 ms poll, one 10 ms
    block and the ripple/noise (< 0.02 deg/s) moving the crossing by < 1 ms."""
    world, clock, server, table = bench
    table.enable()
    accel, tol = 250.0, 0.1
    t0 = clock.now()
    table.set_rate(500.0, accel)
    st = table.wait_at_rate(tol, 0.0, 10.0)
    expected_s = 500.0 / accel + TAU_S * math.log(accel * TAU_S / tol)
    assert clock.now() - t0 == pytest.approx(expected_s, abs=0.03)
    assert abs(st.rate_dps - 500.0) <= tol
    st = table.wait_at_rate(0.05, 0.5, 5.0)  # stays there; the table's own bit agrees
    assert st.at_rate and st.enabled and not st.tripped
    assert world.case_rate_dps == pytest.approx(500.0, abs=1e-6)


def test_stop_decelerates_within_the_accel_limit(bench):
    """Polled every 20 ms, the rate never falls faster than the commanded 200 deg/s^2 (+5% for
    ripple and noise); rest within 200/200 s + 5 tau."""
    world, clock, server, table = bench
    table.enable()
    table.set_rate(200.0, 300.0)
    table.wait_at_rate(0.1, 0.0, 5.0)
    table.stop(200.0)
    t_prev, r_prev = clock.now(), table.status().rate_dps
    t0 = t_prev
    while abs(r_prev) > 0.05:
        clock.sleep(0.02)
        st = table.status()
        t, r = clock.now(), st.rate_dps
        assert (r_prev - r) / (t - t_prev) <= 200.0 * 1.05
        t_prev, r_prev = t, r
        assert t - t0 < 1.0 + 5 * TAU_S + 0.05
    assert table.status().enabled


def test_position_move_and_shortest_way(bench):
    """Trapezoid truth: 90 deg at 60 deg/s and 200 deg/s^2 takes d/v + v/a = 1.8 s; then the
    lag settles (< 0.2 s).  The reported angle carries 1e-3 deg ripple: tolerance 0.01 deg."""
    world, clock, server, table = bench
    table.enable()
    t0 = clock.now()
    table.move_to(90.0, 60.0, 200.0)
    st = table.wait_in_position(0.01, 5.0)
    assert 1.8 - 0.02 <= clock.now() - t0 <= 1.8 + 0.2
    assert abs(angle_error_deg(st.angle_deg, 90.0)) <= 0.01
    table.move_to(350.0, 60.0, 200.0)  # 100 deg backwards beats 260 forwards
    clock.sleep(0.5)
    assert table.status().rate_dps < -10.0
    st = table.wait_in_position(0.01, 5.0)
    assert abs(angle_error_deg(st.angle_deg, 350.0)) <= 0.01


@pytest.mark.parametrize(
    "call, name, message",
    [
        (lambda t: t.set_rate(500.1), "rate_dps", "rate_dps=500.1 deg/s is above the limit 500 deg/s"),
        (lambda t: t.set_rate(-600.0), "rate_dps", "rate_dps=-600 deg/s is below the limit -500 deg/s"),
        (lambda t: t.set_rate(math.nan), "rate_dps", "rate_dps=nan is not a finite number"),
        (lambda t: t.set_rate(100.0, 301.0), "accel_dps2", "accel_dps2=301 deg/s^2 is above the limit 300 deg/s^2"),
        (lambda t: t.set_rate(100.0, 0.0), "accel_dps2", "accel_dps2=0 deg/s^2 is not above the limit 0 deg/s^2"),
        (lambda t: t.move_to(360.0), "angle_deg", "angle_deg=360 deg is not below the limit 360 deg"),
        (lambda t: t.move_to(-1.0), "angle_deg", "angle_deg=-1 deg is below the limit 0 deg"),
        (lambda t: t.move_to(10.0, 501.0), "rate_dps", "rate_dps=501 deg/s is above the limit 500 deg/s"),
    ],
)
def test_limit_errors_name_value_and_limit_and_write_nothing(bench_tcp, call, name, message):
    """The shared wording (bench.validation), the value and the limit with their unit."""
    world, clock, server, table = bench_tcp
    table.enable()
    with pytest.raises(LimitError) as err:
        call(table)
    assert err.value.name == name and str(err.value) == message
    assert server.mechanics.mode == mp.MODE_STOP and server.mechanics.target_rate_dps == 0.0


def test_refused_commands_become_device_errors(bench):
    world, clock, server, table = bench
    with pytest.raises(DeviceError, match="refused"):
        table.set_rate(100.0)  # drive not enabled: the controller refuses
    assert server.mechanics.mode == mp.MODE_STOP


def test_modbus_exception_responses():
    world, clock, server, table = make_bench("modbus-tcp")
    try:
        rr = table.client.read_holding_registers(50, count=2, device_id=1)
        assert rr.isError() and rr.exception_code == mp.EXC_ILLEGAL_ADDRESS
        with pytest.raises(DeviceError, match="exception 3"):
            table._write(mp.HR_MODE, [7], idempotent=False)  # no mode 7
        with pytest.raises(DeviceError, match="exception 2"):
            table._write(mp.IR_COUNT + 40, [1], idempotent=False)
        with pytest.raises(DeviceError, match="exception 4"):
            table._write(mp.HR_MODE, mp.encode_command(mp.MODE_RATE, 10.0, 0.0, 10.0), idempotent=False)
    finally:
        table.close()
        server.stop()
        clock.close()


def test_ascii_error_replies():
    world, clock, server, table = make_bench("ascii-tcp")
    try:
        with pytest.raises(DeviceError, match="-100"):
            table._send("FLY 3", idempotent=False)
        with pytest.raises(DeviceError, match="-104"):
            table._send("RATE fast", idempotent=False)
        with pytest.raises(DeviceError, match="-222"):
            table._send("MODE SIDEWAYS", idempotent=False)
        assert table._query("*IDN?").startswith("GYROBENCH")
    finally:
        table.close()
        server.stop()
        clock.close()


def test_estop_mid_spin_stops_table_and_driver_raises(bench):
    world, clock, server, table = bench
    table.enable()
    table.set_rate(300.0, 100.0)
    clock.sleep(1.0)
    server.inject("estop")
    with pytest.raises(SafetyTripError, match="estop"):
        table.wait_at_rate(0.1, 0.0, 10.0)
    st = table.status()
    assert st.estop and not st.enabled and st.fault_code == mp.FAULT_ESTOP
    clock.sleep(0.02)
    assert abs(table.status().rate_dps) < abs(st.rate_dps)  # braking
    assert table.safe_state() is True  # at rest and disabled, confirmed
    with pytest.raises(DeviceError):
        table.enable()  # button still pressed
    server.clear("estop")
    table.fault_reset()
    table.enable()
    assert not table.status().tripped


@pytest.mark.parametrize("kind, bit", [("fault", "fault"), ("interlock", "interlock_open")])
def test_fault_and_interlock_trip(bench, kind, bit):
    world, clock, server, table = bench
    table.enable()
    table.set_rate(50.0)
    clock.sleep(0.1)
    server.inject(kind)
    with pytest.raises(SafetyTripError):
        table.wait_at_rate(0.1, 0.0, 5.0)
    assert getattr(table.status(), bit)
    assert table.safe_state() is True


@pytest.mark.parametrize("model", ["modbus-tcp", "ascii-tcp"])
def test_watchdog_fed_by_heartbeat_and_expiry_stops_table(model):
    """Watchdog 1 s: with the heartbeat, 1.5 s of wall-time silence from the procedure is
    fine; with the heartbeat gone (a dead bench), 1.5 s of wall time and 1.1 s of simulated time
    without a request, the table latches the expiry, ramps down and disables itself."""
    world, clock, server, table = make_bench(model, watchdog_s=1.0)
    try:
        table.enable()
        table.set_rate(100.0, 300.0)
        table.wait_at_rate(0.1, 0.0, 5.0)
        time.sleep(1.5)
        clock.sleep(0.1)
        assert not table.status().watchdog_expired
        assert table.heartbeat.beats >= 3
        table.heartbeat.stop()  # the bench dies
        time.sleep(1.5)
        clock.sleep(1.1)
        with world.lock:
            rate, _, bits, code = server.mechanics.status()
        assert bits & mp.ST_WATCHDOG_EXPIRED and code == mp.FAULT_WATCHDOG
        clock.sleep(2.0)  # 100 deg/s at 300 deg/s^2 needs 0.33 s
        st = table.status()
        assert st.watchdog_expired and not st.enabled and abs(st.rate_dps) < 0.05
    finally:
        table.close()
        server.stop()
        clock.close()


@pytest.mark.parametrize("kind", ["short", "garbage", "drop"])
def test_one_bad_reply_is_retried_on_reads(bench, kind):
    world, clock, server, table = bench
    server.corrupt_replies(kind, 1)
    st = table.status()
    assert st.rate_dps == pytest.approx(0.0, abs=0.02) and not st.tripped


def test_rtu_read_retried_after_a_late_reply():
    """A reply 1.5 timeouts late (a stalled line): the retry goes out only once the line has been
    quiet, so neither it nor the next transaction sees the straggler (RTU has no transaction id,
    and a straggler arriving with the retry's reply spoils both)."""
    world, clock, server, table = make_bench("modbus-rtu")
    try:
        server.corrupt_replies("late", 1, late_s=1.5 * table.timeout_s)
        st = table.status()
        assert st.rate_dps == pytest.approx(0.0, abs=0.02) and not st.tripped
        table.enable()  # the write after it gets its own echo
        assert server.mechanics.enabled
        assert table.status().enabled
    finally:
        table.close()
        server.stop()
        clock.close()


def test_persistent_bad_replies_raise(bench):
    world, clock, server, table = bench
    server.corrupt_replies("garbage", 50)
    with pytest.raises((LinkLostError, ProtocolError)):
        table.status()
    server.corrupt_replies("garbage", 0)


def test_lost_reply_to_a_motion_command_is_not_retried(bench):
    world, clock, server, table = bench
    table.enable()
    server.corrupt_replies("drop", 1)
    with pytest.raises(LinkLostError):
        table.set_rate(10.0)
    assert server.mechanics.mode == mp.MODE_RATE  # it did arrive: a blind retry would repeat it
    assert table.safe_state() is True


@pytest.mark.parametrize("model", ["modbus-tcp", "ascii-tcp"])
def test_starved_heartbeat_in_lockstep_does_not_trip_a_table_the_bench_reads(model):
    """A loaded machine starves the heartbeat thread (here: stopped) for 1.5 s of wall time, while
    the bench reads the table every 0.4 s of simulated time (the station's lockstep link checks):
    alive in the table's time, no trip.  Reads stop for 1.1 s of simulated time: it trips."""
    world, clock, server, table = make_bench(model, watchdog_s=1.0)
    try:
        table.enable()
        table.set_rate(20.0, 300.0)
        table.heartbeat.stop()
        for _ in range(5):
            time.sleep(0.3)
            clock.sleep(0.4)
            assert not table.status().tripped
        clock.sleep(1.1)
        st = table.status()
        assert st.watchdog_expired and st.fault_code == mp.FAULT_WATCHDOG
    finally:
        table.close()
        server.stop()
        clock.close()


@pytest.mark.serial  # the world at 50x real time, a driver with a 2 s wall-clock timeout: run alone
def test_real_time_clock_spin():
    """The same driver with the world running at 50x wall time (the GUI's mode)."""
    world = World(preset("hrg"), seed=1)
    clock = SimClock(world, speed=50.0)
    server = serve_modbus_table(world)
    table = ModbusRateTable(server.host, server.port, limits=LIMITS, clock=clock, timeout_s=2.0)
    try:
        table.connect()
        table.enable()
        table.set_rate(100.0, 200.0)
        st = table.wait_at_rate(0.1, 0.2, 20.0)
        assert abs(st.rate_dps - 100.0) <= 0.1
        assert table.safe_state() is True
    finally:
        table.close()
        server.stop()
        clock.close()
