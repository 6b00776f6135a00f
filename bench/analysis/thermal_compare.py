"""The ramp method against the soak on the same unit (docs/chamber.md, "Ramp against soak"): the
bias each method's compensation leaves at the soak's settled points, by thermometer (the ramp's
fits against the resonator frequency, the case thermocouple and the chamber air), their ratio to
the soak's own, and the simulated times.  Pure: arrays and fits in, results out."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .thermal_fit import ThermalFit

#: issue 34's target: the ramp within this factor of the soak's residual ...
RESIDUAL_RATIO_TARGET = 1.5
#: ... in at most this fraction of the soak's simulated time
TIME_RATIO_TARGET = 1.0 / 3.0

#: the thermometers a ramp's bias fit can be compensated against, in the order shown
THERMOMETERS = ("frequency", "part", "air")
THERMOMETER_LABELS = {"frequency": "resonator frequency", "part": "case thermocouple", "air": "chamber air"}


@dataclass(frozen=True)
class Compensation:
    """One compensation applied at the soak's points: what is left, its rms and its ratio to the soak's."""

    method: str  # "soak" or "ramp"
    thermometer: str  # "part", "frequency" or "air"
    temperature_c: np.ndarray  # where the thermometer puts each soak point
    residual_dph: np.ndarray  # soak bias minus the fit there
    rms_dph: float
    ratio: float  # rms over the soak's own rms

    @property
    def label(self) -> str:
        return f"{self.method} fit vs {THERMOMETER_LABELS[self.thermometer]}"


@dataclass(frozen=True)
class ThermalComparison:
    """The soak's settled points, each compensation's residual there, the times and the target."""

    part_c: np.ndarray
    bias_dph: np.ndarray
    bias_se_dph: np.ndarray
    soak: Compensation
    ramp: dict[str, Compensation]  # by thermometer
    soak_s: float
    ramp_s: float

    @property
    def noise_rms_dph(self) -> float:
        """rms of the soak points' own standard errors: what their noise allows a residual."""
        return float(np.sqrt(np.mean(self.bias_se_dph**2)))

    @property
    def time_ratio(self) -> float:
        return self.ramp_s / self.soak_s

    @property
    def best(self) -> Compensation:
        """The ramp's compensation that leaves the least at the soak's points."""
        return min(self.ramp.values(), key=lambda c: c.rms_dph)

    def meets_target(self, thermometer: str | None = None) -> bool:
        """The ramp (its best thermometer, or the one named) within 1.5x of the soak's residual in
        at most a third of its simulated time."""
        c = self.best if thermometer is None else self.ramp[thermometer]
        return c.ratio <= RESIDUAL_RATIO_TARGET and self.time_ratio <= TIME_RATIO_TARGET


def frequency_as_temperature(f_hz, line: ThermalFit) -> np.ndarray:
    """Frequencies read as temperatures through a straight line f(T) (the ramp's frequency thermometer)."""
    return line.t_ref_c + (np.asarray(f_hz, dtype=float) - line.coeffs[0]) / line.coeffs[1]


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def compare_at_soak_points(soak_points: dict[str, np.ndarray], soak_fit: Callable, ramp_fits: dict[str, Callable],
                           line: ThermalFit, *, soak_s: float, ramp_s: float) -> ThermalComparison:
    """Each fit applied at the soak's settled points (soak_points: part_c, air_c, f0_hz, bias_dph,
    bias_se_dph): the soak's own bias fit against the case thermocouple, the ramp's against each
    thermometer (its frequency read through `line`, its chamber air fit at the settled air reading)."""
    part = np.asarray(soak_points["part_c"], dtype=float)
    if len(part) < 2:
        raise ValueError(f"{len(part)} soak point(s): a comparison needs 2 or more")
    if not (soak_s > 0 and ramp_s > 0):
        raise ValueError(f"simulated times {soak_s!r} s (soak) and {ramp_s!r} s (ramp) must be > 0")
    bias = np.asarray(soak_points["bias_dph"], dtype=float)
    temps = {"part": part, "air": np.asarray(soak_points["air_c"], dtype=float),
             "frequency": frequency_as_temperature(soak_points["f0_hz"], line)}
    own = bias - soak_fit(part)
    own_rms = _rms(own)
    soak = Compensation("soak", "part", part, own, own_rms, 1.0)
    ramp = {}
    for k in THERMOMETERS:
        r = bias - ramp_fits[k](temps[k])
        ramp[k] = Compensation("ramp", k, temps[k], r, _rms(r), _rms(r) / own_rms if own_rms > 0 else float("inf"))
    return ThermalComparison(part, bias, np.asarray(soak_points["bias_se_dph"], dtype=float), soak, ramp,
                             float(soak_s), float(ramp_s))
