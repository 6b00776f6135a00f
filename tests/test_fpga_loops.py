"""The simulated FPGA's loops, driven end to end through FpgaLink over a loopback socket and
checked against the World's truth (the HRG preset: f0 5500 Hz, tau 300 s)."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only cost here

import math

import numpy as np
import pytest

from bench.analysis.slow_model import orbit_elements, state_from_elements
from bench.clock import SimClock
from drivers.fpga import FpgaLink
from simulators.fpga import serve_fpga
from simulators.physics.params import preset
from simulators.world import World

LOOP_PERIOD_S = 0.05  # the loops' poles are near 1-6 rad/s: 50 ms blocks keep them well sampled


class Tap:
    """Records the world's true states per sample index (ground truth, never over the link)."""

    def __init__(self) -> None:
        self.q_true: dict[int, np.ndarray] = {}

    def before_block(self, *args) -> None:
        pass

    def after_block(self, world, block) -> None:
        self.q_true.update(zip(block.index.tolist(), block.q_true, strict=True))


def _bench(params, *, state=None):
    world = World(params, seed=3)
    if state is not None:
        world.resonator.set_state(state)
    clock = SimClock(world)
    server = serve_fpga(world, seed=4)
    link = FpgaLink(server.url, clock=clock, timeout_s=2.0).connect()
    link.write_register("LOOP_PERIOD_S", LOOP_PERIOD_S)
    blocks: list[np.ndarray] = []
    link.subscribe(blocks.append)
    return world, clock, server, link, blocks


def _close(clock, server, link) -> None:
    link.close()
    server.stop()
    clock.close()


def _rows(link, clock, blocks, t0_s: float = -1.0) -> np.ndarray:
    link.wait_for_sample(clock.now(), timeout_wall_s=10.0)
    rows = np.vstack(blocks)
    return rows[rows[:, 1] > t0_s]


def test_agc_reaches_and_holds_setpoint_and_stream_matches_truth():
    """From rest the AGC brings the HRG to a = 0.8 and holds it: over the last 10 s the mean
    amplitude is within 0.1 % of the setpoint (the PI's integral leaves no static error; the
    pickoff noise 1e-4 over 200 frames averages to ~1e-5) and no sample is off by 1 %.  The
    streamed E and theta agree with the world's true state to the noise (5 sigma)."""
    world, clock, server, link, blocks = _bench(preset("hrg"))
    tap = Tap()
    world.attach(tap)
    try:
        link.set_agc(True, 0.8)
        link.set_quadrature_loop(True)
        link.set_drive_enabled(True)
        link.start_stream(50)
        clock.sleep(30.0)
        rows = _rows(link, clock, blocks, t0_s=20.0)
        a = orbit_elements(rows[:, 2:6])["a"]
        assert abs(a.mean() - 0.8) < 0.8e-3
        assert np.max(np.abs(a - 0.8)) < 0.008
        assert link.read_register("STATUS") & 0x02  # AGC settled bit
        truth = orbit_elements(np.array([tap.q_true[int(i)] for i in rows[:, 0]]))
        meas = orbit_elements(rows[:, 2:6])
        sigma = world.params.noise_sigma
        np.testing.assert_allclose(meas["E"], truth["E"], atol=5 * 2 * sigma * math.sqrt(truth["E"].max()) + 2e-6)
        dtheta = (meas["theta_rad"] - truth["theta_rad"] + math.pi / 4) % (math.pi / 2) - math.pi / 4
        assert np.max(np.abs(dtheta)) < 5 * sigma / 0.8
        assert np.all(rows[:, 6] > 0)  # amp_ctrl: the AGC force is positive, making up the damping
    finally:
        _close(clock, server, link)


def test_cut_drive_gives_free_decay_at_tau():
    """After cut drive, ln E falls at 2/tau: the fitted tau over 40 s of decay is the preset's
    300 s within 1 % (noise alone gives ~0.05 %).  D = 0 here so the decay is the same at every
    wave angle (the anisotropic case is the damping procedure's business)."""
    params = preset("hrg", delta_inv_tau_per_s=0.0)
    world, clock, server, link, blocks = _bench(params, state=state_from_elements(1.0, 0.0, 0.3))
    try:
        link.set_agc(True, 1.0)
        link.set_drive_enabled(True)
        clock.sleep(2.0)
        link.start_stream(20)
        link.set_drive_enabled(False)
        t_cut = clock.now()
        clock.sleep(40.0)
        rows = _rows(link, clock, blocks, t0_s=t_cut + 2 * LOOP_PERIOD_S)
        e = orbit_elements(rows[:, 2:6])["E"]
        slope = np.polyfit(rows[:, 1], np.log(e), 1)[0]
        tau_s = -2.0 / slope
        assert tau_s == pytest.approx(params.tau_s, rel=0.01)
        assert np.all(rows[:, 6] == 0) and np.all(world.total_force == 0)
    finally:
        _close(clock, server, link)


def test_pll_finds_the_resonance():
    """Started 0.3 Hz high, the PLL settles the reference on the resonance: the HRG's natural
    frequency is f0 within half the 5 mHz split, so within 3 mHz of 5500 Hz after 20 s."""
    params = preset("hrg")
    world, clock, server, link, blocks = _bench(params, state=state_from_elements(1.0, 0.0, 0.2))
    try:
        link.set_agc(True, 1.0)
        link.set_drive_enabled(True)
        link.set_pll(True, ref_freq_hz=params.f0_hz + 0.3)
        clock.sleep(20.0)
        f_hz = link.read_register("PLL_FREQ_HZ")
        assert abs(f_hz - params.f0_hz) < 3e-3
        assert world.ref_freq_hz == pytest.approx(f_hz, abs=1e-3)  # held from one block before
        assert link.read_register("STATUS") & 0x04  # locked
    finally:
        _close(clock, server, link)


def test_whole_angle_precession_and_frequency_modulation():
    """A 0.5 deg/s precession command turns the streamed wave angle at 0.5 deg/s within 2 %
    (the damping drift D/4 is 0.0023 deg/s, 0.5 % of it); the reference carries the commanded
    FM (0.2 Hz at 0.5 Hz) seen in freq_ctrl (PLL off: with it on, the PLL follows part of it)."""
    world, clock, server, link, blocks = _bench(preset("hrg"), state=state_from_elements(1.0, 0.0, 0.0))
    try:
        link.set_agc(True, 1.0)
        link.set_quadrature_loop(True)
        link.set_whole_angle(True, 0.5, fm_amplitude_hz=0.2, fm_rate_hz=0.5)
        link.set_drive_enabled(True)
        link.start_stream(10)
        clock.sleep(40.0)
        rows = _rows(link, clock, blocks, t0_s=5.0)
        theta = np.unwrap(4 * orbit_elements(rows[:, 2:6])["theta_rad"]) / 4
        rate_dps = math.degrees(np.polyfit(rows[:, 1], theta, 1)[0])
        assert rate_dps == pytest.approx(0.5, rel=0.02)
        fm = rows[:, 7]
        assert np.max(np.abs(fm)) == pytest.approx(0.2, abs=0.02)
        # the dominant modulation frequency of freq_ctrl is the commanded 0.5 Hz (0.025 Hz bins)
        spec = np.abs(np.fft.rfft(fm - fm.mean()))
        freqs = np.fft.rfftfreq(len(fm), d=rows[1, 1] - rows[0, 1])
        assert freqs[np.argmax(spec)] == pytest.approx(0.5, abs=0.03)
    finally:
        _close(clock, server, link)


def _drift_rate_dps(comp: bool) -> float:
    params = preset("hrg")
    theta0 = math.radians(params.theta_tau_deg + 22.5)  # where the drift is largest
    world, clock, server, link, blocks = _bench(params, state=state_from_elements(1.0, 0.0, theta0))
    try:
        link.set_agc(True, 1.0)
        link.set_quadrature_loop(True)
        link.set_whole_angle(True, 0.0)
        link.set_drift_compensation(comp, params.delta_inv_tau_per_s, params.theta_tau_deg)
        link.set_drive_enabled(True)
        link.start_stream(100)
        clock.sleep(60.0)
        rows = _rows(link, clock, blocks)
        theta = orbit_elements(rows[:, 2:6])["theta_rad"]
        return math.degrees(np.polyfit(rows[:, 1], theta, 1)[0])
    finally:
        _close(clock, server, link)


def test_drift_compensation_cancels_the_damping_drift():
    """In whole-angle mode with no command, the wave drifts at (D/4) sin 4(theta - theta_tau)
    (PHYSICS.md section 2): at 22.5 deg off the damping axis that is D/4 = 0.00229 deg/s (10 %
    tolerance: noise of the 60 s slope ~1e-5 deg/s).  With the identified (D, theta_tau) written
    to the FPGA the drift falls under 5 % of that.  The 5 mHz split stays: the quadrature loop
    cancels its pumping along the wave's predicted phase, so it adds no drift of its own (it used
    to, through the phase lag of the quadrature force, and had to be zeroed here)."""
    d_dps = math.degrees(preset("hrg").delta_inv_tau_per_s / 4)
    assert _drift_rate_dps(False) == pytest.approx(d_dps, rel=0.1)
    assert abs(_drift_rate_dps(True)) < 0.05 * d_dps


def test_force_to_rebalance_holds_the_wave_and_its_rate_output_is_g_k_omega():
    """Force-to-rebalance at 0 and +-10 deg/s of case rate: the wave stays at the held angle
    (within 0.01 deg, noise ~1e-3 deg), and the rate output averages G K (Omega - (D/4K) sin
    4 (theta_h - theta_tau)) (docs/fpga_link.md "Output modes"): G = 3.6, K = 0.277, the drift term
    29.33 deg/h at theta_h = 0.  Tolerance 2e-4 deg/s: the 8 s mean's noise is ~2e-5 deg/s and the
    split's residual quadrature drift a few 1e-5.  Each step's first 17 s are left out: from this
    cold start the quadrature PI alone takes the split's pumping at the held angle (time constant
    2 s; the split observer does not learn in force-to-rebalance, docs/fpga_link.md), 7 s left
    2.7e-4 deg/s."""
    params = preset("hrg")
    world, clock, server, link, blocks = _bench(params, state=state_from_elements(1.0, 0.0, 0.0))
    try:
        link.set_agc(True, 1.0)
        link.set_quadrature_loop(True)
        link.set_pll(True, params.f0_hz)
        link.set_output_mode("force-to-rebalance", ftr_angle_deg=0.0, ftr_gain=3.6)
        assert link.output_mode() == "force-to-rebalance"
        link.set_drive_enabled(True)
        link.start_stream(10)
        k = params.bryan_factor
        d_term = params.delta_inv_tau_per_s / (4 * k) * math.sin(4 * math.radians(0.0 - params.theta_tau_deg))
        for rate in (0.0, 10.0, -10.0):
            world.case_rate_dps = rate
            t0 = clock.now()
            clock.sleep(25.0)
            rows = _rows(link, clock, blocks, t0_s=t0 + 17.0)
            assert abs(np.mean(rows[:, 10]) % 90.0 - 0.0) < 0.01 or abs(np.mean(rows[:, 10]) % 90.0 - 90.0) < 0.01
            want = 3.6 * k * (rate - math.degrees(d_term))
            assert np.mean(rows[:, 11]) == pytest.approx(want, abs=2e-4)
    finally:
        _close(clock, server, link)


def test_whole_angle_output_is_the_unwrapped_wave_angle():
    """Whole-angle at 20 deg/s of case rate: angle_out_deg turns at -K Omega (-5.54 deg/s) through
    several quarter turns without a jump (unwrapped), and agrees with the angle of the streamed
    pickoffs; the rate output is 0 outside force-to-rebalance."""
    params = preset("hrg")
    world, clock, server, link, blocks = _bench(params, state=state_from_elements(1.0, 0.0, 0.0))
    try:
        link.set_agc(True, 1.0)
        link.set_quadrature_loop(True)
        link.set_drive_enabled(True)
        link.start_stream(10)
        world.case_rate_dps = 20.0
        clock.sleep(40.0)
        rows = _rows(link, clock, blocks, t0_s=10.0)
        angle = rows[:, 10]
        assert np.max(np.abs(np.diff(angle))) < 0.2  # 0.055 deg a frame, no 90-deg jumps
        assert angle[0] - angle[-1] > 90.0
        slope = np.polyfit(rows[:, 1], angle, 1)[0]
        assert slope == pytest.approx(-params.bryan_factor * 20.0, rel=2e-3)
        wrapped = np.degrees(orbit_elements(rows[:, 2:6])["theta_rad"])
        # the same angle, up to the float32 rounding of the streamed pickoffs (~1e-5 deg)
        assert np.allclose((angle - wrapped + 45.0) % 90.0 - 45.0, 0.0, atol=1e-4)
        assert np.all(rows[:, 11] == 0.0)
    finally:
        _close(clock, server, link)
