"""The SR865 pair over VXI-11, the VISA path a lab's LAN instruments use (`TCPIP::host::INSTR`):
the simulator's ONC RPC portmapper and core channel against pyvisa-py's own client, a lab's
station file through the portmapper, and mems-sweep on the VXI-11 station end to end."""

from __future__ import annotations

import socket
import struct
from pathlib import Path

import numpy as np
import pytest

from bench.composition import load_station
from bench.composition.sim_station import SimStation
from drivers.frontend.sr865_pair import Sr865PairFrontEnd
from simulators.frontend.sr865_server import serve_sr865_pair
from simulators.physics.params import preset
from simulators.vxi11 import CORE_PROG, CORE_VERS, PortMapper, record, xdr_opaque, xdr_uint
from simulators.world import World


def _call(sock: socket.socket, xid: int, prog: int, vers: int, proc: int, args: bytes) -> bytes:
    """One ONC RPC call (AUTH_NONE) in one record; the reply record's bytes."""
    sock.sendall(record(xdr_uint(xid, 0, 2, prog, vers, proc, 0, 0, 0, 0) + args))
    head = sock.recv(4, socket.MSG_WAITALL)
    (mark,) = struct.unpack(">I", head)
    assert mark & 0x8000_0000
    return sock.recv(mark & 0x7FFF_FFFF, socket.MSG_WAITALL)


def test_rpc_bytes_of_getport_and_the_core_channel():
    """Byte-pinned: GETPORT answers the core channel's port (RFC 1833), create_link / device_write
    (END) / device_read / destroy_link as VXI-11 B.1 lays them out."""
    world = World(preset("mems"), seed=0)
    pair = serve_sr865_pair(world, visa="vxi11")
    core = pair.servers[0]
    pmap = PortMapper({(CORE_PROG, CORE_VERS): core.port})
    try:
        with socket.create_connection((pmap.host, pmap.port), timeout=5) as s:
            reply = _call(s, 7, 100000, 2, 3, xdr_uint(CORE_PROG, CORE_VERS, 6, 0))
            assert reply == xdr_uint(7, 1, 0, 0, 0, 0, core.port)
            assert _call(s, 8, 100000, 2, 3, xdr_uint(CORE_PROG, 9, 6, 0)) == xdr_uint(8, 1, 0, 0, 0, 0, 0)
        with socket.create_connection((core.host, core.port), timeout=5) as s:
            reply = _call(s, 1, CORE_PROG, 1, 10, xdr_uint(42, 0, 0) + xdr_opaque(b"inst0"))
            xid, _, _, _, _, stat, error, lid, abort_port, max_recv = struct.unpack(">10I", reply)
            assert (xid, stat, error, abort_port, max_recv) == (1, 0, 0, 0, 1 << 20)
            message = b"FREQ 13.6 KHZ;FREQ?\n"
            reply = _call(s, 2, CORE_PROG, 1, 11, xdr_uint(lid, 1000, 1000, 0x08) + xdr_opaque(message))
            assert reply == xdr_uint(2, 1, 0, 0, 0, 0, 0, len(message))
            reply = _call(s, 3, CORE_PROG, 1, 12, xdr_uint(lid, 1024, 1000, 1000, 0x80, 10))
            assert reply == xdr_uint(3, 1, 0, 0, 0, 0, 0, 4 | 2) + xdr_opaque(b"1.360000000e+04\n")
            reply = _call(s, 4, CORE_PROG, 1, 12, xdr_uint(lid, 1024, 50, 1000, 0, 10))
            assert reply == xdr_uint(4, 1, 0, 0, 0, 0, 15, 0) + xdr_opaque(b"")  # nothing to read: io_timeout
            assert _call(s, 5, CORE_PROG, 1, 23, xdr_uint(lid)) == xdr_uint(5, 1, 0, 0, 0, 0, 0)
            assert _call(s, 6, CORE_PROG, 1, 23, xdr_uint(lid)) == xdr_uint(6, 1, 0, 0, 0, 0, 4)  # gone
    finally:
        pmap.stop()
        pair.stop()


def _portmappers(hosts: tuple[str, ...], programs: list[dict]) -> tuple[int, list[PortMapper]]:
    """A portmapper on each host, all on one port: 111 when it is free (root), else a free one."""
    for first in (111, 0):
        try:
            maps = [PortMapper(programs[0], hosts[0], first)]
        except OSError:
            continue
        try:
            maps += [PortMapper(p, h, maps[0].port) for p, h in zip(programs[1:], hosts[1:], strict=True)]
            return maps[0].port, maps
        except OSError:
            maps[0].stop()
    raise RuntimeError("no port free for the portmappers on both loopback addresses")


def _doc_station_files() -> dict[str, str]:
    """The lab station files docs/frontend_sr865.md gives, by station id."""
    import tomllib

    text = (Path(__file__).resolve().parents[1] / "docs" / "frontend_sr865.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```toml\n")[1:]]
    return {tomllib.loads(b)["station"]["id"]: b for b in blocks}


def _open_lab_station(tmp_path, text: str, pair) -> None:
    """Open a lab's station file against the simulated pair and use it once."""
    path = tmp_path / "lab.toml"
    path.write_text(text)
    with load_station(path).open() as station:
        fe = station.devices["frontend"]
        assert isinstance(fe, Sr865PairFrontEnd)
        assert fe.idn.count("SR865") == 2
        assert fe.set_frequency_hz(13_646.637) == 13_646.6
        assert pair.models[0].freq_int_hz == 13_646.6
        assert (pair.models[1].rsrc, pair.models[1].rtrg, pair.models[1].refz) == (1, 1, 1)
        assert station.safe_state().confirmed


def test_the_docs_vxi11_station_file_reaches_both_lock_ins_through_the_portmapper(tmp_path, monkeypatch):
    """The resource strings a lab writes (`TCPIP::<ip>::INSTR`, the docs' file with its two
    addresses made loopback ones): pyvisa-py asks the portmapper (port 111, or wherever it was
    put) for each core channel, then speaks VXI-11 to it."""
    from pyvisa_py.protocols import rpc

    text = _doc_station_files()["lab-mems-sr865-vxi11"]
    assert 'resource = "TCPIP::192.168.1.20::INSTR"' in text
    hosts = ("127.0.0.1", "127.0.0.2")
    world = World(preset("mems"), seed=1)
    pair = serve_sr865_pair(world, host=hosts, visa="vxi11")
    port, maps = _portmappers(hosts, [{(CORE_PROG, CORE_VERS): s.port} for s in pair.servers])
    monkeypatch.setattr(rpc, "PMAP_PORT", port)
    try:
        _open_lab_station(tmp_path, text.replace("192.168.1.20", hosts[0]).replace("192.168.1.21", hosts[1]), pair)
    finally:
        for m in maps:
            m.stop()
        pair.stop()


def test_the_docs_socket_station_file_opens_the_pair(tmp_path):
    text = _doc_station_files()["lab-mems-sr865-socket"]
    world = World(preset("mems"), seed=1)
    pair = serve_sr865_pair(world)
    try:
        for doc_resource, resource in zip(("TCPIP::192.168.1.20::5025::SOCKET", "TCPIP::192.168.1.21::5025::SOCKET"),
                                          pair.resources, strict=True):
            assert doc_resource in text
            text = text.replace(doc_resource, resource)
        _open_lab_station(tmp_path, text, pair)
    finally:
        pair.stop()


def test_mems_sweep_on_the_vxi11_station_matches_the_socket_one(tmp_path):
    """sim-mems-sr865-vxi11: the same station as sim-mems-sr865 over VXI-11; the same sweep gives
    the same numbers (the transport carries the same bytes)."""
    from bench.engine import Runner
    from procedures.mems_sweep import MemsSweep

    results = {}
    for name in ("sim-mems-sr865-vxi11", "sim-mems-sr865"):
        station = SimStation(name, seed=0).open()
        try:
            if name.endswith("vxi11"):
                assert all(r.endswith("::INSTR") for r in (station.addresses["frontend"]["resource"],
                                                           station.addresses["frontend"]["resource2"]))
            record = Runner(station, runs_dir=tmp_path / name).run(MemsSweep, {"n_points": 9})
        finally:
            station.close()
        assert record.outcome == "COMPLETE", record.traceback
        results[name] = np.array([r.value for r in record.measurements], dtype=float)
    np.testing.assert_array_equal(results["sim-mems-sr865-vxi11"], results["sim-mems-sr865"])


def test_a_hung_lock_in_over_vxi11_is_a_lost_link():
    from drivers.errors import LinkLostError

    with SimStation("sim-mems-sr865-vxi11").open() as station:
        fe = station.devices["frontend"]
        for dev in fe.devices.values():
            dev.instrument.adapter.connection.timeout = 200
        station.handles["frontend"].inject("hang")
        with pytest.raises(LinkLostError):
            fe.lockin_all()
        station.handles["frontend"].inject("none")
        assert fe.safe_state() is True
