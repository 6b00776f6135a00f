"""A simulator's server and the FPGA link end their threads when stopped (woken at once, issue 36:
no poll left to wait out), and the clients see the link go."""

from __future__ import annotations

import socket

import pytest

from simulators.line_server import LineServer


def test_loopback_server_stop_ends_accept_thread_and_refuses_clients() -> None:
    srv = LineServer(lambda line: line.encode())
    client = socket.create_connection((srv.host, srv.port), timeout=5)
    client.sendall(b"ping\n")
    assert client.recv(16) == b"ping\n"  # accepted and served: a live connection
    srv.stop()
    assert not srv._thread.is_alive()
    assert client.recv(1) == b""  # the live connection was shut
    client.close()
    with pytest.raises(OSError):
        socket.create_connection((srv.host, srv.port), timeout=5).close()
    srv.stop()  # a second stop is a no-op


@pytest.mark.parametrize("transport", ["socket", "pty"])
def test_fpga_link_and_server_close_end_their_threads(transport: str) -> None:
    from bench.clock import SimClock
    from drivers.fpga import FpgaLink
    from simulators.fpga import serve_fpga
    from simulators.physics.params import preset
    from simulators.world import World

    world = World(preset("hrg"), seed=0)
    clock = SimClock(world)
    server = serve_fpga(world, transport=transport, seed=1)
    link = FpgaLink(server.url, clock=clock, timeout_s=0.5, retries=2).connect()
    reader = link._reader
    assert link.read_register("ID")  # the link answers
    link.close()
    assert reader is not None and not reader.is_alive()
    assert link._wake is None  # the wake-up pipe is closed with the link
    link.connect()  # a closed link opens again (a new reader and pipe)
    assert link.read_register("ID")
    link.close()
    server.stop()
    assert not any(t.is_alive() for t in server._threads)
    clock.close()
