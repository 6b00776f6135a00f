"""FPGA link stream benchmark: sustained lockstep throughput through FpgaLink with zero loss
(socket:// and pty), latency from a block's write to its subscriber at a real-time 1 kHz, and
the CPU share at 1 kHz.  Prints its figures; run: .venv/bin/python benchmarks/fpga_stream.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import time

import numpy as np

from bench.clock import SimClock
from drivers.fpga import FpgaLink
from drivers.fpga import protocol as p
from simulators.fpga import serve_fpga
from simulators.physics.params import preset
from simulators.world import World


def throughput(transport: str, wall_s: float, max_block_s: float = 0.1) -> dict[str, float]:
    """Lockstep world streaming every 1 kHz sample; frames/s delivered to a subscriber."""
    world = World(preset("hrg"), seed=0, max_block_s=max_block_s)
    clock = SimClock(world)
    server = serve_fpga(world, transport=transport)
    link = FpgaLink(server.url, clock=clock, timeout_s=2.0).connect()
    count = [0]
    link.subscribe(lambda b: count.__setitem__(0, count[0] + len(b)))
    link.start_stream(1)
    cpu0, t0 = time.process_time(), time.perf_counter()
    while time.perf_counter() - t0 < wall_s:
        clock.sleep(10.0)
    link.wait_for_sample(clock.now(), timeout_wall_s=30.0)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    s = link.stats
    sent = int(link.read_register("FRAMES_SENT"))
    link.close()
    server.stop()
    clock.close()
    assert s.frames == count[0]
    return {
        "frames": s.frames, "lost": sent - s.frames, "dropped": s.dropped, "corrupt": s.corrupt,
        "frames_per_s": s.frames / wall, "values_per_s": 8 * s.frames / wall,
        "x_realtime": s.frames / wall / 1000.0,
        "frames_per_cpu_s": s.frames / cpu, "cpu_per_wall": cpu / wall, "reader_cpu_s": s.reader_cpu_s,
        "wall_s": wall,
    }


def driver_ceiling(transport: str, n_frames: int = 400_000) -> dict[str, float]:
    """The driver alone: pre-encoded frames pushed through the server's write path as fast as
    the link takes them (no world), parsed and delivered to a subscriber."""
    world = World(preset("hrg"), seed=0)
    server = serve_fpga(world, transport=transport)
    link = FpgaLink(server.url, timeout_s=2.0).connect()
    count = [0]
    link.subscribe(lambda b: count.__setitem__(0, count[0] + len(b)))
    link.start_stream(1)
    chunk = 2000
    rng = np.random.default_rng(0)
    payload = [
        p.encode_stream(k, np.arange(k + 1, k + chunk + 1), np.arange(k + 1, k + chunk + 1) * 1e-3,
                        rng.normal(size=(chunk, 8)))
        for k in range(0, n_frames, chunk)
    ]
    cpu0, t0 = time.process_time(), time.perf_counter()
    for data in payload:
        server._send_stream(data, chunk)
    link.wait_for_sample(n_frames, timeout_wall_s=30.0)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    s = link.stats
    link.close()
    server.stop()
    return {"frames": s.frames, "dropped": s.dropped, "frames_per_s": s.frames / wall,
            "frames_per_cpu_s": s.frames / cpu, "cpu_per_wall": cpu / wall}


def _world_process(conn, virtual_s: float, max_block_s: float) -> None:
    """Child process: a lockstep world with the FPGA server, advanced on the parent's signal."""
    world = World(preset("hrg"), seed=0, max_block_s=max_block_s)
    server = serve_fpga(world)
    conn.send(server.url)
    conn.recv()  # go: the parent's stream is on
    cpu0 = time.process_time()
    world.advance(virtual_s)
    conn.send(time.process_time() - cpu0)
    conn.recv()
    server.stop()


def throughput_two_processes(virtual_s: float = 600.0, max_block_s: float = 0.1) -> dict[str, float]:
    """The simulator in its own process (as `gyrobench sim` runs it), the driver in this one."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_world_process, args=(child, virtual_s, max_block_s), daemon=True)
    proc.start()
    link = FpgaLink(parent.recv(), timeout_s=5.0).connect()
    count = [0]
    link.subscribe(lambda b: count.__setitem__(0, count[0] + len(b)))
    link.start_stream(1)
    n = int(round(virtual_s / link.sample_period_s))
    cpu0, t0 = time.process_time(), time.perf_counter()
    parent.send("go")
    link.wait_for_sample(int(link.read_register("STREAM_START_INDEX")) + n, timeout_wall_s=120.0)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    child_cpu = parent.recv()
    s = link.stats
    link.close()
    parent.send("stop")
    proc.join(timeout=10.0)
    return {"frames": s.frames, "dropped": s.dropped, "corrupt": s.corrupt, "frames_per_s": s.frames / wall,
            "driver_cores": cpu / wall, "sim_cores": child_cpu / wall}


class _WriteStamp:
    """Attached before the FPGA: its after_block runs just before the FPGA writes the block."""

    def __init__(self) -> None:
        self.t_write: dict[int, float] = {}

    def before_block(self, *args) -> None:
        pass

    def after_block(self, world, block) -> None:
        self.t_write[int(block.index[-1])] = time.perf_counter()


def realtime(wall_s: float, decimation: int = 1) -> dict[str, float]:
    """A real-time 1 kHz stream: latency write -> subscriber, and the process's CPU share."""
    world = World(preset("hrg"), seed=0)
    stamp = _WriteStamp()
    world.attach(stamp)
    clock = SimClock(world, speed=1.0, tick_s=0.001)
    server = serve_fpga(world)
    link = FpgaLink(server.url, clock=clock, timeout_s=2.0).connect()
    lat: list[float] = []

    def on_block(b: np.ndarray) -> None:
        t = time.perf_counter()
        w = stamp.t_write.get(int(b[-1, 0]))
        if w is not None:
            lat.append(t - w)

    link.subscribe(on_block)
    link.start_stream(decimation)
    time.sleep(0.5)
    lat.clear()
    reader0 = link.stats.reader_cpu_s
    cpu0, t0 = time.process_time(), time.perf_counter()
    time.sleep(wall_s)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    reader = link.stats.reader_cpu_s - reader0
    s = link.stats
    link.close()
    server.stop()
    clock.close()
    ms = np.array(lat) * 1e3
    return {
        "frames": s.frames, "dropped": s.dropped, "blocks": len(ms),
        "latency_median_ms": float(np.median(ms)), "latency_p99_ms": float(np.percentile(ms, 99)),
        "latency_max_ms": float(ms.max()), "cpu_share_process": cpu / wall, "cpu_share_reader": reader / wall,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--wall-s", type=float, default=3.0)
    args = ap.parse_args()
    for transport, max_block_s in (("socket", 0.1), ("pty", 0.1), ("socket", 1.0)):
        r = throughput(transport, args.wall_s, max_block_s)
        print(f"lockstep {transport:6s} {max_block_s * 1000:4.0f}-sample blocks: {r['frames_per_s']:9.0f} frames/s "
              f"({r['values_per_s']:.3g} channel values/s, "
              f"{r['x_realtime']:.0f}x a 1 kHz stream), frames {r['frames']}, lost {r['lost']}, "
              f"dropped {r['dropped']}, corrupt {r['corrupt']}, CPU {r['cpu_per_wall']:.2f} cores "
              f"({r['frames_per_cpu_s']:.0f} frames per CPU second), "
              f"reader thread {r['reader_cpu_s'] / r['wall_s']:.2f} cores")
    for transport in ("socket", "pty"):
        r = driver_ceiling(transport)
        print(f"driver alone {transport:6s}: {r['frames_per_s']:9.0f} frames/s, frames {r['frames']}, "
              f"dropped {r['dropped']}, CPU {r['cpu_per_wall']:.2f} cores "
              f"({r['frames_per_cpu_s']:.0f} frames per CPU second, server writes included)")
    for max_block_s in (0.1, 1.0):
        r = throughput_two_processes(max_block_s=max_block_s)
        print(f"two processes, {max_block_s * 1000:4.0f}-sample blocks: {r['frames_per_s']:9.0f} frames/s, "
              f"frames {r['frames']}, dropped {r['dropped']}, corrupt {r['corrupt']}; CPU: driver process "
              f"{r['driver_cores']:.2f} cores, simulator process {r['sim_cores']:.2f} cores")
    r = realtime(args.wall_s)
    print(f"real-time 1 kHz socket: write->subscriber latency median {r['latency_median_ms']:.3f} ms, "
          f"p99 {r['latency_p99_ms']:.3f} ms, max {r['latency_max_ms']:.3f} ms over {r['blocks']} blocks; "
          f"CPU share: whole process (world + server + driver) {100 * r['cpu_share_process']:.1f} %, "
          f"driver reader thread {100 * r['cpu_share_reader']:.1f} %; dropped {r['dropped']}")


if __name__ == "__main__":
    main()
