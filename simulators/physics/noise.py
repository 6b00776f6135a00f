"""The gyro's noise and environment: drift-rate noise (white, flicker, random walk), a bounded angle
wander, a turn-on bias, slow drifts of the pickoff gains and of the damping anisotropy, and Earth's
rate on the axis.

Every rate process is an equivalent input rate (output-referred: what the gyro would read), added
to the case rate in the resonator's Coriolis term nu = 4 K Omega, so it moves the wave and reaches
the output through the loops, the stream and the transports.  docs/noise_model.md derives each
process's true Allan deviation (IEEE Std 952 annex C) and says how each is seeded.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from bench.analysis.cvg_rate import EARTH_RATE_DPH  # noqa: F401 - Earth's sidereal rate, deg/h

from .kernels import drift_noise_fill
from .normals import NormalBuffer

DEG = math.pi / 180.0
#: each process's stream of random numbers: SeedSequence(world seed, spawn_key=(id,)) (the turn-on
#: bias: spawn_key=(4, turn-on number)); the pickoff noise keeps the world seed itself (its draws are
#: those of sim-hrg before the noise model)
PROCESS_IDS = {"white": 1, "flicker": 2, "walk": 3, "turn_on": 4, "wander": 5}
#: sigma(tau) of a flicker process on its flat floor, in units of B: sqrt(2 ln 2 / pi)
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: the drift-rate noise is generated this far ahead (s of samples per compiled call)
CHUNK_S = 10.0


def dph_to_rad_s(x: float) -> float:
    return x * DEG / 3600.0


def rad_s_to_dph(x: float) -> float:
    return x / DEG * 3600.0


@dataclass(frozen=True)
class NoiseParams:
    """The noise and slow drifts of a simulated gyro, output-referred (deg/h at the gyro's rate output).

    arw_deg_rth: angle random walk N (deg/sqrt(h)): white drift-rate noise, sigma(tau) = N / sqrt(tau).
    bias_instability_dph: B (deg/h): flicker (1/f) drift-rate noise, two-sided spectrum B^2 / (2 pi f)
        between flicker_low_hz and flicker_high_hz, made of first-order Gauss-Markov processes,
        flicker_poles_per_decade of them per decade; sigma(tau) ~ 0.664 B on the flat floor.
    rrw_dph_rth: rate random walk K (deg/h/sqrt(h)): a random walk of the drift, sigma = K sqrt(tau / 3).
    turn_on_bias_mean_dph, turn_on_bias_sd_dph: the constant bias, drawn afresh at every turn-on.
    gain_x_ppm, gain_y_ppm: pickoff (X/Y electrode) gain errors at t = 0; *_drift_ppm_h their drift.
    damping_drift_per_s_h: drift of Delta(1/tau) (1/s per hour); theta_tau_drift_deg_h of its axis.
    angle_wander_deg, angle_wander_tau_s: a stationary (bounded) angle error phi, first-order
        Gauss-Markov with this standard deviation (deg, output-referred) and correlation time; it
        enters as the input rate dphi/dt, so the angle it adds to the output is phi(t) - phi(0), never
        accumulating; sigma(tau) = (sigma_phi / tau) sqrt(3 - 4 r(tau) + r(2 tau)), r(t) = e^(-t/tau_c).
    """

    arw_deg_rth: float = 0.0
    bias_instability_dph: float = 0.0
    rrw_dph_rth: float = 0.0
    flicker_low_hz: float = 1e-6
    flicker_high_hz: float = 20.0
    flicker_poles_per_decade: int = 1
    turn_on_bias_mean_dph: float = 0.0
    turn_on_bias_sd_dph: float = 0.0
    gain_x_ppm: float = 0.0
    gain_y_ppm: float = 0.0
    gain_x_drift_ppm_h: float = 0.0
    gain_y_drift_ppm_h: float = 0.0
    damping_drift_per_s_h: float = 0.0
    theta_tau_drift_deg_h: float = 0.0
    angle_wander_deg: float = 0.0
    angle_wander_tau_s: float = 1000.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"noise parameter {f.name}={v!r} must be a finite number")
        for name in ("arw_deg_rth", "bias_instability_dph", "rrw_dph_rth", "turn_on_bias_sd_dph", "angle_wander_deg"):
            if getattr(self, name) < 0:
                raise ValueError(f"noise parameter {name}={getattr(self, name)!r} must be >= 0")
        if not 0 < self.flicker_low_hz < self.flicker_high_hz:
            raise ValueError(
                f"flicker band {self.flicker_low_hz!r} to {self.flicker_high_hz!r} Hz must be 0 < low < high"
            )
        if self.flicker_poles_per_decade < 1:
            raise ValueError("flicker_poles_per_decade must be >= 1")
        if self.angle_wander_tau_s <= 0:
            raise ValueError(f"noise parameter angle_wander_tau_s={self.angle_wander_tau_s!r} s must be > 0")

    def flicker_poles(self) -> tuple[np.ndarray, np.ndarray]:
        """Corner frequencies f_j (Hz, geometric from low to high) and the variance sigma_j^2
        ((rad/s)^2, the same for each) of the Gauss-Markov processes whose sum has the two-sided
        spectrum B^2 / (2 pi f) in the band: sum_j 2 sigma^2 T_j / (1 + (2 pi f T_j)^2), T_j = 1/(2 pi f_j),
        is (pi sigma^2 / ln r) / (2 pi f) with r the pole ratio, so sigma^2 = B^2 ln r / pi."""
        if self.bias_instability_dph == 0.0:
            return np.empty(0), np.empty(0)
        decades = math.log10(self.flicker_high_hz / self.flicker_low_hz)
        m = max(2, int(math.ceil(decades * self.flicker_poles_per_decade)) + 1)
        f = np.geomspace(self.flicker_low_hz, self.flicker_high_hz, m)
        ln_r = math.log(f[1] / f[0])
        var = dph_to_rad_s(self.bias_instability_dph) ** 2 * ln_r / math.pi
        return f, np.full(m, var)

    def true_avar(self, tau_s: np.ndarray | float) -> np.ndarray:
        """The Allan variance ((rad/s)^2) of the injected drift-rate noise, exactly (continuous time):
        N^2 / tau + K^2 tau / 3 + sum_j of each Gauss-Markov process's
        (2 s^2 T / tau) [1 - (T / 2 tau)(3 - 4 e^(-tau/T) + e^(-2 tau/T))]
        + the angle wander's (sigma_phi / tau)^2 (3 - 4 e^(-tau/tau_c) + e^(-2 tau/tau_c))."""
        tau = np.asarray(tau_s, dtype=float)
        n = self.arw_deg_rth * DEG / 60.0  # deg/sqrt(h) -> rad/sqrt(s)
        k = dph_to_rad_s(self.rrw_dph_rth) / 60.0  # rad/s / sqrt(s)
        out = n**2 / tau + k**2 * tau / 3.0
        f, var = self.flicker_poles()
        for fj, vj in zip(f, var, strict=True):
            t = 1.0 / (2.0 * math.pi * fj)
            x = tau / t
            out = out + (2.0 * vj * t / tau) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))
        if self.angle_wander_deg:
            x = tau / self.angle_wander_tau_s
            out = out + (self.angle_wander_deg * DEG / tau) ** 2 * (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x))
        return out

    def average_sd_dph(self, t_s: np.ndarray | float) -> np.ndarray:
        """Standard deviation (deg/h) of the noise averaged over t_s: the bias stability with t_s
        smoothing, and the spread of the mean bias since start at t_s. For the white rate noise and
        the angle wander: sqrt(N^2 / t + 2 (1 - e^(-t/tau_c)) sigma_phi^2 / t^2) (flicker and random
        walk not included: this is for the presets that have neither)."""
        t = np.asarray(t_s, dtype=float)
        n = self.arw_deg_rth * DEG / 60.0
        var = n**2 / t + 2.0 * (1.0 - np.exp(-t / self.angle_wander_tau_s)) * (self.angle_wander_deg * DEG / t) ** 2
        return rad_s_to_dph(np.sqrt(var))

    def truth(self) -> dict[str, float]:
        return {f"noise_{k}": float(v) for k, v in asdict(self).items()} | {
            "arw_deg_rth": self.arw_deg_rth,
            "bias_instability_dph": self.bias_instability_dph,
            "rrw_dph_rth": self.rrw_dph_rth,
            "allan_floor_dph": FLICKER_FLOOR * self.bias_instability_dph,
            "turn_on_bias_mean_dph": self.turn_on_bias_mean_dph,
            "turn_on_bias_sd_dph": self.turn_on_bias_sd_dph,
        }


def earth_rate_dph(latitude_deg: float, axis_elevation_deg: float = 90.0, axis_azimuth_deg: float = 0.0) -> float:
    """Earth's rate on a sensitive axis at a latitude: the axis at an elevation above the local
    horizontal (90 = up) and an azimuth from north toward east.  Earth's rate vector in (north,
    east, up) is W (cos phi, 0, sin phi): up gives W sin phi, north W cos phi, east 0."""
    from bench.analysis.cvg_rate import earth_rate_projection_dph  # one formula for the world and the analysis

    return earth_rate_projection_dph(latitude_deg, azimuth_deg=axis_azimuth_deg, elevation_deg=axis_elevation_deg)


def process_rng(seed: int, process: str) -> np.random.Generator:
    """The generator of one process: SeedSequence(seed, spawn_key=(PROCESS_IDS[process],))."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(PROCESS_IDS[process],)))


class Environment:
    """The rate processes, the turn-on bias, Earth's rate and the slow drifts of one World.
    Not thread-safe: the World calls it under its lock."""

    def __init__(
        self, noise: NoiseParams | None, *, seed: int, sample_period_s: float, earth_rate_dph: float = 0.0
    ) -> None:
        self.noise = noise or NoiseParams()
        self.earth_rate_dph = float(earth_rate_dph)
        nz = self.noise
        dt = sample_period_s
        self._dt = dt
        self._white_sd = nz.arw_deg_rth * DEG / 60.0 / math.sqrt(dt)
        self._walk_sd = dph_to_rad_s(nz.rrw_dph_rth) / 60.0 * math.sqrt(dt)
        f, var = nz.flicker_poles()
        phi = np.exp(-2.0 * math.pi * f * dt)
        self._gm_phi = phi
        self._gm_drive = np.sqrt(var * (1.0 - phi**2))
        self._seed = seed
        self._rng = {name: process_rng(seed, name) for name in PROCESS_IDS if name != "turn_on"}
        self._gm_state = np.sqrt(var) * self._rng["flicker"].standard_normal(len(f))  # stationary start
        self._walk_state = np.zeros(1)
        self._noisy = bool(self._white_sd or self._walk_sd or len(f))
        # the angle wander (rad, output-referred): its state, a stationary start, normals drawn ahead
        self._wander_sd = nz.angle_wander_deg * DEG
        self._wander_tau_s = nz.angle_wander_tau_s
        self._wander_phi = self._wander_phi_before = 0.0
        if self._wander_sd:
            self._rng["wander"] = process_rng(seed, "wander")
            self._wander_normals = NormalBuffer(self._rng["wander"], chunk=4096)
            self._wander_phi = self._wander_sd * self._wander_normal()
        # the per-sample noise is made a chunk ahead (one compiled call) and its running sum read per block
        self._chunk = np.empty(max(1, int(round(CHUNK_S / dt))))
        self._cum = np.zeros(len(self._chunk) + 1)
        self._pos = len(self._chunk)  # samples of the chunk used
        self.turn_on_count = 0
        self.turn_on_bias_dph = 0.0
        self.turn_on()  # the world's creation is the first power-on
        self.has_slow_drifts = any(
            (nz.gain_x_ppm, nz.gain_y_ppm, nz.gain_x_drift_ppm_h, nz.gain_y_drift_ppm_h,
             nz.damping_drift_per_s_h, nz.theta_tau_drift_deg_h)
        )  # fmt: skip

    def turn_on(self) -> None:
        """A turn-on of the gyro: the constant bias of the next turn-on (turn_on_bias_of)."""
        self.turn_on_count += 1
        self.turn_on_bias_dph = self.turn_on_bias_of(self.turn_on_count)

    def turn_on_bias_of(self, count: int) -> float:
        """The bias (deg/h) of turn-on number `count` (1 = the world's creation, 2 = the first drive-on,
        ...): mean + sd z, z the first normal of SeedSequence(seed, spawn_key=(4, count)), so any
        turn-on's bias is known without running the ones before it."""
        nz = self.noise
        seq = np.random.SeedSequence(self._seed, spawn_key=(PROCESS_IDS["turn_on"], count))
        return nz.turn_on_bias_mean_dph + nz.turn_on_bias_sd_dph * float(np.random.default_rng(seq).standard_normal())

    def block_rate_rad_s(self, n: int) -> float:
        """The equivalent input rate over the next block of n samples: Earth's rate, the turn-on
        bias and the mean of the drift-rate noise over the block: `block_rates_rad_s(n, 1)` in
        scalar arithmetic (the same operations in the same order, without its arrays of one)."""
        rate = dph_to_rad_s(self.earth_rate_dph + self.turn_on_bias_dph)
        if self._noisy:
            pos = self._pos
            if pos + n <= len(self._chunk):  # inside the current chunk
                cum = self._cum
                total = cum[pos + n] - cum[pos]
                self._pos = pos + n
            else:
                total = self._noise_sum(n)
            rate = rate + total / n
        if self._wander_sd:
            h = n * self._dt
            r = math.exp(-h / self._wander_tau_s)
            scale = self._wander_sd * math.sqrt(1.0 - r * r)
            z = self._wander_normals.take(1)
            before = self._wander_phi
            phi = r * before + scale * float(z[0])
            self._wander_phi_before, self._wander_phi = before, phi
            rate = rate + (phi - before) / h
        return float(rate)

    def block_rates_rad_s(self, n: int, k: int) -> np.ndarray:
        """`block_rate_rad_s(n)` for k consecutive blocks at once (the world's fused path), each
        from its own draws in their order: the same numbers as k calls of one block."""
        rates = np.full(k, dph_to_rad_s(self.earth_rate_dph + self.turn_on_bias_dph))
        if self._noisy:
            if self._pos + n * k <= len(self._chunk):  # every block inside the current chunk
                cum = self._cum[self._pos + n * np.arange(k + 1)]
                self._pos += n * k
                sums = cum[1:] - cum[:-1]
            else:
                sums = np.array([self._noise_sum(n) for _ in range(k)])
            rates = rates + sums / n
        if self._wander_sd:
            h = n * self._dt
            r = math.exp(-h / self._wander_tau_s)
            scale = self._wander_sd * math.sqrt(1.0 - r * r)
            z = self._wander_normals.take(k)
            steps = np.empty(k)
            phi = self._wander_phi
            for j in range(k):
                before, phi = phi, r * phi + scale * float(z[j])
                steps[j] = (phi - before) / h
            self._wander_phi_before, self._wander_phi = before, phi
            rates = rates + steps
        return rates

    def _wander_normal(self) -> float:
        """The wander's next standard normal (drawn 4096 at a time from its own generator)."""
        return float(self._wander_normals.take(1)[0])

    def _wander_step(self, h_s: float) -> float:
        """Advance the angle wander by h_s exactly (Gauss-Markov transition); returns the new angle
        (rad) and keeps the old one in _wander_phi_before."""
        r = math.exp(-h_s / self._wander_tau_s)
        self._wander_phi_before = self._wander_phi
        self._wander_phi = r * self._wander_phi + self._wander_sd * math.sqrt(1.0 - r * r) * self._wander_normal()
        return self._wander_phi

    @property
    def wander_angle_rad(self) -> float:
        """The angle wander now (rad, output-referred): the bounded part of the output's angle error."""
        return self._wander_phi

    def rate_samples(self, n: int) -> np.ndarray:
        """The drift-rate noise (rad/s) of the next n samples, one per sample (synthetic records for
        tests of the analysis; the World reads block means instead)."""
        out = np.empty(n)
        if self._noisy:
            r = self._rng
            drift_noise_fill(
                r["white"], self._white_sd, r["flicker"], self._gm_phi, self._gm_drive, self._gm_state,
                r["walk"], self._walk_sd, self._walk_state, out,
            )  # fmt: skip
        else:
            out[:] = 0.0
        if self._wander_sd:
            for i in range(n):
                out[i] += (self._wander_step(self._dt) - self._wander_phi_before) / self._dt
        return out

    def _noise_sum(self, n: int) -> float:
        """Sum of the drift-rate noise over the next n samples."""
        total, size = 0.0, len(self._chunk)
        while n > 0:
            if self._pos == size:
                r = self._rng
                drift_noise_fill(
                    r["white"], self._white_sd, r["flicker"], self._gm_phi, self._gm_drive, self._gm_state,
                    r["walk"], self._walk_sd, self._walk_state, self._chunk,
                )  # fmt: skip
                np.cumsum(self._chunk, out=self._cum[1:])
                self._pos = 0
            take = min(n, size - self._pos)
            total += float(self._cum[self._pos + take] - self._cum[self._pos])
            self._pos += take
            n -= take
        return total

    def gains(self, t_s: float) -> tuple[float, float]:
        """Pickoff gains (X: cx, sx; Y: cy, sy) at t_s."""
        nz, h = self.noise, t_s / 3600.0
        return (1.0 + 1e-6 * (nz.gain_x_ppm + nz.gain_x_drift_ppm_h * h),
                1.0 + 1e-6 * (nz.gain_y_ppm + nz.gain_y_drift_ppm_h * h))  # fmt: skip

    def damping(self, t_s: float, d0_per_s: float, theta_tau0_deg: float) -> tuple[float, float]:
        """Delta(1/tau) (>= 0) and its axis (deg) at t_s, drifted from their values at t = 0."""
        nz, h = self.noise, t_s / 3600.0
        return max(0.0, d0_per_s + nz.damping_drift_per_s_h * h), theta_tau0_deg + nz.theta_tau_drift_deg_h * h

    def truth(self) -> dict[str, float]:
        return self.noise.truth() | {
            "earth_rate_dph": self.earth_rate_dph,
            "turn_on_bias_dph": self.turn_on_bias_dph,
            "turn_on_count": float(self.turn_on_count),
            # the next turn-on's draw: a truth taken at a run's start, the drive off, names the bias of
            # the turn-on the run makes when it switches the drive on (World.truth's drive_on)
            "turn_on_bias_next_dph": self.turn_on_bias_of(self.turn_on_count + 1),
        }


# the CETC self-calibration paper's gyro (docs/selfcal.md, section 1): a noise floor of the paper's
# self-calibrated 0.52 deg/h at 100 s made of a small angle random walk (N = 0.006 deg/sqrt(h):
# 0.036 deg/h at 100 s, 0.0019 deg/h on the 10 h mean) and a bounded angle wander (0.025 deg,
# 550 s: 0.519 deg/h at 100 s, 0.0035 deg/h on the 10 h mean), so the angle error does not
# accumulate and the mean bias since start after 10 h has a 3 sigma of 0.012 deg/h, under the
# paper's 0.018; a 0.15 % X/Y pickoff gain error growing by 20 ppm/h, damping anisotropy stable
SELFCAL_NOISE = NoiseParams(
    arw_deg_rth=0.006,
    angle_wander_deg=0.025,
    angle_wander_tau_s=550.0,
    gain_x_ppm=750.0,
    gain_y_ppm=-750.0,
    gain_x_drift_ppm_h=10.0,
    gain_y_drift_ppm_h=-10.0,
)

#: the noise of each resonator preset that has one (simulators.physics.params.PRESETS)
NOISE_PRESETS: dict[str, NoiseParams] = {
    # an HRG in whole-angle mode (docs/noise_model.md), its three Allan terms all told apart within
    # an hour: N dominates below ~10 s, the floor (0.2 deg/h) around 20 s, K above ~50 s; a turn-on
    # bias of 1 deg/h with a spread of 2 deg/h
    "hrg-wa": NoiseParams(
        arw_deg_rth=0.01,
        bias_instability_dph=0.3,
        rrw_dph_rth=3.0,
        turn_on_bias_mean_dph=1.0,
        turn_on_bias_sd_dph=2.0,
        gain_x_ppm=300.0,
        gain_y_ppm=-300.0,
        gain_x_drift_ppm_h=10.0,
        gain_y_drift_ppm_h=-5.0,
        damping_drift_per_s_h=1e-9,
        theta_tau_drift_deg_h=0.5,
    ),
    "hrg-selfcal": SELFCAL_NOISE,
    # the self-calibration gyro with loop gain errors (docs/selfcal.md): the same floor and X/Y gains
    "hrg-selfcal-gains": SELFCAL_NOISE,
    # the realistic HRG (docs/error_sources.md): the self-calibration gyro's noise floor (its pickoff
    # gains are the error sources' own, simulators.physics.errors)
    "hrg-realistic": NoiseParams(arw_deg_rth=0.006, angle_wander_deg=0.025, angle_wander_tau_s=550.0),
}
