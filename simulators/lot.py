"""A simulated production lot's units: resonator parameters drawn from a spread around a preset,
some pushed out of spec on purpose, reproducible from a seed.  The line's lot simulation
(bench.line.simulate) and the several-gyros station's slots draw their units here."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .physics.params import PRESETS

#: per preset: (parameter, mean, sd, out-of-spec value pushed to) -- sd chosen so that a few
#: units of a lot fall out of the shipped limits by chance, besides those pushed out on purpose
SPREADS: dict[str, list[tuple[str, float, float, float]]] = {
    "hrg": [("tau_s", 300.0, 25.0, 215.0), ("delta_inv_tau_per_s", 1.6e-4, 0.3e-4, 3.2e-4),
            ("split_hz", 0.005, 0.001, 0.0105)],
    "mems": [("tau_s", 0.04648, 0.0015, 0.0395), ("split_hz", 2.75, 0.15, 3.7)],
}
#: the realistic units (docs/error_sources.md) spread as their designs' lots, and in f0 by a few Hz
#: (a machined and trimmed shell's frequency, a ring's etch: sim-hrg-thermal-4 puts four in one chamber)
SPREADS["hrg-realistic"] = [*SPREADS["hrg"], ("f0_hz", 5503.2, 1.5, 5490.0)]
SPREADS["mems-realistic"] = [*SPREADS["mems"], ("f0_hz", PRESETS["mems-realistic"].f0_hz, 20.0,
                                                PRESETS["mems-realistic"].f0_hz - 150.0)]
OUT_OF_SPEC_EVERY = 4  # unit 2, 6, 10 ... has one parameter pushed out of the limits


@dataclass(frozen=True)
class DrawnUnit:
    serial: str
    params: Any  # ResonatorParams
    pushed: str | None  # the parameter pushed out of spec on purpose


def draw_units(preset_name: str, n: int, seed: int, lot: str) -> list[DrawnUnit]:
    """n units around a preset, reproducible from the seed."""
    base = PRESETS[preset_name]
    spread = SPREADS[preset_name]
    rng = np.random.default_rng(seed)
    units = []
    for i in range(n):
        values = {name: float(abs(rng.normal(mean, sd))) for name, mean, sd, _ in spread}
        pushed = None
        if i % OUT_OF_SPEC_EVERY == 1:
            name, _, _, out = spread[(i // OUT_OF_SPEC_EVERY) % len(spread)]
            values[name], pushed = out, name
        units.append(DrawnUnit(f"{lot}-{i + 1:03d}", replace(base, **values), pushed))
    return units
