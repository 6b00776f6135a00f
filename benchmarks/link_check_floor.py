"""What one lockstep grid point's link checks cost at the least, against the 1000x budget of
issue 14 item 6 (the whole hrg-damping at >= 1000x real time: 0.4 ms of wall time for everything
a 0.4 s grid point does).

The engine checks every link once per 0.4 s of simulated time in lockstep (faults found within
0.5 simulated s): the table's status (Modbus/TCP), the front end's tagged *IDN? (SCPI over a VISA
socket) and the FPGA link's sync (its reader has delivered the stream up to the bench clock).
Measured here, on an open `sim-hrg` station whose world does not move between checks (so no
stream frame is pending and the simulated devices do no work for the time that passes):
  (1) a bare request/reply of 12 bytes over loopback TCP between two threads of one Python
      process (the least any request/reply link check costs in Python on this machine), and the
      same with the server in a process of its own (no shared GIL);
  (2) each of the station's three checks, as check_links makes them, and their sum per grid point.
Wall time and the process's CPU time per call (all threads: the servers answer on theirs).

Run: .venv/bin/python benchmarks/link_check_floor.py [--n 3000]

Measured 2026-11-27 on the 2-vCPU machine, nothing else running (load average 0.2-0.3), two runs:
  bare request/reply, server on a thread            20.5-26.0 us wall, 18.5-25.1 us CPU
  bare request/reply, server in its own process     20.1-21.6 us wall,  8.8-10.5 us CPU (this side)
  table status (Modbus/TCP, probe_status)           47.9-58.5 us wall (CPU the same: client + server)
  front end probe (tagged *IDN? over VISA)          45.0-46.8 us wall
  FPGA link sync (nothing pending)                   1.3-2.7 us wall
  the three checks of one grid point               94-108 us = 24-27 % of the 400 us budget at 1000x
In hrg-damping's run (benchmarks/lockstep_breakdown.py, same day) the same checks take ~490 us a grid
point: 248 us of the sync is the reader thread parsing and delivering the grid point's frames
(and the raw-data writer it wakes), and the two request/replies are 2-3x their idle cost while
those threads and the writer share the two vCPUs (two busy threads each run at about half speed
on this machine: a compiled CRC of 40 frames takes 5 us alone and 10 us with the other vCPU busy).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import socket
import threading
import time
from collections.abc import Callable


def _echo_server(sock: socket.socket) -> None:
    """Answer each 12-byte request with 12 bytes until the peer closes."""
    conn, _ = sock.accept()
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    with conn:
        while True:
            data = conn.recv(12)
            if not data:
                return
            conn.sendall(data)


def _serve_in_process(port_box) -> None:
    sock = socket.create_server(("127.0.0.1", 0))
    port_box.put(sock.getsockname()[1])
    _echo_server(sock)


def bare_round_trips(n: int, own_process: bool) -> tuple[float, float]:
    """(wall us, this process's CPU us) per request/reply to an echo server on a thread of this
    process or in a process of its own."""
    if own_process:
        box = multiprocessing.get_context("spawn").Queue()
        proc = multiprocessing.get_context("spawn").Process(target=_serve_in_process, args=(box,), daemon=True)
        proc.start()
        port = box.get(timeout=30)
    else:
        server = socket.create_server(("127.0.0.1", 0))
        port = server.getsockname()[1]
        threading.Thread(target=_echo_server, args=(server,), daemon=True).start()
    client = socket.create_connection(("127.0.0.1", port))
    client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    request = b"x" * 12
    for _ in range(200):  # warm-up
        client.sendall(request)
        client.recv(12)
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        client.sendall(request)
        client.recv(12)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    client.close()
    if own_process:
        proc.join(timeout=5)
    return wall / n * 1e6, cpu / n * 1e6


def timed(fn: Callable[[], object], n: int) -> tuple[float, float]:
    """(wall us, process CPU us) per call of fn."""
    for _ in range(50):
        fn()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6, (time.process_time() - c0) / n * 1e6


def station_checks(n: int) -> dict[str, tuple[float, float]]:
    """Each link check of an open sim-hrg station (stream running, world still) per call."""
    from bench.composition.sim_station import SimStation

    station = SimStation("sim-hrg", seed=0).open()
    try:
        fpga = station.devices["fpga"]
        fpga.start_stream(10)  # hrg-damping's record: every 10th sample (100 Hz)
        station.clock.sleep(0.4)  # a grid point's worth, so the stream has delivered something
        out = {
            "table status (Modbus/TCP)": timed(station.devices["table"].probe_status, n),
            "front end probe (SCPI *IDN?)": timed(station.devices["frontend"].probe, n),
            "FPGA link sync (nothing pending)": timed(fpga.sync, n),
        }
        fpga.stop_stream()
    finally:
        station.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=3000, help="calls per measurement")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.n} calls each")
    for label, own in (("bare request/reply, server on a thread", False),
                       ("bare request/reply, server in its own process", True)):
        wall, cpu = bare_round_trips(args.n, own)
        print(f"  {label:48s} {wall:7.1f} us wall {cpu:7.1f} us CPU (this process)")
    checks = station_checks(args.n)
    for label, (wall, cpu) in checks.items():
        print(f"  {label:48s} {wall:7.1f} us wall {cpu:7.1f} us CPU (all threads)")
    total = sum(w for w, _ in checks.values())
    print(f"  {'the three checks of one grid point':48s} {total:7.1f} us wall = "
          f"{total / 400:.0%} of the 400 us a 0.4 s grid point has at 1000x")
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
