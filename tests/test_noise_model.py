"""The noise and environment model (simulators.physics.noise, docs/noise_model.md): each process's
Allan deviation against the one derived from its injected spectrum, its own seed, the turn-on bias,
Earth's rate on the axis, the slow drifts, and sim-hrg untouched."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from bench.analysis.allan import allan_deviation
from bench.analysis.slow_model import orbit_elements, state_from_elements
from bench.devices import StationError
from bench.station_config import load_config
from simulators.physics.noise import (
    EARTH_RATE_DPH,
    FLICKER_FLOOR,
    NOISE_PRESETS,
    Environment,
    NoiseParams,
    earth_rate_dph,
    rad_s_to_dph,
)
from simulators.physics.params import preset
from simulators.world import World

TO_DPH = rad_s_to_dph(1.0)


def _adev_ratio(nz: NoiseParams, alpha: int, seeds: int = 8, hours: float = 2.0,
                fs: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean Allan variance of `seeds` synthetic records over the one derived from the spectrum, the
    taus and the relative standard deviation of that mean (chi-squared, Greenhall's edf of alpha)."""
    acc = 0.0
    for seed in range(seeds):
        r = Environment(nz, seed=seed, sample_period_s=1.0 / fs).rate_samples(int(hours * 3600 * fs)) * TO_DPH
        curve = allan_deviation(r, fs)
        acc = acc + curve.adev**2
    true = nz.true_avar(curve.tau_s) * TO_DPH**2
    return acc / seeds / true, curve.tau_s, np.sqrt(2.0 / (seeds * curve.edf(alpha)))


@pytest.mark.parametrize("nz, alpha", [(NoiseParams(arw_deg_rth=0.01), 0), (NoiseParams(rrw_dph_rth=1.5), -2),
                                       (NoiseParams(bias_instability_dph=0.3, flicker_high_hz=2.0), -1)],
                         ids=["arw", "rrw", "flicker"])
def test_each_process_has_the_allan_variance_of_its_spectrum(nz, alpha):
    ratio, tau, rel_sd = _adev_ratio(nz, alpha)
    sel = tau >= 1.0  # below, the 10 Hz sampling of the processes shows
    assert np.all(np.abs(ratio[sel] - 1.0) < 4.0 * rel_sd[sel] + 0.01), dict(
        zip(tau[sel], np.round((ratio[sel] - 1) / rel_sd[sel], 2), strict=True))


def test_the_annex_relations_hold_for_the_injected_spectra():
    tau = np.array([1.0, 10.0, 100.0, 1000.0])
    n = NoiseParams(arw_deg_rth=0.01)  # sigma = N / sqrt(tau h): 0.01 deg/sqrt(h) is 0.6 deg/h at 1 s
    assert np.allclose(np.sqrt(n.true_avar(tau)) * TO_DPH, 0.6 / np.sqrt(tau), rtol=1e-12)
    k = NoiseParams(rrw_dph_rth=1.5)  # sigma = K sqrt(tau / 3), tau in h
    assert np.allclose(np.sqrt(k.true_avar(tau)) * TO_DPH, 1.5 * np.sqrt(tau / 3600 / 3), rtol=1e-12)
    b = NoiseParams(bias_instability_dph=0.3)  # the flat floor 0.664 B, 1 s to ~3 h (band 1 uHz to 20 Hz)
    floor = np.sqrt(b.true_avar(np.geomspace(1.0, 1e4, 12))) * TO_DPH / (FLICKER_FLOOR * 0.3)
    assert np.all(np.abs(floor - 1.0) < 0.01), floor
    assert abs(FLICKER_FLOOR - 0.664) < 5e-4


def test_each_process_draws_from_its_own_seed():
    """Adding a process leaves the others' draws as they were: the white part of white + walk is
    the white-only record (the difference is the walk alone, a smooth curve)."""
    white = Environment(NoiseParams(arw_deg_rth=0.01), seed=5, sample_period_s=0.1).rate_samples(2000)
    both = Environment(NoiseParams(arw_deg_rth=0.01, rrw_dph_rth=1.5), seed=5, sample_period_s=0.1).rate_samples(2000)
    walk = Environment(NoiseParams(rrw_dph_rth=1.5), seed=5, sample_period_s=0.1).rate_samples(2000)
    assert np.allclose(both - white, walk, rtol=0, atol=1e-18)
    other = Environment(NoiseParams(arw_deg_rth=0.01), seed=6, sample_period_s=0.1).rate_samples(2000)
    assert not np.allclose(white, other)


def test_a_turn_on_draws_a_new_bias_with_the_declared_spread():
    nz = NoiseParams(turn_on_bias_mean_dph=1.0, turn_on_bias_sd_dph=2.0)
    env = Environment(nz, seed=1, sample_period_s=1e-3)
    first = env.turn_on_bias_dph
    biases = []
    for _ in range(400):
        env.turn_on()
        biases.append(env.turn_on_bias_dph)
    assert first != biases[0] and env.turn_on_count == 401
    assert abs(np.mean(biases) - 1.0) < 4 * 2.0 / math.sqrt(400)
    chi2 = (len(biases) - 1) * np.var(biases, ddof=1) / 4.0
    assert stats.chi2.ppf(0.001, 399) < chi2 < stats.chi2.ppf(0.999, 399)
    # a turn-on's bias depends only on the seed and its number
    assert Environment(nz, seed=1, sample_period_s=1e-3).turn_on_bias_of(7) == biases[5]


def test_the_drive_coming_on_is_a_turn_on():
    world = World(preset("hrg-wa"), seed=3, noise=NOISE_PRESETS["hrg-wa"])
    env = world.environment
    assert env.turn_on_count == 1
    world.set_force("fpga", np.array([1e-3, 0, 0, 0]))
    world.set_force("fpga", np.array([2e-3, 0, 0, 0]))  # the drive stays on: the same turn-on
    assert env.turn_on_count == 2 and env.turn_on_bias_dph == env.turn_on_bias_of(2)
    world.set_force("fpga", None)
    world.set_force("fpga", np.array([1e-3, 0, 0, 0]))
    assert env.turn_on_count == 3 and world.truth()["turn_on_bias_dph"] == env.turn_on_bias_of(3)


def test_earth_rate_on_the_axis():
    phi = 48.0
    assert earth_rate_dph(phi, 90.0) == pytest.approx(EARTH_RATE_DPH * math.sin(math.radians(phi)), rel=1e-12)
    assert earth_rate_dph(phi, 0.0, 0.0) == pytest.approx(EARTH_RATE_DPH * math.cos(math.radians(phi)), rel=1e-12)
    assert abs(earth_rate_dph(phi, 0.0, 90.0)) < 1e-12
    assert EARTH_RATE_DPH == pytest.approx(15.041, abs=1e-3)


def test_earth_rate_turns_the_free_wave_at_minus_k_omega():
    """The only input Earth's rate: the wave of an ideal resonator turns at -K Omega_E."""
    params = preset("hrg-ideal")
    world = World(params, seed=0, earth_rate_dph=earth_rate_dph(48.0))
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.0))
    world.advance(100.0)
    theta = float(orbit_elements(world.state().reshape(1, 4))["theta_rad"][0])
    expected = -params.bryan_factor * math.radians(earth_rate_dph(48.0) / 3600.0) * 100.0
    assert theta == pytest.approx(expected, rel=1e-9)


def test_slow_drifts_move_the_gains_and_the_damping():
    nz = NoiseParams(gain_x_ppm=300.0, gain_y_ppm=-300.0, gain_x_drift_ppm_h=3600.0, damping_drift_per_s_h=1e-6)
    params = preset("hrg-ideal", delta_inv_tau_per_s=1e-5)
    world = World(params, seed=0, noise=nz)
    world.resonator.set_state(state_from_elements(1.0, 0.0, math.radians(22.5)))  # equal x and y
    world.advance(3600.0)
    block = world.last_block
    gx, gy = world.environment.gains(3600.0 - 0.1)
    assert gx == pytest.approx(1.0 + 3900e-6, rel=1e-6) and gy == pytest.approx(1.0 - 300e-6)
    ratio = block.q_meas[-1, [0, 2]] / block.q_true[-1, [0, 2]]  # cx and cy (sx, sy are 0 on this wave)
    assert ratio[0] == pytest.approx(gx, rel=1e-9) and ratio[1] == pytest.approx(gy, rel=1e-9)
    d = math.hypot(world.resonator._zg[2], world.resonator._zg[3])
    assert d == pytest.approx(1e-5 + 1e-6, rel=1e-4)


def test_a_noise_free_world_is_the_world_before_the_noise_model():
    """sim-hrg has no environment: the same draws, the same truth keys (its results do not change)."""
    world = World(preset("hrg"), seed=0)
    assert world.environment is None
    assert "arw_deg_rth" not in world.truth() and "earth_rate_dph" not in world.truth()


def test_station_keys_for_earth_are_checked(tmp_path):
    cfg = load_config("sim-hrg-wa")
    assert cfg.station["latitude_deg"] == 48.0 and cfg.simulation["earth_rate"] is True
    text = (load_config("sim-hrg-wa").source and open(cfg.source).read()).replace("latitude_deg = 48.0",
                                                                                  "latitude_deg = 100.0")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(StationError, match=r"latitude_deg=100 deg is above the limit 90 deg"):
        load_config(bad)


def test_sim_hrg_wa_truth_has_the_noise_terms_and_earth():
    from bench.composition.sim_station import SimStation

    st = SimStation("sim-hrg-wa")
    try:
        truth = st.truth()
    finally:
        st.clock.close()
    nz = NOISE_PRESETS["hrg-wa"]
    assert truth["arw_deg_rth"] == nz.arw_deg_rth and truth["rrw_dph_rth"] == nz.rrw_dph_rth
    assert truth["earth_rate_dph"] == pytest.approx(EARTH_RATE_DPH * math.sin(math.radians(48.0)))
    assert dataclasses.asdict(nz)["bias_instability_dph"] == truth["bias_instability_dph"]


def test_pickoff_noise_reaches_the_rate_output_as_white_angle_noise():
    """docs/noise_model.md: in whole-angle mode the pickoffs' white noise sigma is a white angle
    noise of the output, sigma(tau) = sqrt(3) Q / tau with Q = sigma / (2 a K sqrt(dec)) for block
    means of dec samples, not an angle random walk (no drift noise, no table here)."""
    from drivers.fpga import protocol as p
    from simulators.fpga.firmware import FpgaFirmware

    params = preset("hrg-wa", noise_sigma=1e-4)
    world = World(params, seed=2)
    world.resonator.set_state(state_from_elements(1.0, 0.0, 0.3))
    fw = FpgaFirmware(world)
    world.attach(fw)
    for name, value in {"REF_FREQ_HZ": params.f0_hz, "AGC_SETPOINT": 1.0, "PRECESSION_RATE_DPS": 0.0}.items():
        fw.write(p.register(name), value)
    fw.write(p.register("CTRL"), p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE)
    world.advance(20.0)
    means: list[np.ndarray] = []
    world.add_listener(lambda w: means.append(w.last_block.q_meas.mean(axis=0)))
    world.advance(600.0)
    q = np.array(means)  # 50 ms blocks of 50 samples
    theta = np.unwrap(4 * orbit_elements(q)["theta_rad"]) / 4
    rate_dph = -np.degrees(np.diff(theta) / 0.05 / params.bryan_factor) * 3600
    curve = allan_deviation(rate_dph, 20.0)
    q_deg = math.degrees(1e-4 / (2 * 1.0 * params.bryan_factor * math.sqrt(50)))
    expected = math.sqrt(3) * q_deg * 3600 / curve.tau_s
    sel = curve.tau_s <= 10.0
    ratio = curve.adev[sel] / expected[sel]
    assert np.all(np.abs(ratio - 1) < 0.15), np.round(ratio, 3)


def test_ftr_pickoff_noise_term_matches_the_delayed_loop_closed_form():
    """Force-to-rebalance, white pickoff noise only (sigma 1e-5): the rate output sampled every
    second block (a 10 Hz frame) is white at |Kp - Ki T/2| sigma_theta sqrt(T) / K, the discrete
    loop with its one-block delay (docs/noise_model.md), within 10 % (400 chunk means: 3.5 % rms);
    the form without the delay is 11 % higher."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from ftr_pickoff_noise import closed_form_dpsh, rate_output, white_level_dpsh

    u, t_s, k = rate_output(1e-5, 2000.0)
    got = white_level_dpsh(u[::2] / k, 2 * t_s, 50)
    want = closed_form_dpsh(1e-5, k, t_s)
    assert got == pytest.approx(want, rel=0.10), (got, want)


WANDER = NoiseParams(angle_wander_deg=0.03, angle_wander_tau_s=300.0)


def _wander_records(nz: NoiseParams, seeds: int, hours: float, fs: float = 1.0) -> np.ndarray:
    return np.array([Environment(nz, seed=s, sample_period_s=1.0 / fs).rate_samples(int(hours * 3600 * fs))
                     for s in range(seeds)]) * TO_DPH


def test_the_angle_wander_is_bounded_and_exactly_the_integrated_rate():
    """The integrated angle the wander adds is phi(t) - phi(0) (no accumulation) to rounding."""
    env = Environment(WANDER, seed=3, sample_period_s=0.5)
    phi0 = env.wander_angle_rad
    rate = env.rate_samples(20000)
    assert math.isclose(np.sum(rate) * 0.5, env.wander_angle_rad - phi0, rel_tol=0, abs_tol=1e-15)
    env2 = Environment(WANDER, seed=3, sample_period_s=0.5)
    blocks = sum(env2.block_rate_rad_s(n) * n * 0.5 for n in (7, 1000, 3, 18990))  # the World's path
    assert math.isclose(blocks, env2.wander_angle_rad - phi0, rel_tol=0, abs_tol=1e-15)


def test_the_angle_wander_has_its_closed_form_allan_variance_and_averages():
    recs = _wander_records(WANDER, seeds=12, hours=3.0)
    ratios = []
    for r in recs:
        curve = allan_deviation(r, 1.0)
        sel = (curve.tau_s >= 4.0) & (curve.tau_s <= 3000.0)  # 1 s sampling to a quarter of the record
        assert sel.sum() >= 8
        ratios.append(curve.adev[sel] ** 2 / (WANDER.true_avar(curve.tau_s[sel]) * TO_DPH**2))
    ratios = np.array(ratios)
    m, se = ratios.mean(axis=0), ratios.std(axis=0, ddof=1) / math.sqrt(len(ratios))
    assert np.all(np.abs(m - 1.0) < 4.0 * se + 0.02), (m, se)
    # the 100 s bias stability: the std of 100 s means, against average_sd_dph(100)
    means = recs[:, : recs.shape[1] // 100 * 100].reshape(len(recs), -1, 100).mean(axis=2)
    bs = float(np.sqrt(np.mean(np.var(means, axis=1, ddof=1))))
    k = means.size - len(recs)
    lo, hi = (bs * math.sqrt(k / stats.chi2.ppf(q, k)) for q in (0.9995, 0.0005))
    assert lo <= float(WANDER.average_sd_dph(100.0)) <= hi, (bs, WANDER.average_sd_dph(100.0))


def test_the_mean_since_start_has_the_closed_form_spread():
    """Across 200 seeded starts the mean after T has the spread sqrt(N^2/T + 2(1-e^(-T/tau_c)) s^2/T^2)."""
    nz = NoiseParams(arw_deg_rth=0.01, angle_wander_deg=0.03, angle_wander_tau_s=300.0)
    t_s = 1800.0
    means = np.array([np.mean(Environment(nz, seed=s, sample_period_s=10.0).rate_samples(180)) * TO_DPH
                      for s in range(200)])
    sd = float(np.sqrt(np.mean(means**2)))
    k = len(means)
    lo, hi = (sd * math.sqrt(k / stats.chi2.ppf(q, k)) for q in (0.9995, 0.0005))
    assert lo <= float(nz.average_sd_dph(t_s)) <= hi, (sd, nz.average_sd_dph(t_s))
    # white part alone, bounded part alone: the closed form's two terms
    assert float(NoiseParams(arw_deg_rth=0.01).average_sd_dph(t_s)) == pytest.approx(0.6 / math.sqrt(t_s), rel=1e-12)
    assert float(WANDER.average_sd_dph(1e9)) == pytest.approx(math.sqrt(2) * 0.03 * 3600 / 1e9, rel=1e-6)


def test_the_angle_wander_is_off_by_default_and_checked():
    assert NoiseParams().angle_wander_deg == 0.0
    a = Environment(NoiseParams(arw_deg_rth=0.01), seed=5, sample_period_s=0.1).rate_samples(500)
    b = Environment(dataclasses.replace(NoiseParams(arw_deg_rth=0.01), angle_wander_tau_s=50.0), seed=5,
                    sample_period_s=0.1).rate_samples(500)
    assert np.array_equal(a, b)  # no wander: no draws, the other processes' streams untouched
    w = Environment(dataclasses.replace(NoiseParams(arw_deg_rth=0.01), angle_wander_deg=0.01), seed=5,
                    sample_period_s=0.1).rate_samples(500)
    assert not np.array_equal(a, w)
    with pytest.raises(ValueError, match="angle_wander_deg"):
        NoiseParams(angle_wander_deg=-0.1)
    with pytest.raises(ValueError, match="angle_wander_tau_s"):
        NoiseParams(angle_wander_tau_s=0.0)


def test_hrg_selfcal_floor_is_the_papers_figures():
    """The preset's floor: 0.52 deg/h at 100 s, and its mean since start after 10 h at 3 sigma under
    0.018 deg/h (docs/selfcal.md, section 1)."""
    nz = NOISE_PRESETS["hrg-selfcal"]
    assert float(nz.average_sd_dph(100.0)) == pytest.approx(0.52, abs=0.002)
    assert 3.0 * float(nz.average_sd_dph(36000.0)) < 0.018


@pytest.mark.parametrize("preset_name", sorted(NOISE_PRESETS))
def test_one_blocks_rate_is_the_bits_of_the_fused_paths_rate_of_one(preset_name):
    """block_rate_rad_s (the per-block path, in scalar arithmetic) against block_rates_rad_s(n, 1)
    on twin environments, with the angle wander on too: the very same bits, block after block, across
    chunk boundaries (seeded runs are bit-identical whichever form a block takes)."""
    nz = dataclasses.replace(NOISE_PRESETS[preset_name], angle_wander_deg=0.03, angle_wander_tau_s=300.0)
    a = Environment(nz, seed=5, sample_period_s=1e-3, earth_rate_dph=10.0)
    b = Environment(nz, seed=5, sample_period_s=1e-3, earth_rate_dph=10.0)
    for n in [50] * 300 + [1, 7, 4999, 20000, 3] * 4:
        got, want = a.block_rate_rad_s(n), b.block_rates_rad_s(n, 1)[0]
        assert type(got) is float and np.float64(got).tobytes() == want.tobytes(), n
    assert a.wander_angle_rad == b.wander_angle_rad
