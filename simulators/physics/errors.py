"""Error sources of a real gyro that the estimators do not assume (docs/error_sources.md).

Each is off (0) by default, so a World without them computes what it always did; the "realistic"
presets (ERROR_PRESETS) switch them on at sizes a real unit shows.  They act where they act in
hardware:
  * on the pickoffs (`measure`, applied to the demodulated states (cx, sx, cy, sy) of each block):
    electrode misalignment, capacitive (cubic) nonlinearity, readout phase delay, then the chain's
    gain, common-mode and differential, each with a drift and the common-mode one with temperature;
  * on the forcers (`force`, applied to the force the devices command): gain and angle errors of
    the X and Y drive electrodes;
  * on the resonator (`thermal`): the natural frequency and Q at the world's temperature.
Conventions: x(t) = cx cos wt + sx sin wt (PHYSICS.md section 1); an electrode at physical angle
phi reads the n = 2 displacement x cos 2 phi + y sin 2 phi (X nominally at 0, Y at 45 deg).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from functools import cached_property

import numpy as np

from .errors_kernel import pickoff_block

TWO_PI = 2.0 * math.pi
#: the temperature a unit's f0 and Q are given at (deg C)
REFERENCE_TEMPERATURE_C = 25.0


@dataclass(frozen=True)
class ErrorSources:
    """The error sources of one simulated unit, physical units; all 0 = an ideal chain.

    pickoff_gain_cm_ppm, pickoff_gain_diff_ppm: pickoff chain gains X = 1 + cm + diff,
        Y = 1 + cm - diff (ppm at t = 0 and the reference temperature); *_drift_ppm_h their drift.
    pickoff_gain_tc_ppm_k: the common-mode gain's temperature coefficient.
    pickoff_angle_x_deg, pickoff_angle_y_deg: misalignment of the X and Y pickoff electrodes from
        0 and 45 deg (physical degrees in the case frame).
    pickoff_phase_x_deg, pickoff_phase_y_deg: phase delay of each readout chain at the carrier
        (electrical degrees: 360 f0 x the group delay).
    pickoff_cubic: capacitive nonlinearity e3 of each pickoff, x_read = x + e3 x^3 (per model
        amplitude squared): at the fundamental a relative gain of (3/4) e3 a^2.
    forcer_gain_x_ppm, forcer_gain_y_ppm: drive/control chain gain errors of the X and Y forcers.
    forcer_angle_x_deg, forcer_angle_y_deg: misalignment of the X and Y forcer electrodes.
    freq_tc_ppm_k: df0/dT / f0 (ppm per K); q_tc_per_k: dtau/dT / tau (relative, per K; Q = pi f0 tau
        moves by that and by f0's TCF).
    bias_tc_dps_k, bias_tc2_dps_k2: a rate-equivalent bias following the unit's temperature,
        b(T) = bias_tc (T - 25) + bias_tc2 (T - 25)^2 deg/s at the sensitive axis (the datasheet
        figure of a MEMS gyro's zero-rate level against temperature, docs/chamber.md).
    hyst_halfwidth_k, bias_hyst_dps, sf_hyst_ppm: thermal hysteresis (docs/chamber.md, "Thermal
        hysteresis"): the package's stress state s follows the temperature T through a play
        (backlash) of half-width hyst_halfwidth_k (it moves only when |T - s| would exceed it), and
        h = (T - s) / hyst_halfwidth_k (+1 on a heating branch, -1 on a cooling one, 0 at the start)
        adds h bias_hyst_dps / 2 to the bias and h sf_hyst_ppm / 2 to the scale factor: on saturated
        branches, heating minus cooling at the same temperature is bias_hyst_dps and sf_hyst_ppm.
    """

    pickoff_gain_cm_ppm: float = 0.0
    pickoff_gain_diff_ppm: float = 0.0
    pickoff_gain_cm_drift_ppm_h: float = 0.0
    pickoff_gain_diff_drift_ppm_h: float = 0.0
    pickoff_gain_tc_ppm_k: float = 0.0
    pickoff_angle_x_deg: float = 0.0
    pickoff_angle_y_deg: float = 0.0
    pickoff_phase_x_deg: float = 0.0
    pickoff_phase_y_deg: float = 0.0
    pickoff_cubic: float = 0.0
    forcer_gain_x_ppm: float = 0.0
    forcer_gain_y_ppm: float = 0.0
    forcer_angle_x_deg: float = 0.0
    forcer_angle_y_deg: float = 0.0
    freq_tc_ppm_k: float = 0.0
    q_tc_per_k: float = 0.0
    bias_tc_dps_k: float = 0.0
    bias_tc2_dps_k2: float = 0.0
    hyst_halfwidth_k: float = 0.0
    bias_hyst_dps: float = 0.0
    sf_hyst_ppm: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"error source {f.name}={v!r} must be a finite number")
        if (self.bias_hyst_dps or self.sf_hyst_ppm) and not self.hyst_halfwidth_k > 0:
            raise ValueError("bias_hyst_dps / sf_hyst_ppm need hyst_halfwidth_k > 0 (the play's half-width, K)")

    @property
    def active(self) -> bool:
        """Any source switched on."""
        return any(getattr(self, f.name) for f in fields(self))

    def with_(self, **changes: float) -> ErrorSources:
        return replace(self, **changes)

    # --- thermal hysteresis --------------------------------------------------------------------
    @property
    def hysteretic(self) -> bool:
        return bool(self.bias_hyst_dps or self.sf_hyst_ppm)

    def stress_after(self, stress_c: float, temperature_c: float) -> float:
        """The package's stress state after the temperature moved to temperature_c: the play
        operator (it stays unless the temperature is more than the half-width away, then it is
        dragged along at that distance).  Rate-independent: a settled point keeps its branch."""
        w = self.hyst_halfwidth_k
        return min(max(stress_c, temperature_c - w), temperature_c + w)

    def hysteresis_state(self, temperature_c: float, stress_c: float | None) -> float:
        """h = (T - s) / half-width in [-1, 1]: +1 on a heating branch, -1 on a cooling one."""
        if stress_c is None or not self.hysteretic:
            return 0.0
        return (temperature_c - stress_c) / self.hyst_halfwidth_k

    # --- pickoffs ----------------------------------------------------------------------------
    def pickoff_gains(self, t_s: float, temperature_c: float = REFERENCE_TEMPERATURE_C,
                      stress_c: float | None = None) -> tuple[float, float]:
        """The X and Y pickoff chain gains at t_s and a temperature (and the package's stress state:
        force-to-rebalance's scale factor goes as 1 / the gain, so the gain moves by -h sf_hyst / 2)."""
        h = t_s / 3600.0
        cm = self.pickoff_gain_cm_ppm + self.pickoff_gain_cm_drift_ppm_h * h
        cm += self.pickoff_gain_tc_ppm_k * (temperature_c - REFERENCE_TEMPERATURE_C)
        if self.sf_hyst_ppm:
            cm -= 0.5 * self.sf_hyst_ppm * self.hysteresis_state(temperature_c, stress_c)
        diff = self.pickoff_gain_diff_ppm + self.pickoff_gain_diff_drift_ppm_h * h
        return 1.0 + 1e-6 * (cm + diff), 1.0 + 1e-6 * (cm - diff)

    @cached_property
    def _pickoff_constants(self) -> tuple:
        """The pickoff kernel's constants (errors_kernel.pickoff_block), worked out once: the
        electrodes' angles, the cubic term and the chains' phases as their sines and cosines."""
        ax, ay = 2.0 * math.radians(self.pickoff_angle_x_deg), 2.0 * math.radians(self.pickoff_angle_y_deg)
        px, py = math.radians(self.pickoff_phase_x_deg), math.radians(self.pickoff_phase_y_deg)
        return (bool(ax or ay), math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), float(self.pickoff_cubic),
                bool(px), math.cos(px), math.sin(px), bool(py), math.cos(py), math.sin(py))  # fmt: skip

    def measure(self, q: np.ndarray, t_s: float, temperature_c: float = REFERENCE_TEMPERATURE_C,
                stress_c: float | None = None) -> np.ndarray:
        """The states (n, 4) as the pickoff chains read them (a new array): the electrodes'
        projection, their cubic nonlinearity, each chain's phase delay and gain (one compiled
        loop, simulators.physics.errors_kernel)."""
        q = np.asarray(q, dtype=float)
        gx, gy = self.pickoff_gains(t_s, temperature_c, stress_c)
        out = np.empty_like(q)
        pickoff_block(q, *self._pickoff_constants, gx, gy, out)
        return out

    # --- forcers -----------------------------------------------------------------------------
    @cached_property
    def _forcer_constants(self) -> tuple[float, float, float, float, float, float]:
        """The forcers' gains and their electrodes' cosines and sines, worked out once."""
        gx, gy = 1.0 + 1e-6 * self.forcer_gain_x_ppm, 1.0 + 1e-6 * self.forcer_gain_y_ppm
        ax, ay = 2.0 * math.radians(self.forcer_angle_x_deg), 2.0 * math.radians(self.forcer_angle_y_deg)
        return gx, gy, math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)

    def force(self, u: np.ndarray) -> np.ndarray:
        """The force the modes receive (4,) for a commanded one (u1, u2 on X; u3, u4 on Y): each
        forcer's gain, and its electrode's angle (X at fx pushes along (cos 2fx, sin 2fx), Y at
        45 deg + fy along (-sin 2fy, cos 2fy))."""
        u1, u2, u3, u4 = np.asarray(u, dtype=float).tolist()
        gx, gy, c_x, s_x, c_y, s_y = self._forcer_constants
        fx1, fx2, fy1, fy2 = gx * u1, gx * u2, gy * u3, gy * u4
        return np.array([c_x * fx1 - s_y * fy1, c_x * fx2 - s_y * fy2, s_x * fx1 + c_y * fy1, s_x * fx2 + c_y * fy2])

    # --- resonator ---------------------------------------------------------------------------
    def thermal(self, gamma: float, c_m: float, f0_hz: float, temperature_c: float) -> tuple[float, float]:
        """The damping gamma and mean mistuning c_m (1/s) at a temperature, from those at the
        reference: f0 moves by f0 TCF dT (c_m by 2 x 2 pi of that), the damping time tau by
        (1 + q_tc dT) (so Q = pi f tau by that and by f's own change)."""
        dt_k = temperature_c - REFERENCE_TEMPERATURE_C
        df_hz = f0_hz * 1e-6 * self.freq_tc_ppm_k * dt_k
        return gamma / (1.0 + self.q_tc_per_k * dt_k), c_m + 2.0 * TWO_PI * df_hz

    def thermal_bias_dps(self, temperature_c: float, stress_c: float | None = None) -> float:
        """The rate-equivalent bias the temperature adds (deg/s at the sensitive axis), with the
        hysteresis's h bias_hyst / 2 for the package's stress state (None: none)."""
        dt_k = temperature_c - REFERENCE_TEMPERATURE_C
        b = self.bias_tc_dps_k * dt_k + self.bias_tc2_dps_k2 * dt_k * dt_k
        if self.bias_hyst_dps:
            b += 0.5 * self.bias_hyst_dps * self.hysteresis_state(temperature_c, stress_c)
        return b

    @property
    def thermal_active(self) -> bool:
        return bool(self.freq_tc_ppm_k or self.q_tc_per_k)

    def truth(self, t_s: float, temperature_c: float, resonator_truth: dict[str, float],
              stress_c: float | None = None) -> dict:
        """Each source under `err_<name>`, and what they make now: the pickoff gains, the
        temperature, the natural frequency and Q there; away from the reference temperature the
        resonator's damping and frequency keys (tau_s, q_factor, Q, gamma, freq_offset_hz, c_m)
        become the unit's at that temperature, their reference values kept as `<key>_ref`."""
        gx, gy = self.pickoff_gains(t_s, temperature_c, stress_c)
        dt_k = temperature_c - REFERENCE_TEMPERATURE_C
        r = resonator_truth
        f0_hz = r["f0_hz"]
        df_hz = f0_hz * 1e-6 * self.freq_tc_ppm_k * dt_k
        tau_scale = 1.0 + self.q_tc_per_k * dt_k
        q_scale = tau_scale * (1.0 + df_hz / f0_hz)  # Q = pi f tau: both move
        out = {f"err_{k}": float(v) for k, v in asdict(self).items()} | {
            "pickoff_gain_x": gx,
            "pickoff_gain_y": gy,
            "temperature_c": float(temperature_c),
            "f0_at_temperature_hz": f0_hz + r["freq_offset_hz"] + df_hz,
            "q_factor_at_temperature": r["q_factor"] * q_scale,
            "thermal_bias_dps": self.thermal_bias_dps(temperature_c, stress_c),
        }
        if self.hysteretic and stress_c is not None:
            out |= {"package_stress_c": float(stress_c),
                    "hysteresis_state": self.hysteresis_state(temperature_c, stress_c)}
        if dt_k and self.thermal_active:
            now = {"tau_s": r["tau_s"] * tau_scale, "q_factor": r["q_factor"] * q_scale, "Q": r["Q"] * q_scale,
                   "gamma": r["gamma"] / tau_scale, "freq_offset_hz": r["freq_offset_hz"] + df_hz,
                   "c_m": r["c_m"] + 2.0 * TWO_PI * df_hz}
            out |= {f"{k}_ref": r[k] for k in now} | now
        return out


#: the error sources of each realistic preset (docs/error_sources.md gives each size's source)
ERROR_PRESETS: dict[str, ErrorSources] = {
    "hrg-realistic": ErrorSources(
        pickoff_gain_cm_ppm=-500.0,  # the common-mode case; CETC fig. 3: both gains rise
        pickoff_gain_diff_ppm=750.0,  # CETC: X/Y gain error about 0.15 %
        pickoff_gain_cm_drift_ppm_h=20.0,
        pickoff_gain_diff_drift_ppm_h=2.0,
        pickoff_gain_tc_ppm_k=30.0,
        pickoff_angle_x_deg=0.05,
        pickoff_angle_y_deg=-0.08,
        pickoff_phase_x_deg=2.0,  # ~1 us of group delay at 5.5 kHz
        pickoff_phase_y_deg=2.05,
        pickoff_cubic=1e-3,
        forcer_gain_x_ppm=800.0,
        forcer_gain_y_ppm=-400.0,
        forcer_angle_x_deg=0.1,
        forcer_angle_y_deg=-0.05,
        freq_tc_ppm_k=55.0,  # fused silica: dE/dT / E ~ +1.1e-4 / K, f ~ sqrt(E)
        q_tc_per_k=-3e-3,
    ),
    # the self-calibration gyro (its X/Y pickoff difference is simulators.physics.noise's) with the
    # loop gain errors the paper's self-calibration identifies: a common-mode pickoff gain, both gains
    # rising together (CETC fig. 3: the gain term of its eq. 11), and forcer gains (the FM's path)
    "hrg-selfcal-gains": ErrorSources(
        pickoff_gain_cm_ppm=-500.0,
        pickoff_gain_cm_drift_ppm_h=20.0,
        forcer_gain_x_ppm=800.0,
        forcer_gain_y_ppm=-400.0,
    ),
    "mems-realistic": ErrorSources(
        pickoff_gain_cm_ppm=2000.0,
        pickoff_gain_diff_ppm=-3000.0,  # two capacitive channels matched to 0.3 %
        pickoff_gain_cm_drift_ppm_h=50.0,
        pickoff_gain_diff_drift_ppm_h=-10.0,
        pickoff_gain_tc_ppm_k=100.0,
        pickoff_angle_x_deg=0.2,
        pickoff_angle_y_deg=-0.3,
        pickoff_phase_x_deg=5.0,  # ~1 us of group delay at 13.6 kHz
        pickoff_phase_y_deg=5.3,
        pickoff_cubic=5e-3,
        forcer_gain_x_ppm=3000.0,
        forcer_gain_y_ppm=-2000.0,
        forcer_angle_x_deg=0.3,
        forcer_angle_y_deg=0.2,
        freq_tc_ppm_k=-30.0,  # silicon: dE/dT / E ~ -60 ppm / K
        q_tc_per_k=-2e-3,
        # the zero-rate level against temperature of MEMS gyro datasheets (0.01..0.16 deg/s/K,
        # docs/chamber.md): 0.03 deg/s/K, curved by 5e-5 deg/s/K^2 (+0.18 deg/s at -35 and +85 degC)
        bias_tc_dps_k=0.03,
        bias_tc2_dps_k2=5e-5,
        # thermal hysteresis (docs/chamber.md, "Thermal hysteresis"): a play of +-0.5 K in the
        # package's stress; on saturated branches heating minus cooling is -0.06 deg/s in bias (20 %
        # of the 0.3 deg/s the bias moves over the 10 K of eol-mems-thermal; Analog Devices reports
        # ~0.1 deg/s bias hysteresis on single ADIS16460 units) and -200 ppm in scale factor
        hyst_halfwidth_k=0.5,
        bias_hyst_dps=-0.06,
        sf_hyst_ppm=-200.0,
    ),
}
