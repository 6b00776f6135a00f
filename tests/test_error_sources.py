"""The error sources of simulators.physics.errors against their closed forms (docs/error_sources.md),
the defaults that leave them off, and truth that differs from the nominal values a procedure uses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.composition.sim_station import SimStation
from bench.nominal import PRODUCT_NOMINAL
from procedures.cvg_allan import rate_from_stream
from simulators.physics.errors import ERROR_PRESETS, REFERENCE_TEMPERATURE_C, ErrorSources
from simulators.physics.params import PRESETS, ResonatorParams, preset
from simulators.probes import EndStateProbe
from simulators.world import World

IDEAL = preset("hrg-ideal")  # no anisotropy, split or noise: the wave keeps its angle and amplitude
FAST = ResonatorParams(f0_hz=1000.0, tau_s=0.05)  # settles to a forced steady state in a second


def _wave(a: float, theta_deg: float, chi: float = 0.0) -> np.ndarray:
    """(cx, sx, cy, sy) of a standing wave with k = 0 (PHYSICS.md section 1)."""
    c2, s2 = math.cos(2 * math.radians(theta_deg)), math.sin(2 * math.radians(theta_deg))
    return np.array([a * c2 * math.cos(chi), -a * c2 * math.sin(chi), a * s2 * math.cos(chi), -a * s2 * math.sin(chi)])


def _elements(q: np.ndarray) -> tuple[float, float, float]:
    """Amplitude, angle (deg) and phase chi of states (4,) with k ~ 0."""
    cx, sx, cy, sy = q
    r, s = cx * cx + sx * sx - cy * cy - sy * sy, 2 * (cx * cy + sx * sy)
    theta = 0.25 * math.atan2(s, r)
    c2, s2 = math.cos(2 * theta), math.sin(2 * theta)
    chi = math.atan2(-(sx * c2 + sy * s2), cx * c2 + cy * s2)
    return math.sqrt(0.5 * (cx * cx + sx * sx + cy * cy + sy * sy + math.hypot(r, s))), math.degrees(theta), chi


def _measured(errors: ErrorSources, q0: np.ndarray, *, t_s: float = 0.1, params=IDEAL) -> tuple[np.ndarray, np.ndarray]:
    """The last (true, measured) states after t_s of free motion from q0."""
    world = World(params, seed=0, errors=errors)
    world.resonator.set_state(q0)
    world.advance(t_s)
    return world.last_block.q_true[-1], world.last_block.q_meas[-1]


def test_every_source_is_off_by_default():
    """The estimators' presets have none; an all-zero set is no set (the world's old arithmetic)."""
    assert not ErrorSources().active
    assert World(IDEAL, errors=ErrorSources()).errors is None
    assert World(IDEAL).errors is None
    for name in ("hrg", "hrg-wa", "hrg-selfcal", "hrg-ideal", "mems"):
        assert name not in ERROR_PRESETS
    for name in ERROR_PRESETS:  # the realistic units, and the self-calibration gyro with loop gain errors
        assert (name.endswith("-realistic") or name == "hrg-selfcal-gains") and ERROR_PRESETS[name].active


def test_common_mode_pickoff_gain_scales_the_amplitude():
    """A common-mode gain error g: the measured amplitude is (1 + g) a, the angle unchanged."""
    g_ppm = -500.0
    q_true, q_meas = _measured(ErrorSources(pickoff_gain_cm_ppm=g_ppm), _wave(1.0, 20.0))
    a, th, _ = _elements(q_true)
    am, thm, _ = _elements(q_meas)
    assert am == pytest.approx(a * (1 + 1e-6 * g_ppm), rel=1e-12)
    assert thm == pytest.approx(th, abs=1e-9)


def test_differential_pickoff_gain_and_its_drift():
    """X reads (1 + cm + d), Y (1 - ...) each with its drift x hours: after one hour the ratios
    measured / true are 1 + 1e-6 (cm + cm' +- (d + d'))."""
    err = ErrorSources(pickoff_gain_cm_ppm=100.0, pickoff_gain_diff_ppm=750.0,
                       pickoff_gain_cm_drift_ppm_h=20.0, pickoff_gain_diff_drift_ppm_h=-10.0)
    world = World(IDEAL, seed=0, errors=err, sample_period_s=0.01, max_block_s=10.0)
    world.resonator.set_state(_wave(1.0, 22.5))
    world.advance(3600.0)
    world.advance(0.1)  # a block that starts at t = 3600 s
    b = world.last_block
    gx, gy = b.q_meas[-1, 0] / b.q_true[-1, 0], b.q_meas[-1, 2] / b.q_true[-1, 2]
    assert gx == pytest.approx(1 + 1e-6 * (120.0 + 740.0), rel=1e-12)
    assert gy == pytest.approx(1 + 1e-6 * (120.0 - 740.0), rel=1e-12)
    assert world.truth()["pickoff_gain_x"] == pytest.approx(gx, rel=1e-8)


def test_pickoff_misalignment_offsets_the_angle():
    """Both pickoff electrodes turned by e: the wave reads at theta - e (and its amplitude unchanged)."""
    e = 0.1
    q_true, q_meas = _measured(ErrorSources(pickoff_angle_x_deg=e, pickoff_angle_y_deg=e), _wave(1.0, 30.0))
    a, th, _ = _elements(q_true)
    am, thm, _ = _elements(q_meas)
    assert thm == pytest.approx(th - e, abs=1e-9)
    assert am == pytest.approx(a, rel=1e-12)


def test_readout_phase_delay_lags_the_phase():
    """A phase delay p in both chains: chi reads chi - p, amplitude and angle unchanged."""
    p_deg = 2.0
    q_true, q_meas = _measured(ErrorSources(pickoff_phase_x_deg=p_deg, pickoff_phase_y_deg=p_deg),
                               _wave(1.0, 10.0, chi=0.3))
    a, th, chi = _elements(q_true)
    am, thm, chim = _elements(q_meas)
    assert chim == pytest.approx(chi - math.radians(p_deg), abs=1e-12)
    assert (am, thm) == (pytest.approx(a, rel=1e-12), pytest.approx(th, abs=1e-9))


def test_capacitive_nonlinearity_gain_at_the_amplitude():
    """x + e3 x^3 at the fundamental: a wave on one axis reads a (1 + 3/4 e3 a^2)."""
    e3, a0 = 1e-3, 0.8
    q_true, q_meas = _measured(ErrorSources(pickoff_cubic=e3), _wave(a0, 0.0))
    a = _elements(q_true)[0]
    assert a == pytest.approx(a0, rel=1e-3)
    assert _elements(q_meas)[0] == pytest.approx(a * (1 + 0.75 * e3 * a**2), rel=1e-12)


def _forced(errors: ErrorSources | None, u: np.ndarray) -> np.ndarray:
    """The steady state of FAST forced at its natural frequency (0 = A q + u/2: q = u / gamma)."""
    world = World(FAST, seed=0, errors=errors)
    world.set_force("test", u)
    world.advance(2.0)  # 50 time constants
    return world.state()


def test_forcer_gain_and_angle():
    """A force on the X forcer, gain g and electrode angle f: the forced wave is (1 + g) u / gamma
    along f (an ideal forcer: u / gamma along 0)."""
    gamma = 2.0 / FAST.tau_s
    u = np.array([0.5, 0.0, 0.0, 0.0])
    ideal = _forced(None, u)
    assert ideal == pytest.approx(u / gamma, abs=1e-12)
    q = _forced(ErrorSources(forcer_gain_x_ppm=800.0, forcer_angle_x_deg=0.3), u)
    a, th, _ = _elements(q)
    assert a == pytest.approx((1 + 800e-6) * 0.5 / gamma, rel=1e-9)
    assert th == pytest.approx(0.3, abs=1e-7)


def test_frequency_and_q_follow_the_temperature():
    """At T = T_ref + 10 K: the wave's phase turns at -2 pi f0 TCF dT against a reference at f0 and
    its amplitude decays at 1 / tau(T), tau(T) = tau (1 + q_tc dT)."""
    err = ErrorSources(freq_tc_ppm_k=55.0, q_tc_per_k=-3e-3)
    world = World(FAST, seed=0, errors=err, temperature_c=REFERENCE_TEMPERATURE_C + 10.0)
    world.resonator.set_state(_wave(1.0, 0.0))
    world.advance(0.1)
    q = world.last_block.q_true
    t = world.last_block.t_s
    phase = np.unwrap(np.arctan2(-q[:, 1], q[:, 0]))  # chi of a wave on X
    assert np.polyfit(t, phase, 1)[0] == pytest.approx(2 * math.pi * 1000.0 * 55e-6 * 10.0, rel=1e-9)
    decay = np.polyfit(t, np.log(np.hypot(q[:, 0], q[:, 1])), 1)[0]
    assert -1.0 / decay == pytest.approx(FAST.tau_s * (1 - 3e-3 * 10.0), rel=1e-9)
    truth = world.truth()
    assert truth["temperature_c"] == REFERENCE_TEMPERATURE_C + 10.0
    assert truth["f0_at_temperature_hz"] == pytest.approx(1000.0 * (1 + 55e-6 * 10.0))
    assert truth["q_factor_at_temperature"] == pytest.approx(FAST.q_factor * 0.97 * (1 + 55e-6 * 10.0))
    # the resonator's keys are the unit's at its temperature now, the reference's kept as *_ref
    assert truth["tau_s"] == pytest.approx(FAST.tau_s * 0.97) and truth["tau_s_ref"] == FAST.tau_s
    assert truth["freq_offset_hz"] == pytest.approx(1000.0 * 55e-6 * 10.0)
    assert truth["c_m"] == pytest.approx(4 * math.pi * 1000.0 * 55e-6 * 10.0)


def test_set_temperature_is_an_input():
    world = World(FAST, seed=0, errors=ErrorSources(freq_tc_ppm_k=-30.0))
    assert world.truth()["temperature_c"] == REFERENCE_TEMPERATURE_C
    world.set_temperature(40.0)
    assert world.truth()["temperature_c"] == 40.0
    with pytest.raises(ValueError):
        world.set_temperature(float("nan"))


def test_mistuned_bryan_factor_scales_the_whole_angle_rate():
    """The realistic HRG's K (0.2745) against the design's 0.277: a whole-angle rate worked out with
    the nominal K reads Omega K_true / K_nominal (0.9 % low)."""
    unit = PRESETS["hrg-realistic"].with_(delta_inv_tau_per_s=0.0, split_hz=0.0, noise_sigma=0.0)
    k_nom = PRODUCT_NOMINAL["hrg"]["bryan_factor"]
    assert unit.bryan_factor != k_nom
    world = World(unit, seed=0)
    world.resonator.set_state(_wave(1.0, 0.0))
    world.case_rate_dps = 10.0
    world.advance(1.0)
    b = world.last_block
    theta = np.degrees(np.unwrap(4 * np.radians([_elements(q)[1] for q in b.q_true])) / 4)
    _, rate_dph = rate_from_stream(b.t_s, theta, k_nom)
    assert np.mean(rate_dph) / 3600.0 == pytest.approx(10.0 * unit.bryan_factor / k_nom, rel=1e-9)


def test_realistic_stations_differ_from_their_nominal():
    """The station gives the procedures the design's K and f0; the unit's truth differs by the
    lot's spread; the default stations' truth equals their nominal values."""
    for name, kind in (("sim-hrg-realistic", "hrg"), ("sim-mems-realistic", "mems-ring")):
        st = SimStation(name)
        nominal, truth = st.nominal, st.truth()
        assert st.world.errors is not None
        assert truth["bryan_factor"] / nominal["bryan_factor"] == pytest.approx(0.99 if kind == "hrg" else 0.98,
                                                                                 abs=0.002)
        assert 2.5 < truth["f0_hz"] - nominal["f0_hz"] < 3.5
        assert truth["err_pickoff_gain_cm_ppm"] == ERROR_PRESETS[st.config.simulation["preset"]].pickoff_gain_cm_ppm
    for name in ("sim-hrg", "sim-mems", "sim-hrg-selfcal"):
        st = SimStation(name)
        assert st.world.errors is None
        assert st.truth()["bryan_factor"] == st.nominal["bryan_factor"]
        assert st.truth()["f0_hz"] == pytest.approx(st.nominal["f0_hz"], rel=1e-15)


@pytest.mark.parametrize("errors, depth", [
    (ErrorSources(pickoff_gain_diff_ppm=750.0), 2 * 750e-6),  # E_m = E (1 + 2 d cos 4 theta)
    (ErrorSources(pickoff_angle_x_deg=0.05, pickoff_angle_y_deg=-0.08), 2 * math.radians(0.13)),  # 2 (e_x - e_y)
])
def test_energy_modulation_reads_as_damping_anisotropy(errors, depth):
    """A pickoff error that modulates the measured energy by m cos 4(theta - psi) is, to a free-decay
    fit of a wave turning at theta' = -K Omega, a damping anisotropy D = 4 m K Omega (the log of
    E_m gains m cos 4 theta, the model's D integral D sin 4 theta / (4 theta')): docs/sensitivity.md's
    largest biases, in closed form, on a resonator with no anisotropy at all."""
    from bench.analysis.damping import fit_free_decay_q

    unit = IDEAL.with_(noise_sigma=1e-6)
    world = World(unit, seed=0, errors=errors, sample_period_s=0.01, max_block_s=1.0)
    world.resonator.set_state(_wave(1.0, 0.0))
    world.case_rate_dps = 20.0
    t, q = [], []
    for _ in range(60):
        world.advance(1.0)
        t.append(world.last_block.t_s)
        q.append(world.last_block.q_meas)
    fit = fit_free_decay_q(np.concatenate(t), np.concatenate(q))
    expected = 4 * depth * unit.bryan_factor * math.radians(20.0)
    assert fit.delta_inv_tau_per_s == pytest.approx(expected, rel=0.02)


def _whole_angle_drift_wave_dph(params, errors: ErrorSources, rate_dps: float):
    """The simulated FPGA's whole-angle loops (AGC, PLL, quadrature) on the World directly at a
    commanded precession; the true wave's drift against its angle (deg/h of wave angle): mean and
    4, 8 theta harmonics (as tests/test_wa_drift.py, not referred to the output)."""
    from bench.analysis.damping import fit_drift_harmonics
    from bench.analysis.slow_model import orbit_elements, state_from_elements
    from drivers.fpga import protocol as p
    from procedures.hrg_damping import block_drift
    from simulators.fpga.firmware import FpgaFirmware

    world = World(params, seed=1, errors=errors)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in (("REF_FREQ_HZ", params.f0_hz), ("AGC_SETPOINT", 1.0), ("PRECESSION_RATE_DPS", rate_dps)):
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.advance(15.0)
    wave = EndStateProbe()
    world.attach(wave)
    world.advance(45.0)  # 180 deg of wave angle at 4 deg/s: whole periods of 4 theta
    theta = np.unwrap(4.0 * orbit_elements(np.array(wave.q))["theta_rad"]) / 4.0
    mids, rate = block_drift(np.array(wave.t_s), theta, 0.5)
    return fit_drift_harmonics(mids, rate - math.radians(rate_dps), orders=(4, 8)).scaled(math.degrees(1.0) * 3600)


def test_forcer_gains_scale_the_commanded_precession():
    """Forcer gains g_x, g_y on the precession force along the wave: the wave turns at
    Omega (1 + (g_x + g_y)/2 - (g_x - g_y)/2 cos 4 theta): a mean drift Omega (g_x + g_y)/2 and a
    4 theta one of amplitude Omega |g_x - g_y| / 2 (docs/error_sources.md)."""
    fit = _whole_angle_drift_wave_dph(IDEAL, ErrorSources(forcer_gain_x_ppm=800.0, forcer_gain_y_ppm=-400.0), 4.0)
    omega_dph = 4.0 * 3600.0
    assert fit.mean == pytest.approx(omega_dph * 200e-6, rel=0.01)
    assert fit.harmonics[4].amplitude == pytest.approx(omega_dph * 600e-6, rel=0.01)


def test_readout_phase_delay_turns_the_split_cancellation_into_drift():
    """A phase delay p read by the loops turns their forces by p in phase: the quadrature force
    that cancels the split's pumping (2 a (Dw/2) at 4 theta) leaks into the precession by sin p, a
    4 theta drift of Dw sin p / 4 rad/s of wave angle (204 deg/h output-referred at 5 mHz and 2 deg:
    docs/sensitivity.md's largest whole-angle term)."""
    params = IDEAL.with_(split_hz=0.005, theta_w_deg=10.0)
    fit = _whole_angle_drift_wave_dph(params, ErrorSources(pickoff_phase_x_deg=2.0, pickoff_phase_y_deg=2.0), 4.0)
    dw = 2 * math.pi * 0.005
    assert fit.harmonics[4].amplitude == pytest.approx(math.degrees(dw * math.sin(math.radians(2.0)) / 4) * 3600,
                                                       rel=0.03)


def test_a_rig_of_several_gyros_carries_the_error_sources():
    """Several gyros on one table (simulators.rig): each slot's world has the station's error sources."""
    from simulators.rig import Rig

    rig = Rig([IDEAL, IDEAL], seeds=[1, 2], errors=ERROR_PRESETS["hrg-realistic"])
    assert all(w.errors is ERROR_PRESETS["hrg-realistic"] for w in rig.worlds)
    assert all(w.errors is None for w in Rig([IDEAL], seeds=[1]).worlds)


def _measure_numpy(e: ErrorSources, q: np.ndarray, t_s: float, temperature_c: float, stress_c: float) -> np.ndarray:
    """ErrorSources.measure as it was written in numpy before its compiled kernel (the reference)."""
    cx, sx, cy, sy = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    ax, ay = 2.0 * math.radians(e.pickoff_angle_x_deg), 2.0 * math.radians(e.pickoff_angle_y_deg)
    if ax or ay:
        cx, cy = math.cos(ax) * cx + math.sin(ax) * cy, -math.sin(ay) * cx + math.cos(ay) * cy
        sx, sy = math.cos(ax) * sx + math.sin(ax) * sy, -math.sin(ay) * sx + math.cos(ay) * sy
    if e.pickoff_cubic:
        fx = 1.0 + 0.75 * e.pickoff_cubic * (cx * cx + sx * sx)
        fy = 1.0 + 0.75 * e.pickoff_cubic * (cy * cy + sy * sy)
        cx, sx, cy, sy = cx * fx, sx * fx, cy * fy, sy * fy
    px, py = math.radians(e.pickoff_phase_x_deg), math.radians(e.pickoff_phase_y_deg)
    if px:
        cx, sx = cx * math.cos(px) - sx * math.sin(px), cx * math.sin(px) + sx * math.cos(px)
    if py:
        cy, sy = cy * math.cos(py) - sy * math.sin(py), cy * math.sin(py) + sy * math.cos(py)
    gx, gy = e.pickoff_gains(t_s, temperature_c, stress_c)
    return np.stack([gx * cx, gx * sx, gy * cy, gy * sy], axis=1)


def _force_numpy(e: ErrorSources, u: np.ndarray) -> np.ndarray:
    """ErrorSources.force as it was written before its constants were worked out once (the reference)."""
    gx, gy = 1.0 + 1e-6 * e.forcer_gain_x_ppm, 1.0 + 1e-6 * e.forcer_gain_y_ppm
    ax, ay = 2.0 * math.radians(e.forcer_angle_x_deg), 2.0 * math.radians(e.forcer_angle_y_deg)
    fx1, fx2, fy1, fy2 = gx * u[0], gx * u[1], gy * u[2], gy * u[3]
    c_x, s_x, c_y, s_y = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)
    return np.array([c_x * fx1 - s_y * fy1, c_x * fx2 - s_y * fy2, s_x * fx1 + c_y * fy1, s_x * fx2 + c_y * fy2])


@pytest.mark.parametrize("sources", [*ERROR_PRESETS.values(), ErrorSources(pickoff_angle_y_deg=0.3),
                                     ErrorSources(pickoff_phase_y_deg=3.0, pickoff_cubic=0.02),
                                     ErrorSources(pickoff_gain_cm_ppm=5.0)])  # fmt: skip
def test_the_compiled_pickoff_chains_give_the_numpy_forms_numbers_bit_for_bit(sources):
    """The pickoff kernel (simulators.physics.errors_kernel) and the forcers' constants worked out
    once: every value the very bits of the numpy form's (seeded runs stay bit-identical)."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.normal(0.0, rng.uniform(0.01, 3.0), (int(rng.integers(1, 300)), 4))
        t_s, temp_c = rng.uniform(0.0, 1e5), rng.uniform(-40.0, 85.0)
        got, want = sources.measure(q, t_s, temp_c, temp_c - 0.3), _measure_numpy(sources, q, t_s, temp_c, temp_c - 0.3)
        assert got.tobytes() == want.tobytes()
        u = rng.normal(0.0, 1.0, 4)
        assert sources.force(u).tobytes() == _force_numpy(sources, u).tobytes()
