"""The nominal values a procedure assumes of a product (its data sheet), apart from any unit's truth.

A procedure that needs the Bryan factor K or the natural frequency f0 takes them from its station's
nominal values (`Station.nominal`: this table for the station's kind, with the station file's
`[nominal]` table over it), never from the simulator: a simulated unit's true values may differ
from these by the unit-to-unit spread a real lot shows (docs/error_sources.md), and a procedure
that relies on a nominal value then shows the error it causes.  Bottom layer: imports nothing of
the engine, the drivers or the simulators.
"""

from __future__ import annotations

import math

#: the nominal keys a station's `[nominal]` table may set, with what each is
NOMINAL_KEYS: dict[str, str] = {
    "bryan_factor": "Bryan factor K of the design (the wave turns at -K Omega)",
    "f0_hz": "natural frequency of the design (Hz)",
    "pickoff_gain": "pickoff chain gain assumed (1 = as calibrated)",
    "forcer_gain": "forcer (drive and control) chain gain assumed (1 = as calibrated)",
}

#: Maslov et al.'s MEMS ring: w = 85732 1/s (docs/free_decay_identification.md)
_MEMS_F0_HZ = 85732.0 / (2.0 * math.pi)

#: per kind of gyro (bench.station_config kinds): the data-sheet values
PRODUCT_NOMINAL: dict[str, dict[str, float]] = {
    # a thin hemispherical shell, n = 2: K = 0.277 (PHYSICS.md section 6); the 5.5 kHz design
    "hrg": {"bryan_factor": 0.277, "f0_hz": 5500.0, "pickoff_gain": 1.0, "forcer_gain": 1.0},
    # a thin ring, n = 2: K = 0.4 (Maslov et al.)
    "mems-ring": {"bryan_factor": 0.4, "f0_hz": _MEMS_F0_HZ, "pickoff_gain": 1.0, "forcer_gain": 1.0},
}


def nominal_for(kind: str, overrides: dict[str, float] | None = None) -> dict[str, float]:
    """The nominal values of a kind of gyro ('' = unknown: the HRG's), with a station's overrides."""
    base = dict(PRODUCT_NOMINAL.get(kind) or PRODUCT_NOMINAL["hrg"])
    return base | dict(overrides or {})
