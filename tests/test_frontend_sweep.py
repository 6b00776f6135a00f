"""A forced-response sweep of the MEMS ring driven through the front end in lockstep: each step
sets the drive frequency, waits in virtual time on the bench clock, reads the lock-in; the
readings must match the averaged model's forced steady state (Resonator.steady_state)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.analysis.slow_model import linear_matrix
from bench.clock import SimClock
from drivers.frontend import ScpiFrontEnd
from simulators.frontend import serve_frontend
from simulators.physics.params import preset
from simulators.world import World

DRIVE_GAIN = 50.0  # serve_frontend's model units per volt
AMPLITUDE_V, PHASE_DEG = 0.4, 20.0


@pytest.fixture
def sweep_bench(request):
    world = World(request.param, seed=5)
    clock = SimClock(world)
    server = serve_frontend(world, drive_gain=DRIVE_GAIN, seed=6)
    fe = ScpiFrontEnd(server.resource_name, clock=clock, timeout_s=5.0).connect()
    yield world, clock, fe
    fe.close()
    server.stop()
    clock.close()


def _force(amplitude_v: float) -> np.ndarray:
    phi = math.radians(PHASE_DEG)
    return DRIVE_GAIN * amplitude_v * np.array([math.sin(phi), math.cos(phi), 0.0, 0.0])


def _slowest_decay_per_s(world: World, ref_hz: float) -> float:
    """Smallest decay rate of the linear slow model (dq/dt = A q + u/2) at this detuning."""
    a = linear_matrix(world.resonator.coeffs.zg(0.0), world.resonator.detuning_rad_s(ref_hz))
    return float(-np.max(np.linalg.eigvals(a).real))


LINEAR_MEMS = preset("mems", xi_per_s=0.0, noise_sigma=0.0)


@pytest.mark.parametrize("sweep_bench", [LINEAR_MEMS], indirect=True)
def test_sweep_in_lockstep_matches_the_linear_steady_state(sweep_bench):
    world, clock, fe = sweep_bench
    tau_s = world.params.tau_s  # 46.5 ms
    f0 = world.params.f0_hz
    freqs = f0 + np.linspace(-12.0, 12.0, 13)
    fe.lockin_tc_s = 0.001
    fe.set_drive(1, amplitude_v=AMPLITUDE_V, phase_deg=PHASE_DEG, frequency_hz=float(freqs[0]), output_on=True)
    clock.sleep(20 * tau_s)  # settle from rest once
    t_start = world.t_s
    wait_s = 5 * tau_s
    readings, expected = [], []
    for f in freqs:
        fe.set_frequency_hz(float(f))
        clock.sleep(wait_s)
        readings.append(fe.lockin_all())
        expected.append(world.resonator.steady_state(force=_force(AMPLITUDE_V), ref_freq_hz=float(f)))
    readings, expected = np.array(readings), np.array(expected)
    # lockstep: virtual time moved by exactly the waits, to the 1 ms sample grid
    assert abs(world.t_s - t_start - len(freqs) * wait_s) <= world.sample_period_s
    # after 5 tau the previous step's transient is down to exp(-rate_min * wait) of its size; a
    # step changes the response by at most the peak response, so that (x2, for the lock-in lag) bounds the error
    rate_min = min(_slowest_decay_per_s(world, float(f)) for f in freqs)
    peak = np.max(np.linalg.norm(expected, axis=1))
    tol = 2.0 * math.exp(-rate_min * wait_s) * peak
    assert tol < 0.03 * peak
    np.testing.assert_allclose(readings, expected, atol=tol)
    # the response peaks inside the sweep, near the mistuned natural frequency (f0 + c_m / (4 pi))
    f_peak = freqs[np.argmax(np.linalg.norm(readings, axis=1))]
    assert abs(f_peak - (f0 + world.params.freq_offset_hz)) < 6.0


@pytest.mark.parametrize("sweep_bench", [LINEAR_MEMS], indirect=True)
def test_a_long_wait_reaches_the_steady_state_to_1e_6(sweep_bench):
    world, clock, fe = sweep_bench
    f = world.params.f0_hz + 2.0
    fe.lockin_tc_s = 0.001
    fe.set_drive(1, amplitude_v=AMPLITUDE_V, phase_deg=PHASE_DEG, frequency_hz=f, output_on=True)
    clock.sleep(40 * world.params.tau_s)  # transient exp(-40 x 0.93) ~ 1e-16, lock-in lag nil
    expected = world.resonator.steady_state(force=_force(AMPLITUDE_V), ref_freq_hz=f)
    np.testing.assert_allclose(fe.lockin_all(), expected, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("sweep_bench", [preset("mems", noise_sigma=0.0)], indirect=True)
def test_nonlinear_mems_preset_at_small_drive_is_close_to_linear(sweep_bench):
    # the cubic term shifts the response by about xi (3/4) |q|^2 / gamma: at |q| ~ 0.03 that is 4e-4
    world, clock, fe = sweep_bench
    amplitude_v = 0.02
    f0 = world.params.f0_hz
    fe.lockin_tc_s = 0.001
    fe.set_drive(1, amplitude_v=amplitude_v, phase_deg=PHASE_DEG, frequency_hz=f0 - 4.0, output_on=True)
    clock.sleep(10 * world.params.tau_s)
    for df in (-4.0, 0.0, 4.0):
        fe.set_frequency_hz(f0 + df)
        clock.sleep(10 * world.params.tau_s)
        expected = world.resonator.steady_state(force=_force(amplitude_v), ref_freq_hz=f0 + df)
        peak = np.linalg.norm(expected)
        np.testing.assert_allclose(fe.lockin_all(), expected, atol=0.01 * peak)
