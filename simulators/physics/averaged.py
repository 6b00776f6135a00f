"""Integrate the averaged slow-variable model: exact matrix-exponential steps when it is linear,
an adaptive Runge-Kutta integrator (DOP853, compiled) when the resonator has cubic or quintic nonlinearity.

Inputs are held constant over a block of samples (piecewise-constant case rate, forcing and
reference frequency); a whole block of samples comes out of one compiled call (kernels.py), which
is what makes a 300 s decay at 1 kHz cost milliseconds and a 50 ms loop block a few microseconds.
Table-rate ripple enters as a per-sample wave rotation of -2 K (ripple angle) electrical: the
rotation commutes with the isotropic part of the dynamics, so carrying it outside the exact step
is accurate to O(D x ripple angle).
"""

from __future__ import annotations

import math

import numpy as np
from threadpoolctl import threadpool_limits

from bench.analysis.slow_model import linear_matrix

from .dop853 import integrate_block
from .kernels import linear_block
from .normals import NormalBuffer
from .params import TWO_PI, ResonatorParams

_blas_limiter: object | None = None
_ZERO4 = np.zeros(4)
_EMPTY = np.empty(0)
_EMPTY_ROWS = np.empty((0, 4))


def use_single_thread_blas() -> None:
    """Run BLAS single-threaded in this process.  The simulator's matrices are 4x4 and 5x5, where
    threaded BLAS only adds hand-offs: one 5x5 expm took 850 us with two OpenBLAS threads on this
    busy 2-core machine and 35-100 us with one.  Called when a World is built."""
    global _blas_limiter
    if _blas_limiter is None:
        _blas_limiter = threadpool_limits(limits=1, user_api="blas")


def rotate_wave(q: np.ndarray, psi_rad: np.ndarray | float) -> np.ndarray:
    """Rotate the electrical angle of states q (..., 4) by psi (the wave turns by psi/2)."""
    c, s = np.cos(psi_rad), np.sin(psi_rad)
    q1, p1, q2, p2 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(np.broadcast_shapes(q1.shape, np.shape(c)) + (4,))
    out[..., 0] = q1 * c - q2 * s
    out[..., 1] = p1 * c - p2 * s
    out[..., 2] = q1 * s + q2 * c
    out[..., 3] = p1 * s + p2 * c
    return out


def _scale(q: np.ndarray, gains: tuple[float, float]) -> None:
    """Pickoff gains on measured states (n, 4) in place: X on cx, sx; Y on cy, sy."""
    q[:, :2] *= gains[0]
    q[:, 2:] *= gains[1]


def damping_terms(d_per_s: float, theta_tau_deg: float) -> tuple[float, float]:
    """The linear step's damping-anisotropy parameters (zg[2], zg[3]) of Delta(1/tau) at its axis."""
    th = math.radians(theta_tau_deg)
    return d_per_s * math.cos(4.0 * th), d_per_s * math.sin(4.0 * th)


class Resonator:
    """The resonator's slow state and its integration.  Not thread-safe: the World locks it."""

    def __init__(self, params: ResonatorParams, *, seed: int = 0, state: np.ndarray | None = None) -> None:
        use_single_thread_blas()  # also makes the arrays independent of BLAS's thread split
        self.params = params
        self.coeffs = params.coefficients()
        self.rng = np.random.default_rng(seed)
        self._normals = NormalBuffer(self.rng)  # every pickoff noise draw goes through it
        self._q = np.zeros(4) if state is None else np.asarray(state, dtype=float).copy()
        self._psi = 0.0  # current ripple rotation (electrical rad) applied to the output
        self._zg = self.coeffs.zg(0.0)  # the kernel's parameter vector; nu is set per block
        # constants of the per-block path, read once (params and coefficients are frozen)
        c = self.coeffs
        self._linear = c.xi == 0.0 and c.kappa == 0.0
        self._four_k, self._nu_offset, self._w0 = 4.0 * c.bryan_factor, c.nu_offset, c.w0_rad_s
        self._psi_per_rad = -2.0 * c.bryan_factor
        self._sigma = params.noise_sigma
        self._thermal: tuple[float, float] | None = None  # (gamma, c_m) away from the reference temperature

    # --- state -------------------------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """True slow variables (cx, sx, cy, sy) now, ripple rotation included."""
        return rotate_wave(self._q, self._psi) if self._psi else self._q.copy()

    def set_state(self, q: np.ndarray) -> None:
        self._q = np.asarray(q, dtype=float).copy()
        self._psi = 0.0

    def set_damping_anisotropy(self, d_per_s: float, theta_tau_deg: float) -> None:
        """Change Delta(1/tau) and its axis (the slow drift of simulators.physics.noise) in the
        linear step's parameters."""
        self._zg[2], self._zg[3] = damping_terms(d_per_s, theta_tau_deg)

    def set_thermal(self, gamma: float, c_m: float) -> None:
        """The damping gamma and mean mistuning c_m (1/s) at the unit's temperature
        (simulators.physics.errors.ErrorSources.thermal)."""
        self._zg[0], self._zg[4] = gamma, c_m
        self._thermal = (gamma, c_m)

    def _model_zg(self, rate_rad_s: float) -> np.ndarray:
        """The coefficients' parameter vector at a rate, with the temperature's gamma and c_m."""
        zg = self.coeffs.zg(rate_rad_s)
        if self._thermal is not None:
            zg[0], zg[4] = self._thermal
        return zg

    @property
    def is_linear(self) -> bool:
        return self.coeffs.xi == 0.0 and self.coeffs.kappa == 0.0

    def detuning_rad_s(self, ref_freq_hz: float) -> float:
        """lam = w_ref - w0: reference (drive) minus the nominal natural frequency."""
        return TWO_PI * ref_freq_hz - self.coeffs.w0_rad_s

    # --- integration -------------------------------------------------------------------------
    def step_block(
        self,
        n_samples: int,
        dt_s: float,
        *,
        rate_rad_s: float = 0.0,
        force: np.ndarray | None = None,
        ref_freq_hz: float | None = None,
        ripple_angle_rad: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance n_samples steps of dt_s with constant inputs; return the true states at the end
        of each step, shape (n_samples, 4)."""
        return self.step_and_measure(
            n_samples, dt_s, rate_rad_s=rate_rad_s, force=force, ref_freq_hz=ref_freq_hz,
            ripple_angle_rad=ripple_angle_rad, measure=False,
        )[0]  # fmt: skip

    def step_and_measure(
        self,
        n_samples: int,
        dt_s: float,
        *,
        rate_rad_s: float = 0.0,
        force: np.ndarray | None = None,
        ref_freq_hz: float | None = None,
        ripple_angle_rad: np.ndarray | None = None,
        measure: bool = True,
        gains: tuple[float, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """step_block and, with `measure`, `measure` of its states: (true, measured) states (the
        World's block in one compiled call when the model is linear); `gains` (X on cx, sx; Y on
        cy, sy) scale the measured states."""
        if n_samples <= 0:
            return np.empty((0, 4)), (np.empty((0, 4)) if measure else None)
        u = _ZERO4 if force is None else np.asarray(force, dtype=float)
        lam = 0.0 if ref_freq_hz is None else TWO_PI * ref_freq_hz - self._w0  # detuning_rad_s
        if self._linear:
            return self._linear_block(n_samples, dt_s, rate_rad_s, u, lam, ripple_angle_rad, measure, gains)
        traj = self._nonlinear_block(n_samples, dt_s, self._model_zg(rate_rad_s), u, lam)
        self._q = traj[-1].copy()
        if ripple_angle_rad is None:
            self._psi = 0.0
        else:
            psi = -2.0 * self.coeffs.bryan_factor * np.asarray(ripple_angle_rad, dtype=float)
            self._psi = float(psi[-1])
            traj = rotate_wave(traj, psi)
        if not measure:
            return traj, None
        q_meas = self.measure(traj)
        if gains is not None:
            _scale(q_meas, gains)
        return traj, q_meas

    def _linear_block(
        self,
        n: int,
        dt: float,
        rate_rad_s: float,
        u: np.ndarray,
        lam: float,
        ripple_angle_rad: np.ndarray | None,
        measure: bool,
        gains: tuple[float, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Exact steps of dq/dt = A q + u/2 (the top row of exp([[A, I/2], [0, 0]] dt) applied to
        (q, u) each sample), the ripple rotation and the pickoff noise: kernels.linear_block."""
        zg = self._zg
        zg[1] = self._four_k * rate_rad_s + self._nu_offset  # 4 K rate + nu_offset, as coeffs.zg
        psi_per_rad = self._psi_per_rad
        if ripple_angle_rad is None:
            self._psi = 0.0
            ripple = _EMPTY
        else:
            ripple = np.ascontiguousarray(ripple_angle_rad, dtype=float)
            self._psi = float(psi_per_rad * ripple[-1])
        sigma = self._sigma
        noise = _EMPTY_ROWS
        if measure and sigma != 0.0:
            noise = self._normals.take(4 * n).reshape(n, 4)  # the draws of rng.normal(0, sigma, (n, 4))
        out = np.empty((n, 4))
        if gains is not None and sigma != 0.0:  # the gains applied in the kernel's noise loop
            linear_block(zg, lam, dt, self._q, u, ripple, psi_per_rad, out, noise, sigma, gains[0], gains[1])
            return out, noise
        linear_block(zg, lam, dt, self._q, u, ripple, psi_per_rad, out, noise, sigma, 1.0, 1.0)  # one signature
        if not measure:
            return out, None
        q_meas = noise if sigma != 0.0 else out.copy()
        if gains is not None:
            _scale(q_meas, gains)
        return out, q_meas

    def _nonlinear_block(self, n: int, dt: float, zg: np.ndarray, u: np.ndarray, lam: float) -> np.ndarray:
        """n samples of dt of the nonlinear model from the state now: scipy's DOP853 (rtol 1e-9,
        atol 1e-12, first step dt), compiled (simulators.physics.dop853)."""
        if not np.any(self._q) and not np.any(u):
            return np.zeros((n, 4))  # at rest and unforced: stays at rest (and spares the solver a 0/0)
        return integrate_block(linear_matrix(zg, lam), u, self.coeffs.xi, self.coeffs.kappa, self._q, dt, n)

    # --- measurement -------------------------------------------------------------------------
    def measure(self, q_true: np.ndarray) -> np.ndarray:
        """Add the white measurement noise of the pickoff chain (seeded)."""
        sigma = self.params.noise_sigma
        if sigma == 0.0:
            return np.array(q_true, dtype=float, copy=True)
        shape = np.shape(q_true)
        z = self._normals.take(int(np.prod(shape))).reshape(shape)
        return q_true + (0.0 + sigma * z)  # rng.normal(0, sigma, shape): loc + scale z

    def steady_state(self, *, rate_rad_s: float = 0.0, force: np.ndarray, ref_freq_hz: float) -> np.ndarray:
        """Forced steady state of the linear model: 0 = A q + u/2 (used to start sweeps settled)."""
        lam = self.detuning_rad_s(ref_freq_hz)
        a = linear_matrix(self._model_zg(rate_rad_s), lam)
        return np.linalg.solve(a, -0.5 * np.asarray(force, dtype=float))
