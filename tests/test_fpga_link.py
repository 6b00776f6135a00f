"""FpgaLink against the simulated FPGA over real loopback transports (socket:// and a pty):
register round trips, limits, NACKs, safe state, stream integrity under injected faults, and
a link that drops or stalls raising within its wall timeout."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import math
import time

import numpy as np
import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError
from drivers.fpga import FpgaLink
from drivers.fpga import protocol as p
from simulators.fpga import serve_fpga
from simulators.physics.params import preset
from simulators.world import World


@pytest.fixture(params=["socket", "pty"])
def bench(request):
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    server = serve_fpga(world, transport=request.param, seed=1)
    link = FpgaLink(server.url, clock=clock, timeout_s=0.5, retries=2).connect()
    yield world, clock, server, link
    link.close()
    server.stop()
    clock.close()


def _collect(link):
    blocks: list[np.ndarray] = []
    link.subscribe(blocks.append)
    return blocks


def test_register_round_trips(bench):
    world, _, _, link = bench
    assert link.read_register("ID") == p.FPGA_ID
    assert link.sample_period_s == world.sample_period_s
    for name, value in [("AGC_SETPOINT", 0.625), ("REF_FREQ_HZ", 5500.125), ("STREAM_DECIMATION", 7),
                        ("DRIFT_THETA_TAU_DEG", -12.5), ("PRECESSION_RATE_DPS", 3.0)]:
        assert link.write_register(name, value) == value
        assert link.read_register(name) == value
        assert link.read_register(p.BY_NAME[name].addr) == value
    link.set_agc(True, 0.5)
    link.set_pll(True)
    assert link.read_register("CTRL") == p.AGC_EN | p.PLL_EN


def test_bad_values_raise_before_anything_is_written(bench):
    _, _, server, link = bench
    before = server.firmware.regs["AGC_SETPOINT"]
    with pytest.raises(LimitError, match="^AGC_SETPOINT=-1 is below the limit 0$"):
        link.write_register("AGC_SETPOINT", -1.0)
    with pytest.raises(LimitError, match="^decimation=0 is below the limit 1$"):
        link.start_stream(0)
    with pytest.raises(LimitError, match="^FM_RATE_HZ=nan is not a finite number$"):
        link.set_whole_angle(True, 1.0, 0.1, float("nan"))
    with pytest.raises(LimitError, match="read-only"):
        link.write_register("STATUS", 1)
    with pytest.raises(KeyError):
        link.read_register("NO_SUCH_REGISTER")
    assert server.firmware.regs["AGC_SETPOINT"] == before
    assert server.firmware.regs["CTRL"] == 0  # the whole-angle call wrote nothing


def test_device_nack_is_a_device_error(bench):
    _, _, _, link = bench
    # bypass the driver's own check to see the FPGA refuse an out-of-range value
    with pytest.raises(DeviceError, match="NACK 3"):
        link._command(p.WRITE, p.BY_NAME["STREAM_DECIMATION"].addr, (0).to_bytes(8, "little"), "raw write")
    with pytest.raises(DeviceError, match="NACK 1"):
        link._command(p.READ, 0x7F, b"", "raw read")
    assert link.read_register("ERR_CMD") == 2


def test_safe_state_cuts_drive_and_loops(bench):
    world, clock, _, link = bench
    link.set_agc(True, 1.0)
    link.set_quadrature_loop(True)
    link.set_whole_angle(True, 1.0)
    link.set_drive_enabled(True)
    clock.sleep(1.0)
    assert link.read_register("STATUS") & p.ST_DRIVE_ON
    assert np.any(world.total_force != 0)
    assert link.safe_state() is True
    assert link.read_register("CTRL") & (p.DRIVE_EN | p.LOOP_BITS) == 0
    clock.sleep(0.1)
    assert np.all(world.total_force == 0)


def test_stream_is_complete_in_lockstep(bench):
    world, clock, _, link = bench
    blocks = _collect(link)
    link.start_stream(1)
    start = link.read_register("STREAM_START_INDEX")
    clock.sleep(20.0)  # 20 000 frames
    link.wait_for_sample(clock.now(), timeout_wall_s=10.0)
    rows = np.vstack(blocks)
    np.testing.assert_array_equal(rows[:, 0], np.arange(start + 1, world.sample_index + 1))
    np.testing.assert_allclose(rows[:, 1], rows[:, 0] * world.sample_period_s)
    np.testing.assert_allclose(rows[-1, 2:6], world.last_block.q_meas[-1], rtol=1e-6, atol=1e-7)  # float32
    s = link.stats
    assert (s.frames, s.dropped, s.corrupt) == (len(rows), 0, 0)


def test_decimation_and_wait_for_time(bench):
    world, clock, _, link = bench
    blocks = _collect(link)
    link.start_stream(25)
    clock.sleep(1.0)
    link.wait_for_sample(clock.now(), timeout_wall_s=10.0)
    idx = np.vstack(blocks)[:, 0]
    assert np.all(idx % 25 == 0) and idx[-1] == world.sample_index - world.sample_index % 25
    assert len(idx) == 40


def test_decimated_frames_carry_the_boxcar_mean_of_their_window(bench):
    """Truth: the world's measured samples; each decimated frame is the mean of the 25 samples
    ending at its index (float32 on the wire, hence the tolerance), across block boundaries."""
    world, clock, _, link = bench
    measured: dict[int, np.ndarray] = {}

    class Tap:
        def before_block(self, *a):
            pass

        def after_block(self, w, block):
            measured.update(zip(block.index.tolist(), block.q_meas, strict=True))

    world.attach(Tap())
    blocks = _collect(link)
    link.start_stream(25)
    clock.sleep(0.333)  # blocks that end mid-window carry their partial sums
    clock.sleep(0.667)
    link.wait_for_sample(clock.now(), timeout_wall_s=10.0)
    rows = np.vstack(blocks)
    checked = 0
    for row in rows:
        i = int(row[0])
        window = [measured[j] for j in range(i - 24, i + 1) if j in measured]
        if len(window) == 25:
            np.testing.assert_allclose(row[2:6], np.mean(window, axis=0), rtol=1e-5, atol=1e-7)
            checked += 1
    assert checked >= 38


def test_dropped_and_corrupted_frames_are_counted_never_wrong(bench):
    """Faults at 2 % drop and 5 % corruption per frame: every delivered sample equals what the
    world measured, and every missing frame is counted (dropped = frames sent - delivered)."""
    world, clock, server, link = bench
    truth: dict[int, np.ndarray] = {}

    class Tap:  # records the world's measured samples: the ground truth of the stream
        def before_block(self, *a):
            pass

        def after_block(self, w, block):
            truth.update(zip(block.index.tolist(), block.q_meas, strict=True))

    world.attach(Tap())
    blocks = _collect(link)
    link.start_stream(1)
    server.inject("drop", 0.02)
    server.inject("corrupt", 0.05)
    clock.sleep(10.0)
    server.clear_faults()
    clock.sleep(0.5)  # clean frames after the faults, so a loss at the very end is seen as a gap
    link.wait_for_sample(clock.now(), timeout_wall_s=10.0)
    rows = np.vstack(blocks)
    expected = np.array([truth[int(i)] for i in rows[:, 0]])
    np.testing.assert_allclose(rows[:, 2:6], expected, rtol=1e-6, atol=1e-7)
    s = link.stats
    sent = int(link.read_register("FRAMES_SENT"))
    assert s.frames == len(rows) and s.frames + s.dropped == sent
    assert s.dropped >= server.frames_dropped > 100
    assert s.corrupt > 0 and server.frames_corrupted > 300


def test_link_drop_raises_within_timeout(bench):
    _, clock, server, link = bench
    link.start_stream(1)
    clock.sleep(0.5)
    server.inject("link-drop")
    t0 = time.monotonic()
    with pytest.raises(LinkLostError, match="FPGA link"):
        for _ in range(10):
            link.read_register("STATUS")
            time.sleep(0.05)
    assert time.monotonic() - t0 < 3 * link.timeout_s + 3.0  # generous: a loaded machine
    assert link.safe_state() is False  # cannot be confirmed


def test_stall_raises_within_timeout_and_recovers(bench):
    _, clock, server, link = bench
    server.inject("stall")
    t0 = time.monotonic()
    with pytest.raises(LinkLostError, match="no answer to read STATUS in 3 attempts"):
        link.read_register("STATUS")
    elapsed = time.monotonic() - t0
    assert 3 * link.timeout_s - 0.05 <= elapsed < 3 * link.timeout_s + 3.0  # generous: a loaded machine
    server.clear_faults()
    assert link.read_register("ID") == p.FPGA_ID


def test_stalled_stream_wait_raises(bench):
    _, clock, server, link = bench
    link.start_stream(1)
    server.inject("stall")
    clock.sleep(0.2)
    with pytest.raises(LinkLostError, match="stream stopped at sample .*no frame for 0.3 s"):
        link.wait_for_sample(clock.now(), timeout_wall_s=0.3)


def test_a_slow_stream_is_waited_for_while_its_frames_arrive():
    """A starved host delivers frames slowly: the wait lasts longer than its timeout in all but
    never goes timeout_wall_s without a frame, so it is not a lost link (a lockstep run under
    load ended ERROR "stream reached sample 304400, not 304800, within 2 s" before)."""
    import threading

    link = FpgaLink("socket://127.0.0.1:1")
    link._streaming = True
    link._last_index = 0
    steps, period_s, timeout_s = 30, 0.1, 2.0  # 3 s in all, a frame every 0.1 s

    def deliver() -> None:
        for i in range(1, steps + 1):
            time.sleep(period_s)
            with link._cond:
                link._last_index = i
                link._cond.notify_all()

    feeder = threading.Thread(target=deliver, daemon=True)
    t0 = time.monotonic()
    feeder.start()
    link.wait_for_sample(steps, timeout_wall_s=timeout_s)
    assert time.monotonic() - t0 > timeout_s and link.last_index == steps
    feeder.join()


def test_open_fails_cleanly():
    with pytest.raises(LinkLostError, match="cannot open"):
        FpgaLink("socket://127.0.0.1:1", timeout_s=0.2).connect()
    with pytest.raises(LimitError, match="timeout_s"):
        FpgaLink("socket://127.0.0.1:1", timeout_s=-1)
    assert math.isnan(FpgaLink("socket://127.0.0.1:1").sample_period_s)


def test_failing_subscriber_does_not_stop_the_link(bench):
    _, clock, _, link = bench
    good = _collect(link)

    def bad(block):
        raise RuntimeError("subscriber bug")

    link.subscribe(bad)
    link.start_stream(10)
    clock.sleep(1.0)
    link.sync(timeout_wall_s=10.0)
    assert len(np.vstack(good)) == 100 and link.stats.callback_errors >= 1
    assert link.read_register("ID") == p.FPGA_ID


def test_a_client_that_stops_reading_cannot_hang_the_world():
    """A client enables the stream and never reads: the server's blocking writes give up after
    write_timeout_s, drop the client and count the frames lost; the world keeps going."""
    import socket as socketlib

    world = World(preset("hrg"), seed=0)
    server = serve_fpga(world, write_timeout_s=0.3)
    host, port = server.url.removeprefix("socket://").split(":")
    raw = socketlib.create_connection((host, int(port)), timeout=2.0)
    raw.setsockopt(socketlib.SOL_SOCKET, socketlib.SO_RCVBUF, 4096)
    try:
        raw.sendall(p.encode_frame(p.WRITE, 1, p.BY_NAME["CTRL_SET"].addr, p.STREAM_EN.to_bytes(8, "little")))
        deadline = time.monotonic() + 5.0
        while not int(server.firmware.regs["CTRL"]) & p.STREAM_EN and time.monotonic() < deadline:
            time.sleep(0.01)
        t0 = time.monotonic()
        world.advance(300.0)  # 300 000 frames, 18 MB: far more than the socket buffers hold
        assert time.monotonic() - t0 < 30.0  # the encoding costs ~1 s; a hang would be forever
        assert server.frames_lost > 0
    finally:
        raw.close()
        server.stop()


def test_pty_without_a_reader_cannot_hang_the_world():
    """On a pty nobody reads: after one write timeout the server skips writes until the pty
    drains, so the world runs on at full speed and counts the frames lost."""
    world = World(preset("hrg"), seed=0)
    server = serve_fpga(world, transport="pty", write_timeout_s=0.3)
    try:
        server.firmware.write(p.BY_NAME["CTRL_SET"], p.STREAM_EN)
        t0 = time.monotonic()
        world.advance(60.0)  # 3.6 MB of frames into a pty buffer of a few kB
        assert time.monotonic() - t0 < 20.0  # one 0.3 s timeout, not one per block (180 s)
        assert server.frames_lost > 50_000
    finally:
        server.stop()


def test_wait_without_a_stream_returns_at_once(bench):
    _, clock, _, link = bench
    blocks = _collect(link)
    clock.sleep(0.5)
    link.sync(timeout_wall_s=0.1)  # no stream: nothing to wait for
    link.start_stream(1)
    clock.sleep(0.5)
    link.stop_stream()  # ordered after every frame sent before it
    n = link.stats.frames
    assert n == 500 and len(np.vstack(blocks)) == n
    clock.sleep(0.5)
    link.sync(timeout_wall_s=0.1)
    assert link.stats.frames == n


def test_reconnect_after_a_link_drop():
    world = World(preset("hrg"), seed=0)
    server = serve_fpga(world)
    link = FpgaLink(server.url, timeout_s=0.5).connect()
    try:
        server.inject("link-drop")
        with pytest.raises(LinkLostError):
            for _ in range(20):
                link.read_register("ID")
                time.sleep(0.05)
        assert not link.connected
        link.connect()
        assert link.connected and link.read_register("ID") == p.FPGA_ID
    finally:
        link.close()
        server.stop()


def test_a_protocol_version_mismatch_is_one_clear_message():
    """A device of another protocol version (its stream frame differs) is refused at connect, with
    the two versions named, and the port is closed."""
    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    server = serve_fpga(world, seed=1)
    try:
        server.firmware.regs["VERSION"] = 1
        link = FpgaLink(server.url, clock=clock, timeout_s=0.5)
        with pytest.raises(ProtocolError, match=r"protocol VERSION is 1, this driver speaks 3") as err:
            link.connect()
        assert "\n" not in str(err.value) and not link.connected
    finally:
        server.stop()
        clock.close()


def test_output_mode_values_are_checked_before_anything_is_written(bench):
    world, _, server, link = bench
    with pytest.raises(LimitError, match="output_mode='rate' is not one of whole-angle, force-to-rebalance"):
        link.set_output_mode("rate")
    with pytest.raises(LimitError, match="FTR_ANGLE_DEG"):
        link.set_output_mode("force-to-rebalance", ftr_angle_deg=60.0, ftr_gain=2.0)
    assert server.firmware.regs["FTR_GAIN"] == 1.0 and server.firmware.regs["OUTPUT_MODE"] == 0
    link.set_output_mode("force-to-rebalance", ftr_angle_deg=10.0, ftr_gain=2.0)
    assert link.output_mode() == "force-to-rebalance"
    # and the frequency the PLL runs the wave held at 10 deg at (the hrg's 5 mHz split along it)
    from simulators.physics.drive_frequency import drive_frequency_offset_hz

    offset_hz = drive_frequency_offset_hz(world.params, None, setpoint=1.0, angle_deg=10.0)
    assert offset_hz == pytest.approx(0.005 / 2.0 * math.cos(math.radians(4.0 * (10.0 - 10.0))), rel=1e-9)
    assert server.truth() == {"cvg_output_mode": 1.0, "ftr_angle_deg": 10.0, "ftr_gain": 2.0, "agc_setpoint": 1.0,
                              "drive_freq_offset_hz": pytest.approx(offset_hz, rel=1e-12)}


def test_an_advance_streams_in_one_write_and_a_reply_comes_after_its_frames(bench):
    """The simulated FPGA writes the frames of one World.advance in one piece (one reader wake-up
    and one delivery per advance, not one per 50 ms block: issue 14 item 6), and a reply still
    follows every frame produced before it."""
    world, clock, server, link = bench
    blocks = _collect(link)
    link.set_pll(True)  # the loops cut the world into their 50 ms blocks
    link.start_stream(1)
    link.sync()
    blocks.clear()
    port, writes = server._port, []
    send = port.send
    port.send = lambda data, timeout_s: writes.append(len(data)) or send(data, timeout_s)
    clock.sleep(1.0)  # one advance: 20 blocks of 50 ms
    link.sync()
    rows = np.concatenate(blocks)
    assert len(rows) == 1000 and np.all(np.diff(rows[:, 0]) == 1)
    assert writes == [1000 * p.STREAM_FRAME_SIZE], f"{len(writes)} writes for one advance"
    clock.sleep(0.25)
    link.read_register("STATUS")  # no sync: the reply came after the 250 frames streamed before it
    assert link.last_index == world.sample_index
