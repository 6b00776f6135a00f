"""The simulated SR865's command set, byte for byte as the SR86x manual gives it: 6-digit
frequency, unit suffixes, unknown queries (a status bit, no answer), the status registers,
SNAPD?, HARM, SCAL, IRNG, SOFF, RTRG, REFZ; and one unknown query through the whole driver."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from drivers.errors import ProtocolError
from simulators.frontend.sr865_server import Sr865Model, clipped_fundamental, rounded_frequency_hz


@pytest.fixture
def m() -> Sr865Model:
    return Sr865Model(1, serial="T")


@pytest.mark.parametrize(
    "asked, kept",
    [(13_646.637, 13_646.6), (13_646.65, 13_646.6), (999_999.7, 1_000_000.0), (123.4567, 123.457),
     (5.123456, 5.1235), (0.00123, 0.0012)],
)
def test_frequency_keeps_six_digits_or_a_tenth_of_a_millihertz(asked, kept):
    assert rounded_frequency_hz(asked) == kept


def test_transcript_frequency_and_unit_suffixes(m):
    assert m.execute("FREQ 13646.637;FREQ?") == "1.364660000e+04"
    assert m.execute("FREQ 1.364664e+04;FREQ?") == "1.364660000e+04"  # PyMeasure's "%0.6e"
    assert m.execute("FREQ 13.6 KHZ;FREQ?") == "1.360000000e+04"
    assert m.execute("FREQ 13.6KHZ;FREQ?") == "1.360000000e+04"
    assert m.execute("SLVL 100 MV;SLVL?") == "1.000000000e-01"
    assert m.execute("SOFF -250 mV;SOFF?") == "-2.500000000e-01"
    assert m.execute("PHAS 30 DEG;PHAS?") == "30.0000000"
    assert m.execute("*ESR?") == "0"
    assert m.execute("FREQ 3 MV;*ESR?") == "32"  # a volt suffix on a frequency: command error
    assert m.execute("FREQ?") == "1.360000000e+04"  # unchanged


def test_transcript_unknown_query_is_a_status_bit_not_an_answer(m):
    assert m.execute("FOO?") is None
    assert m.execute("*ESR?") == "32"
    assert m.execute("*ESR?") == "0"  # reading clears it
    assert m.execute("*ESE 32;FOO?;*STB?") == "32"  # ESB summarises the enabled *ESR bits
    assert m.execute("*SRE 32;*STB?") == "96"  # ... and MSS follows the enabled summary bits
    assert m.execute("*CLS;*STB?") == "0"
    assert m.execute("HARM 100;*ESR?") == "16"  # out of range: execution error
    assert m.execute("*ESE?;*SRE?") == "32;32"


def test_transcript_settings_the_front_end_checks(m):
    assert m.execute("HARM?;SOFF?;RTRG?;REFZ?;SCAL?;IRNG?") == "1;0.000000000e+00;0;1;0;0"
    assert m.execute("Harm 2;HARM?") == "2"  # PyMeasure writes "Harm %d"
    assert m.execute("RTRG 1;REFZ 0;SCAL 8;IRNG 3;RTRG?;REFZ?;SCAL?;IRNG?") == "1;0;8;3"
    assert m.execute("RTRG 3;SCAL 28;IRNG 5;*ESR?") == "16"
    assert m.execute("RSRC 2;*ESR?") == "16"  # dual reference: not simulated, refused


def test_transcript_snapd_and_outputs(m):
    m.cs = np.array([0.0, 0.5])  # a pickoff of 0.5 sin(wt): X = 0.5/sqrt(2) at PHAS 0
    m.execute("FREQ 13646.6;SLVL 0.2;SOFF 0.1")
    assert m.execute("SNAPD?") == "3.535533906e-01,0.000000000e+00,3.535533906e-01,0.000000000e+00"
    assert m.execute("CDSP 3, FI;SNAPD?").endswith(",1.364660000e+04")
    assert m.execute("SNAP? X, SAM, LEV") == "3.535533906e-01,2.000000000e-01,1.000000000e-01"
    assert m.execute("SNAP? TH, PHASE") == "0.000000000e+00,0.000000000e+00"
    assert m.execute("HARM 2;SNAP? X, Y") == "0.000000000e+00,0.000000000e+00"  # nothing at 2f


def test_transcript_overload_registers(m):
    """CUROVLDSTAT? is the state now; LIAS? latches until read (all of it, or one bit)."""
    m.cs = np.array([0.0, 0.5])
    assert m.execute("CUROVLDSTAT?;LIAS?") == "0;0"
    m.execute("SCAL 3")  # 100 mV full scale against X = 354 mV
    assert m.execute("CUROVLDSTAT?") == "1"
    m.lias |= m.overload_bits()
    m.execute("SCAL 0")
    assert m.execute("CUROVLDSTAT?;LIAS? 0;LIAS?") == "0;1;0"
    m.lias = 0b1_1001
    assert m.execute("LIAE 16;*STB?") == "8"  # the LIA summary bit, through its enable mask
    assert m.execute("LIAS?;LIAS?") == "25;0"
    slave = Sr865Model(2, serial="S")
    slave.execute("RSRC 1")
    assert slave.execute("CUROVLDSTAT?") == "8"  # external reference and nothing to lock to


def test_clipped_sine_fundamental():
    """Truth: a sine clipped at its peak keeps all of it; at half its peak, (2/pi)(pi/6 + sqrt(3)/4)."""
    np.testing.assert_allclose(clipped_fundamental(np.array([1.0, 0.5, 0.0])),
                               [1.0, (2 / np.pi) * (np.pi / 6 + np.sqrt(3) / 4), 0.0])


def test_an_unknown_query_on_the_socket_leaves_the_link_in_step():
    """Bytes on the simulator's socket: no answer to FOO?, then *ESR?'s 32 (not a stale reply)."""
    from simulators.frontend.sr865_server import serve_sr865_pair
    from simulators.physics.params import preset
    from simulators.world import World

    world = World(preset("mems"), seed=0)
    server = serve_sr865_pair(world)
    try:
        with socket.create_connection((server.servers[0].host, server.servers[0].port), timeout=5) as s:
            s.sendall(b"FOO?\n*ESR?\n*IDN?\n")
            data = b""
            while data.count(b"\n") < 2:
                data += s.recv(4096)
        assert data == b"32\nStanford_Research_Systems,SR865,SIM001,v1.0-gyrobench-sim\n"
    finally:
        server.stop()


def test_the_driver_names_an_unknown_query_instead_of_losing_the_link():
    """The front end's query the instrument does not know: a ProtocolError saying so (its *ESR?
    answered 32), not a LinkLostError that would take the station to its safe state."""
    from bench.composition.sim_station import SimStation

    with SimStation("sim-mems-sr865").open() as station:
        fe = station.devices["frontend"]
        fe.devices[1].instrument.adapter.connection.timeout = 200  # ms: keep the test short
        with pytest.raises(ProtocolError, match=r"FOO\? went unanswered and \*ESR\? = 32"):
            fe.devices[1].ask("FOO?")
        assert "SR865" in fe.idn
