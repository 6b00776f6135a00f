"""Front-end driver against its simulator over pyvisa-py: every command, range errors on both
sides, timeouts and a hung instrument, garbled replies, binary block integrity, lock-in settling."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from bench.clock import SimClock
from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError
from drivers.frontend import FrontEndLimits, ScpiFrontEnd
from drivers.frontend import commands as cmd
from simulators.frontend import serve_frontend
from simulators.physics.carrier import iq_demodulate
from simulators.physics.params import ResonatorParams, preset
from simulators.world import World


def _bench(params: ResonatorParams, *, timeout_s: float = 5.0, limits: FrontEndLimits | None = None, **sim):
    world = World(params, seed=3)
    clock = SimClock(world)
    server = serve_frontend(world, seed=4, **sim)
    fe = ScpiFrontEnd(server.resource_name, clock=clock, limits=limits, timeout_s=timeout_s).connect()
    return world, clock, server, fe


@pytest.fixture
def bench():
    # an ideal (isotropic) resonator with tau 3000 s: a free state stays put to 2e-4 over 0.5 s
    world, clock, server, fe = _bench(ResonatorParams(f0_hz=5500.0, tau_s=3000.0))
    yield world, clock, server, fe
    fe.close()
    server.stop()
    clock.close()


def test_idn_opc_esr_and_cls(bench):
    _, _, _, fe = bench
    assert fe.idn.split(",") == list(cmd.IDN_FIELDS)
    fe.wait_complete()
    assert fe.event_status() == 0
    fe._write("BOGUS:HEAD 1")  # an undefined header: -113 and the command-error bit of *ESR
    assert fe.event_status() == cmd.ESR_CME
    assert fe.check_errors()[0][0] == cmd.UNDEFINED_HEADER
    fe._write("SOUR1:VOLT 99")
    fe._write("*CLS")
    assert fe.event_status() == 0 and fe.check_errors() == []


def test_every_setting_round_trips_exactly(bench):
    _, _, _, fe = bench
    for ch, c in fe.channels.items():
        c.amplitude_v = 0.125 * ch
        c.frequency_hz = 5500.123456789 + ch
        c.phase_deg = -33.3 * ch
        c.bias_v = 12.5 - ch
        c.input_range_v = 0.5 * ch
        c.output_on = True
    for ch, c in fe.channels.items():
        assert (c.amplitude_v, c.frequency_hz, c.phase_deg) == (0.125 * ch, 5500.123456789 + ch, -33.3 * ch)
        assert (c.bias_v, c.input_range_v, c.output_on) == (12.5 - ch, 0.5 * ch, True)
    fe.sample_rate_hz = 250_000.0
    fe.lockin_tc_s = 0.03
    fe.capture_points = 4096
    assert (fe.sample_rate_hz, fe.lockin_tc_s, fe.capture_points) == (250_000.0, 0.03, 4096)
    fe.set_drive(2, amplitude_v=0.5, frequency_hz=6000.0, phase_deg=10.0, output_on=False)
    assert (fe.ch2.amplitude_v, fe.ch2.frequency_hz, fe.ch2.phase_deg, fe.ch2.output_on) == (0.5, 6000.0, 10.0, False)
    fe.set_frequency_hz(5400.0)
    assert fe.ch1.frequency_hz == fe.ch2.frequency_hz == 5400.0
    assert fe.check_errors() == []


def test_reset_restores_defaults(bench):
    _, _, _, fe = bench
    fe.ch1.amplitude_v, fe.ch1.output_on, fe.lockin_tc_s = 1.0, True, 2.0
    fe.reset()
    assert (fe.ch1.amplitude_v, fe.ch1.output_on) == (0.0, False)
    assert fe.ch1.frequency_hz == cmd.RST_FREQUENCY_HZ and fe.lockin_tc_s == cmd.RST_TIME_CONSTANT_S


def test_long_forms_and_default_suffix_are_understood(bench):
    _, _, server, fe = bench
    fe._set("SOURCE:VOLTAGE 0.25")  # no suffix means channel 1
    fe._set("OUTPUT2 ON")
    assert server.model.channels[1].amplitude_v == 0.25 and server.model.channels[2].output_on
    assert fe._query("SOUR:VOLT?") == "0.25"


@pytest.mark.parametrize(
    "action, fragment",
    [
        (lambda fe: setattr(fe.ch1, "amplitude_v", 10.5), "ch1.amplitude_v=10.5 V is above the limit 10 V"),
        (lambda fe: setattr(fe.ch2, "amplitude_v", -0.1), "ch2.amplitude_v=-0.1 V is below the limit 0 V"),
        (lambda fe: setattr(fe.ch1, "frequency_hz", 0.5), "ch1.frequency_hz=0.5 Hz"),
        (lambda fe: setattr(fe.ch1, "phase_deg", float("nan")), "ch1.phase_deg=nan is not a finite number"),
        (lambda fe: setattr(fe.ch2, "bias_v", 51.0), "ch2.bias_v=51 V is above the limit 50 V"),
        (lambda fe: setattr(fe.ch1, "input_range_v", 3.0),
         "ch1.input_range_v=3 is not one of 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0"),
        (lambda fe: setattr(fe.ch1, "output_on", 1), "ch1.output_on=1 is not true or false"),
        (lambda fe: setattr(fe, "sample_rate_hz", 5e6), "sample_rate_hz=5000000 Hz is above the limit"),
        (lambda fe: setattr(fe, "lockin_tc_s", -1.0), "lockin_tc_s=-1 s is below the limit 0 s"),
        (lambda fe: fe.capture(1, 2_000_000), "capture_points=2000000"),
        (lambda fe: fe.capture(1, 10.5), "capture_points=10.5 is not an integer"),
        (lambda fe: fe.lockin_xy(3), "channel=3"),
        (lambda fe: fe.set_drive(1, amplitude_v=0.1, phase_deg=400.0), "phase_deg=400 deg is above the limit"),
    ],
)
def test_driver_refuses_out_of_range_before_sending(bench, action, fragment):
    _, _, server, fe = bench
    before = dict(vars(server.model.channels[1]))
    with pytest.raises(LimitError) as info:
        action(fe)
    assert fragment in str(info.value)
    # nothing reached the instrument: no setting changed, no error queued, no capture armed
    assert dict(vars(server.model.channels[1])) == before
    assert server.model.capture is None and fe.check_errors() == []


def test_bench_limits_are_tighter_than_the_instrument(bench):
    world, clock, server, _ = bench
    limits = FrontEndLimits(max_amplitude_v=1.0, frequency_range_hz=(5000.0, 6000.0), bias_range_v=(-5.0, 5.0))
    fe = ScpiFrontEnd(server.resource_name, clock=clock, limits=limits).connect()
    try:
        fe.ch1.amplitude_v = 1.0
        with pytest.raises(LimitError, match=r"amplitude_v=1.5 V is above the limit 1 V"):
            fe.ch1.amplitude_v = 1.5
        with pytest.raises(LimitError, match="4000"):
            fe.set_frequency_hz(4000.0)
        with pytest.raises(LimitError, match=r"bias_v=6 V is above the limit 5 V"):
            fe.ch2.bias_v = 6.0
    finally:
        fe.close()
    with pytest.raises(LimitError, match="max_amplitude_v=20"):
        FrontEndLimits(max_amplitude_v=20.0)


@pytest.mark.parametrize(
    "command, code",
    [
        ("SOUR1:VOLT 11", cmd.DATA_OUT_OF_RANGE),
        ("SOUR2:FREQ 0", cmd.DATA_OUT_OF_RANGE),
        ("SENS1:RANG 3", cmd.ILLEGAL_PARAMETER_VALUE),
        ("SOUR1:VOLT abc", cmd.DATA_TYPE_ERROR),
        ("SOUR1:VOLT", cmd.MISSING_PARAMETER),
        ("OUTP1 MAYBE", cmd.ILLEGAL_PARAMETER_VALUE),
        ("SOUR3:VOLT 1", cmd.HEADER_SUFFIX_OUT_OF_RANGE),
        ("SOUR1:WOBBLE 1", cmd.UNDEFINED_HEADER),
        ("CAPT:POIN 10.5", cmd.DATA_TYPE_ERROR),
        ("*RST 5", cmd.PARAMETER_NOT_ALLOWED),
    ],
)
def test_instrument_refuses_bad_settings_with_standard_codes(bench, command, code):
    _, _, server, fe = bench
    before = dict(vars(server.model.channels[1]))
    with pytest.raises(DeviceError, match=f"{code} "):
        fe._set(command)  # bypass the driver's validators: the instrument's own check
    assert dict(vars(server.model.channels[1])) == before


def test_error_queue_overflow_reports_minus_350(bench):
    _, _, _, fe = bench
    for _ in range(cmd.ERROR_QUEUE_DEPTH + 5):
        fe._write("NOPE")
    errors = fe.check_errors()
    assert len(errors) == cmd.ERROR_QUEUE_DEPTH and errors[-1][0] == cmd.QUEUE_OVERFLOW
    assert all(code == cmd.UNDEFINED_HEADER for code, _ in errors[:-1])


def test_hung_instrument_times_out_in_wall_time_and_recovers():
    world, clock, server, fe = _bench(preset("hrg", noise_sigma=0.0), timeout_s=0.3)
    try:
        fe.ch1.amplitude_v = 0.2
        server.inject("hang")
        t0 = time.monotonic()
        with pytest.raises(LinkLostError, match="within 0.3 s"):
            fe.lockin_all()
        elapsed = time.monotonic() - t0
        assert 0.25 <= elapsed < 5.0  # the wall-clock transport timeout, generous upper bound
        assert world.t_s == 0.0  # a transport timeout never moves virtual time
        assert fe.safe_state() is False  # cannot be confirmed: the link is lost
        with pytest.raises(LinkLostError, match="call connect"):
            fe.idn  # noqa: B018
        server.inject(None)
        fe.connect()
        assert fe.safe_state() is True
        assert server.model.channels[1].amplitude_v == 0.0
    finally:
        fe.close()
        server.stop()
        clock.close()


def test_garbled_replies_raise_protocol_error(bench):
    _, _, server, fe = bench
    server.inject("garble")
    for read in (lambda: fe.ch1.amplitude_v, fe.lockin_all, lambda: fe.idn, lambda: fe.lockin_xy(2)):
        with pytest.raises(ProtocolError):
            read()
    with pytest.raises(ProtocolError):
        fe.ch1.amplitude_v = 0.5  # the link check before it arrives garbled: nothing is sent
    assert server.model.channels[1].amplitude_v == 0.0
    server.inject("none")
    assert fe.ch1.amplitude_v == 0.0  # the link is confirmed again and back in step
    fe.ch1.amplitude_v = 0.5
    assert fe.ch1.amplitude_v == 0.5
    with pytest.raises(ValueError, match="melt"):
        server.inject("melt")


def test_capture_block_integrity_1e5_samples_with_newline_bytes():
    world, clock, server, fe = _bench(preset("hrg", noise_sigma=0.0), adc_noise_v=0.05)
    try:
        world.resonator.set_state(np.array([0.6, -0.3, 0.2, 0.1]))
        fe.sample_rate_hz = 1e6
        fe.ch1.input_range_v = 1.0
        data = fe.capture(1, 100_000)
        truth = server.last_capture(1)
        assert truth is not None and data.shape == (100_000,)
        assert b"\n" in truth.tobytes()  # the block really carries 0x0A bytes
        np.testing.assert_array_equal(data, truth.astype(np.float64))  # bit for bit
        lsb = 2.0 / 2**16
        np.testing.assert_allclose(data / lsb, np.round(data / lsb), atol=1e-6)  # 16-bit ADC codes
        assert world.t_s >= 0.1  # the capture took 0.1 s of virtual time
        again = fe.fetch_capture(1)
        np.testing.assert_array_equal(again, data)
        assert fe.lockin_all()  # the text stream is still in step after the block
    finally:
        fe.close()
        server.stop()
        clock.close()


def test_capture_demodulates_back_to_the_slow_state_and_clips_to_the_range():
    # a 1 kHz resonator, tau 50 ms, driven at resonance: after 20 tau it sits at its steady state
    params = ResonatorParams(f0_hz=1000.0, tau_s=0.05)
    world, clock, server, fe = _bench(params, adc_noise_v=1e-3)
    try:
        fe.set_drive(1, amplitude_v=0.5, frequency_hz=1000.0, phase_deg=30.0, output_on=True)
        fe.lockin_tc_s = 0.0
        fe.sample_rate_hz = 100_000.0
        clock.sleep(1.0)
        x1, y1, _, _ = fe.lockin_all()
        raw = fe.capture(1, 20_000)
        t = np.arange(raw.size) / 1e5
        _, c, s = iq_demodulate(t, raw, 1000.0, 1e5)
        # steady state: q = u / gamma with u1 = 50 * 0.5 sin 30deg, u2 = 50 * 0.5 cos 30deg, gamma = 40
        assert math.isclose(x1, 25 * 0.5 / 40, rel_tol=1e-6)
        assert math.isclose(y1, 25 * math.sqrt(0.75) / 40, rel_tol=1e-6)
        # demodulation averages 1e3 noise samples (1 mV) per period and a 30 uV LSB: 1e-4 V is 3 sigma
        # the capture starts on the 1 ms world grid, a whole number of 1 kHz periods: t from 0 is in phase
        np.testing.assert_allclose(np.median(c), x1, atol=1e-4)
        np.testing.assert_allclose(np.median(s), y1, atol=1e-4)
        fe.ch1.input_range_v = 0.2  # the 0.36 V carrier clips at the 0.2 V full scale
        raw = fe.capture(1, 2000)
        lsb = 0.4 / 2**16  # codes -32768 .. 32767: the top code is one LSB below full scale
        assert raw.max() == np.float32(0.2 - lsb) and raw.min() == np.float32(-0.2)
    finally:
        fe.close()
        server.stop()
        clock.close()


def test_fetch_without_a_capture_is_a_device_error(bench):
    _, _, _, fe = bench
    with pytest.raises(DeviceError, match=str(cmd.DATA_STALE)):
        fe.fetch_capture(2)


def test_lockin_settles_with_its_time_constant_in_virtual_time(bench):
    world, clock, _, fe = bench
    q = np.array([0.8, -0.4, 0.3, 0.2])
    world.resonator.set_state(q)  # free and isotropic: constant to 2e-4 over the test
    fe.lockin_tc_s = 0.1
    assert fe.lockin_all() == (0.0, 0.0, 0.0, 0.0)
    clock.sleep(0.1)
    # first-order low pass of a held input: 1 - exp(-t/tc) exactly on the sample grid
    np.testing.assert_allclose(fe.lockin_all(), q * (1 - math.exp(-1.0)), rtol=2e-3)
    clock.sleep(0.4)
    np.testing.assert_allclose(fe.lockin_all(), q * (1 - math.exp(-5.0)), rtol=2e-3)
    np.testing.assert_allclose(fe.lockin_xy(2), q[2:] * (1 - math.exp(-5.0)), rtol=2e-3)


def test_safe_state_cuts_the_force_on_the_resonator(bench):
    world, clock, _, fe = bench
    fe.set_drive(1, amplitude_v=0.3, frequency_hz=5500.0, output_on=True)
    fe.set_drive(2, amplitude_v=0.2, frequency_hz=5500.0, phase_deg=90.0, output_on=True)
    clock.sleep(0.01)
    np.testing.assert_allclose(world.total_force, [0.0, 15.0, 10.0, 0.0], atol=1e-12)
    assert world.ref_freq_hz == 5500.0
    assert fe.safe_state() is True
    clock.sleep(0.01)
    assert not world.total_force.any()
    assert [c.output_on for c in fe.channels.values()] == [False, False]
