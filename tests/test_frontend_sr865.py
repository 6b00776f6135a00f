"""The two-SR865 front end (PyMeasure's SR860 driver) against its simulator: the same readings as
the SCPI front end on the same world, limits, lost links, the safe state and the measured skew."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bench.composition.sim_station import SimStation
from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError
from drivers.frontend.sr865_pair import Sr865PairFrontEnd
from simulators.frontend.sr865_server import Sr865Model

F_HZ = 13_646.6  # near the MEMS preset's resonance


def _settled_reading(station, drives) -> np.ndarray:
    fe = station.devices["frontend"]
    fe.lockin_tc_s = 0.01
    for ch, (amp, phase) in drives.items():
        fe.set_drive(ch, amplitude_v=amp, frequency_hz=F_HZ, phase_deg=phase, output_on=True)
    station.clock.sleep(0.6)
    return np.mean([fe.lockin_all() for _ in range(5)], axis=0)


def test_readings_agree_with_the_scpi_front_end_on_the_same_world():
    """Truth: the SCPI front end's lock-in on the same preset and seed.  Drive and read
    conventions (peak volts, cos/sin parts, drive phase) must come out the same through the
    SR865's rms volts and sin(wt + PHAS) reference: agreement to 1e-3 of the amplitude."""
    drives = {1: (0.888, 46.43), 2: (0.0308, 113.15)}
    with SimStation("sim-mems").open() as ref_station:
        ref = _settled_reading(ref_station, drives)
    with SimStation("sim-mems-sr865").open() as station:
        got = _settled_reading(station, drives)
        assert isinstance(station.devices["frontend"], Sr865PairFrontEnd)
    scale = np.max(np.abs(ref))
    assert scale > 0.05
    np.testing.assert_allclose(got, ref, atol=1e-3 * scale)


@pytest.fixture
def station():
    with SimStation("sim-mems-sr865").open() as st:
        yield st


def test_slave_follows_the_master_reference(station):
    """Truth: the SR865 keeps 6 digits of an asked frequency (12345.678 -> 12345.7)."""
    fe = station.devices["frontend"]
    assert fe.set_frequency_hz(12_345.678) == 12_345.7
    master, slave = fe.devices[1], fe.devices[2]
    assert float(master.ask("FREQ?")) == 12_345.7
    assert float(slave.ask("FREQ?")) == 12_345.7
    assert slave.ask("RSRC?") == "1" and master.ask("RSRC?") == "0"


def test_frequency_goes_through_pymeasures_setter_and_is_read_back(station):
    """PyMeasure's SR860 `frequency` setter ("FREQ %0.6e") sends 1.364664e+04; the instrument
    keeps 6 digits; the front end answers (and keeps) FREQ?'s 13646.6, not the asked 13646.637."""
    fe = station.devices["frontend"]
    handle = station.handles["frontend"]
    sent: list[str] = []
    server = handle.servers[0]
    execute = server.execute
    server.execute = lambda line: (sent.append(line.strip()), execute(line))[1]
    try:
        used = fe.set_frequency_hz(13_646.637)
    finally:
        server.execute = execute
    assert sent[:2] == ["FREQ 1.364664e+04", "FREQ?"]
    assert used == 13_646.6 and fe.frequency_hz == 13_646.6
    assert handle.models[0].freq_int_hz == 13_646.6


def test_limits_are_checked_before_anything_is_sent(station):
    fe = station.devices["frontend"]
    model = station.handles["frontend"].models[0]
    before = model.slvl_v
    with pytest.raises(LimitError, match="amplitude_v"):
        fe.set_drive(1, amplitude_v=2.5, output_on=True)  # the station's max_amplitude_v = 2.0
    with pytest.raises(LimitError, match="frequency_hz"):
        fe.set_drive(1, amplitude_v=0.1, frequency_hz=600_000.0)
    with pytest.raises(LimitError, match="channel"):
        fe.set_drive(3, amplitude_v=0.1)
    assert model.slvl_v == before


def test_tc_is_the_next_step_up_and_amplitudes_are_rms(station):
    fe = station.devices["frontend"]
    fe.lockin_tc_s = 0.005
    assert fe.lockin_tc_s == pytest.approx(0.01)
    fe.set_drive(1, amplitude_v=1.0, phase_deg=0.0, output_on=True)
    model = station.handles["frontend"].models[0]
    assert model.slvl_v == pytest.approx(1.0 / math.sqrt(2.0))
    assert model.phas_deg == pytest.approx(90.0)  # sin(wt + 90) = cos(wt)


def test_refused_setting_is_a_device_error(station):
    fe = station.devices["frontend"]
    fe.devices[2].write("RSRC 3")  # chop reference: not simulated, the instrument refuses
    with pytest.raises(DeviceError, match="refused"):
        fe._check(fe.devices[2])


def test_hang_is_a_lost_link_and_safe_state_reports_it(station):
    fe = station.devices["frontend"]
    fe.set_drive(1, amplitude_v=0.5, output_on=True)
    for dev in fe.devices.values():
        dev.instrument.adapter.connection.timeout = 300  # ms: keep the test short
    station.handles["frontend"].inject("hang")
    with pytest.raises(LinkLostError):
        fe.lockin_all()
    assert fe.safe_state() is False
    station.handles["frontend"].inject("none")
    assert fe.safe_state() is True
    assert all(m.slvl_v <= 1e-9 for m in station.handles["frontend"].models)


def test_skew_between_the_two_instruments_is_measured(station):
    fe = station.devices["frontend"]
    for _ in range(5):
        fe.lockin_all()
    assert fe.skew.count == 5 and 0.0 < fe.skew.mean_s <= fe.skew.max_s < 1.0
    assert fe.skew.virtual_last_s == 0.0  # lockstep: the world waits for both


def test_model_conventions():
    """X + iY = (s + i c)/sqrt(2) exp(-i PHAS): a pure cos(wt) pickoff of 1 V peak reads X = 0,
    Y = 1/sqrt(2) at PHAS 0, and X = 1/sqrt(2) at PHAS 90."""
    m = Sr865Model(1, serial="T")
    m.cs = np.array([1.0, 0.0])
    x, y = m.xy_rms()
    assert (x, y) == pytest.approx((0.0, 1 / math.sqrt(2)))
    m.phas_deg = 90.0
    assert m.xy_rms() == pytest.approx((1 / math.sqrt(2), 0.0), abs=1e-12)
    assert m.execute("PHAS 270;PHAS?") == "-90.0000000"
    assert m.execute("SNAP? X, Y") == m.execute("OUTP? 0") + "," + m.execute("OUTP? 1")
    assert m.execute("FLY 1;*ESR?") == "32"


def test_garbled_answers_are_protocol_errors_and_the_link_stays_in_step(station):
    fe = station.devices["frontend"]
    station.handles["frontend"].inject("garble")
    for read in (fe.lockin_all, lambda: fe.lockin_xy(2), lambda: fe.lockin_tc_s):
        with pytest.raises(ProtocolError):
            read()
    station.handles["frontend"].inject("none")
    assert len(fe.lockin_all()) == 4 and "SR865" in fe.idn


def test_drive_forces_the_resonator_as_the_scpi_front_end_does(station):
    """Truth: drive gain 50 per peak volt; phase 0 puts the force on u2, phase 90 on u3 (the
    SCPI front end's test_safe_state_cuts_the_force_on_the_resonator, same numbers)."""
    world, clock, fe = station.world, station.clock, station.devices["frontend"]
    fe.set_drive(1, amplitude_v=0.3, frequency_hz=F_HZ, output_on=True)
    fe.set_drive(2, amplitude_v=0.2, frequency_hz=F_HZ, phase_deg=90.0, output_on=True)
    clock.sleep(0.01)
    np.testing.assert_allclose(world.total_force, [0.0, 15.0, 10.0, 0.0], atol=1e-9)
    assert world.ref_freq_hz == F_HZ
    assert fe.safe_state() is True
    clock.sleep(0.01)
    assert not world.total_force.any()


def test_lockin_settles_with_its_time_constant_in_virtual_time():
    """Truth: a first-order low pass of a held input, 1 - exp(-t/tc) (OFSL 0, tc 0.1 s), on an
    ideal isotropic resonator with tau 3000 s (a free state holds to 2e-4 over the test)."""
    from bench.clock import SimClock
    from simulators.frontend.sr865_server import serve_sr865_pair
    from simulators.physics.params import ResonatorParams
    from simulators.world import World

    world = World(ResonatorParams(f0_hz=5500.0, tau_s=3000.0), seed=3)
    clock = SimClock(world)
    server = serve_sr865_pair(world)
    fe = Sr865PairFrontEnd(*server.resources, clock=clock).connect()
    try:
        fe.set_frequency_hz(world.ref_freq_hz)
        q = np.array([0.8, -0.4, 0.3, 0.2])
        with world.lock:
            world.resonator.set_state(q)
            for m in server.models:
                m._zi, m.cs = np.zeros((1, 2)), np.zeros(2)
        fe.lockin_tc_s = 0.1
        clock.sleep(0.1)
        np.testing.assert_allclose(fe.lockin_all(), q * (1 - math.exp(-1.0)), rtol=3e-3)
        clock.sleep(0.4)
        np.testing.assert_allclose(fe.lockin_all(), q * (1 - math.exp(-5.0)), rtol=3e-3)
    finally:
        fe.close()
        server.stop()
        clock.close()


def test_mems_sweep_on_the_sr865_station_finds_the_truth(tmp_path):
    """mems-sweep unmodified on sim-mems-sr865 (17 points) with the SR865's 6-digit frequency
    rounding modelled: every measurement with a truth holds it inside its 95 % interval (recording
    the asked frequency put freq_offset_hz at 1.949 and c_m at 24.49, truth 1.938 and 24.36), and
    the sweep records the frequencies the master read back."""
    from bench.engine import Runner
    from bench.recorder import open_run
    from procedures.mems_sweep import MemsSweep

    station = SimStation("sim-mems-sr865", seed=0).open()
    try:
        record = Runner(station, runs_dir=tmp_path / "runs").run(MemsSweep, {"n_points": 17})
        truth = MemsSweep.truth_for(station.truth())
    finally:
        station.close()
    assert record.outcome == "COMPLETE", record.traceback
    m = {r.name: r for r in record.measurements}
    assert m["chosen_model_order"].value == 3.0
    checked = [name for name in truth if name in m and m[name].ci95 is not None]
    assert {"freq_offset_hz", "c_m", "Q", "split_hz", "gamma", "xi"} <= set(checked)
    for name in checked:
        lo, hi = m[name].ci95
        assert lo <= truth[name] <= hi, (name, m[name].value, truth[name], (lo, hi))
    freq_hz = open_run(record.raw_file).table("sweep")["freq_hz"]
    asked = MemsSweep({"n_points": 17}).frequencies()
    assert len(freq_hz) == 34
    np.testing.assert_array_equal(freq_hz[:17], [float(f"{f:.6g}") for f in asked])
    assert np.any(freq_hz[:17] != asked)


@pytest.fixture
def pair():
    """Two simulated SR865s on a MEMS world and a front end not yet connected: (world, clock, server, fe)."""
    from bench.clock import SimClock
    from simulators.frontend.sr865_server import serve_sr865_pair
    from simulators.physics.params import preset
    from simulators.world import World

    world = World(preset("mems"), seed=5)
    clock = SimClock(world)
    server = serve_sr865_pair(world)
    fe = Sr865PairFrontEnd(*server.resources, clock=clock)
    yield world, clock, server, fe
    fe.close()
    server.stop()
    clock.close()


def _transcript(server) -> list[list[str]]:
    """Every message each simulated lock-in receives from now on."""
    sent: list[list[str]] = [[], []]
    for k, s in enumerate(server.servers):
        execute = s.execute
        s.execute = lambda line, execute=execute, k=k: (sent[k].append(line.strip()), execute(line))[1]
    return sent


def test_connect_sets_and_reads_back_what_a_lab_may_have_left(pair):
    """A lab's leftovers (harmonic 2, a 1.5 V DC offset, a sine trigger on 50 ohm, 30 mV range,
    2 mV sensitivity) are all set to the bench's values and read back, in PyMeasure's spellings."""
    world, clock, server, fe = pair
    master, slave = server.models
    for m in server.models:
        m.execute("HARM 2;SOFF 1.5;IRNG 3;SCAL 8")
    slave.execute("RTRG 0;REFZ 0")
    sent = _transcript(server)
    fe.connect()
    for m in server.models:
        assert (m.harm, m.soff_v, m.irng, m.scal, m.ofsl) == (1, 0.0, 0, 0, 0)
    assert (slave.rsrc, slave.rtrg, slave.refz, master.rsrc) == (1, 1, 1, 0)
    for k in (0, 1):
        for command in ("Harm 1", "HARM?", "SOFF 0", "SOFF?", "IRNG 0", "IRNG?", "SCAL 0", "SCAL?"):
            assert command in sent[k], (k, command)
    assert {"RTRG 1", "RTRG?", "REFZ 1", "REFZ?"} <= set(sent[1])


def test_a_setting_that_does_not_read_back_is_refused(pair):
    world, clock, server, fe = pair
    slave = server.models[1]
    execute = slave.execute
    slave.execute = lambda line: execute("RTRG 2" if line.strip() == "RTRG 1" else line)
    server.servers[1].execute = slave.execute
    with pytest.raises(DeviceError, match="RTRG reads back 'NEG'"):
        fe.connect()


def test_safe_state_clears_a_dc_offset_left_on_the_electrodes(station):
    fe = station.devices["frontend"]
    models = station.handles["frontend"].models
    assert float(fe.devices[2].ask("SOFF 1.5;SOFF?")) == 1.5  # answered: the write is done
    assert models[1].soff_v == 1.5
    assert fe.safe_state() is True
    assert [m.soff_v for m in models] == [0.0, 0.0]


def _drive_hard(fe, clock) -> None:
    fe.lockin_tc_s = 0.01
    fe.set_drive(1, amplitude_v=0.888, frequency_hz=13_648.5, phase_deg=46.43, output_on=True)
    clock.sleep(0.5)


def test_an_input_beyond_its_range_is_reported_and_clips(pair):
    """Truth: a 10 mV input range against a pickoff of ~0.9 V peak: LIAS? bit 4 latched, the
    reading is the clipped sine's fundamental (far below the true amplitude); under the fixed
    policy nothing changes, under step-up the range goes up one step (30 mV) and reads back."""
    from drivers.frontend.sr865_pair import Sr865Setup

    world, clock, server, fe = pair
    fe.setup = Sr865Setup(input_range_v=0.01, range_policy="fixed")
    fe.irng = {1: 4, 2: 4}
    fe.connect()
    _drive_hard(fe, clock)
    amp_clipped = math.hypot(*fe.lockin_xy(1))
    over = fe.lockin_overload()
    assert "#1 input beyond its range" in over.conditions and not over.changed
    assert server.models[0].irng == 4
    assert server.models[0].input_peak_v > 0.5 and amp_clipped < 0.05
    fe.setup = Sr865Setup(input_range_v=0.01, range_policy="step-up")
    clock.sleep(0.05)
    over = fe.lockin_overload()
    assert "#1 input range 0.03 V" in over.changed and server.models[0].irng == 3
    clock.sleep(0.05)
    assert fe.lockin_overload(act=False)  # still beyond 30 mV; not acted on
    assert server.models[0].irng == 3


def _sweep_on(tmp_path, extra: str):
    from bench.composition import load_station
    from bench.engine import Runner
    from bench.recorder import open_run
    from procedures.mems_sweep import MemsSweep

    text = (Path(__file__).resolve().parents[1] / "bench" / "stations" / "sim-mems-sr865.toml").read_text()
    path = tmp_path / "station.toml"
    tmp_path.mkdir(parents=True)
    path.write_text(text.replace('max_amplitude_v = 2.0', 'max_amplitude_v = 2.0\n' + extra))
    station = load_station(path, seed=0).open()
    try:
        record = Runner(station, runs_dir=tmp_path / "runs").run(MemsSweep, {"n_points": 17})
        scal = [m.scal for m in station.handles["frontend"].models]
    finally:
        station.close()
    assert record.outcome == "COMPLETE", record.traceback
    return record, open_run(record.raw_file).table("sweep")["freq_hz"], scal


def test_points_taken_in_overload_are_refused_not_fitted(tmp_path):
    """Sensitivity 0.5 V rms, fixed: the points near resonance (X or Y beyond 0.5 V rms) are
    refused and the rest fitted; under step-up the sensitivity goes to 1 V and every point counts."""
    record, freq_hz, scal = _sweep_on(tmp_path / "fixed", 'sensitivity_v = 0.5\nrange_policy = "fixed"')
    refused = 34 - len(freq_hz)
    assert 2 <= refused <= 12 and scal == [1, 1]
    from procedures.mems_sweep import MemsSweep

    asked = [float(f"{f:.6g}") for f in MemsSweep({"n_points": 17}).frequencies()]
    missing = [f for f in asked if np.count_nonzero(freq_hz == f) < 2]
    assert len(missing) >= 1 and all(asked[3] < f < asked[-3] for f in missing), missing
    record, freq_hz, scal = _sweep_on(tmp_path / "step", 'sensitivity_v = 0.5\nrange_policy = "step-up"')
    assert len(freq_hz) == 34 and scal == [0, 1]


@pytest.mark.parametrize("sensitivity_v, scal", [(1.0, 0), (0.5, 1), (5e-5, 13), (5e-6, 16), (2e-7, 20), (1e-9, 27)])
def test_sensitivity_goes_to_its_own_scal_index(pair, sensitivity_v, scal):
    """Truth: the SR86x's SCAL table (0 = 1 V .. 27 = 1 nV); PyMeasure's setter truncates up, so
    a table value off by one ulp would land one step higher."""
    from drivers.frontend.sr865_pair import Sr865Setup

    world, clock, server, _ = pair
    fe = Sr865PairFrontEnd(*server.resources, clock=clock, setup=Sr865Setup(sensitivity_v=sensitivity_v))
    try:
        fe.connect()
        assert [m.scal for m in server.models] == [scal, scal]
    finally:
        fe.close()
