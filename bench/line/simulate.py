"""A simulated production lot: units drawn from a spread of resonator parameters around a preset
(some pushed out of spec on purpose), each run through a sequence on its own simulated station,
and the check that every outcome is right for the unit's drawn truth.

The check, per limited measurement with a true value: a truth inside the limits by more than its
interval's width (U below + U above: an interval that covers the truth reaches at most that far
from it) must PASS; a truth outside by more than that width must FAIL; the rest may be MARGINAL.
A unit must PASS when all its truths must, and FAIL when any must.  A limited measurement without a
true value (the drift left after compensation) that FAILs or is MARGINAL leaves the unit's outcome
to the line: truth cannot say what it must be (`undecided` counts those units)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .verdict import ERROR, FAIL, MARGINAL, PASS

#: per preset: (parameter, mean, sd, out-of-spec value pushed to) -- sd chosen so that a few
#: units of a lot fall out of the shipped limits by chance, besides those pushed out on purpose
SPREADS: dict[str, list[tuple[str, float, float, float]]] = {
    "hrg": [("tau_s", 300.0, 25.0, 215.0), ("delta_inv_tau_per_s", 1.6e-4, 0.3e-4, 3.2e-4),
            ("split_hz", 0.005, 0.001, 0.0105)],
    "mems": [("tau_s", 0.04648, 0.0015, 0.0395), ("split_hz", 2.75, 0.15, 3.7)],
}
OUT_OF_SPEC_EVERY = 4  # unit 2, 6, 10 ... has one parameter pushed out of the limits


@dataclass(frozen=True)
class DrawnUnit:
    serial: str
    params: Any  # ResonatorParams
    pushed: str | None  # the parameter pushed out of spec on purpose


def draw_units(preset_name: str, n: int, seed: int, lot: str) -> list[DrawnUnit]:
    """n units around a preset, reproducible from the seed."""
    from simulators.physics.params import PRESETS

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


def expected_outcome(record: dict[str, Any]) -> tuple[str | None, list[str]]:
    """What the unit's outcome must be from its truths: PASS, FAIL, or None (MARGINAL allowed,
    or either); and why, per measurement."""
    must_fail, all_pass, why = False, True, []
    for m in record["measurements"]:
        if m.get("rule") and m.get("truth") is None and m["outcome"] in (FAIL, MARGINAL):
            all_pass = False  # decided by a measurement without a true value: truth cannot say
            why.append(f"{m['name']} {m['outcome']} has no true value")
        if not m.get("rule") or m.get("truth") is None:
            continue
        lim = m["limits"] or {}
        width = (m.get("u_low") or 0.0) + (m.get("u_high") or 0.0)
        t, lo, hi = m["truth"], lim.get("low"), lim.get("high")
        inside = min(t - lo if lo is not None else np.inf, hi - t if hi is not None else np.inf)
        if inside > width:
            continue
        all_pass = False
        if -inside > width:
            must_fail = True
            why.append(f"{m['name']} truth {t:.6g} outside by {-inside:.3g} > {width:.3g}")
        else:
            why.append(f"{m['name']} truth {t:.6g} within {width:.3g} of a limit")
    if must_fail:
        return FAIL, why
    return (PASS if all_pass else None), why


def check_lot(records: list[dict[str, Any]]) -> list[str]:
    """The units whose final outcome is wrong for their truth (empty: the line decided right)."""
    last: dict[str, dict[str, Any]] = {}
    for r in records:
        if r["serial"] not in last or r["attempt"] > last[r["serial"]]["attempt"]:
            last[r["serial"]] = r
    wrong = []
    for serial, r in last.items():
        want, why = expected_outcome(r)
        got = r["outcome"]
        ok = got != ERROR and (want is None and got in (PASS, FAIL, MARGINAL) or got == want)
        if not ok:
            wrong.append(f"{serial}: {got}, expected {want or 'PASS/FAIL/MARGINAL'} ({'; '.join(why) or 'in spec'})")
    return wrong


def undecided(records: list[dict[str, Any]]) -> list[str]:
    """Serials whose final outcome was decided by a limited measurement that has no true value."""
    last: dict[str, dict[str, Any]] = {}
    for r in records:
        last[r["serial"]] = r
    return [s for s, r in last.items() if any(m.get("rule") and m.get("truth") is None and m["outcome"] in
                                              (FAIL, MARGINAL) and m["outcome"] == r["outcome"]
                                              for m in r["measurements"])]


def simulate_lot(ctx: Any, station_file: str, units: list[DrawnUnit], seed: int, operator: Any) -> list[dict]:
    """Each unit through the sequence on its own simulated station (on a station with slots, as many
    units at once as it has slots); every attempt's record."""
    from bench.station_config import load_config
    from simulators.station_sim import SimStation

    from .run import run_unit

    config = load_config(station_file)
    if config.slots:
        return _simulate_batches(ctx, config, units, seed, operator)

    records: list[dict] = []
    for i, unit in enumerate(units):
        attempt_seed = iter(range(1000))

        def open_station(u=unit, i=i, k=attempt_seed):
            return SimStation(station_file, seed=seed * 10007 + i * 101 + next(k), resonator=u.params)

        first = ctx.db.next_attempt(unit.serial) if ctx.db is not None else 1
        records.extend(run_unit(ctx, open_station, unit.serial, operator, first_attempt=first))
        if ctx.aborted:
            break
    return records


def _simulate_batches(ctx: Any, config: Any, units: list[DrawnUnit], seed: int, operator: Any) -> list[dict]:
    """The lot in batches of the station's slots: each batch on a fresh simulated several-gyros
    station whose slots hold the batch's drawn resonators (a last, short batch leaves slots empty:
    their resonators are the preset's, with no unit judged)."""
    from simulators.physics.params import preset
    from simulators.rig_station import SimBatchStation

    from .batch_run import run_batch_attempt

    n_slots = len(config.slots)
    records: list[dict] = []
    for b, first in enumerate(range(0, len(units), n_slots)):
        group = units[first:first + n_slots]
        params = [u.params for u in group] + [preset(config.simulation["preset"])] * (n_slots - len(group))
        station = SimBatchStation(config, seed=seed * 10007 + b * 101, resonators=params).open()
        try:
            serials = {k + 1: u.serial for k, u in enumerate(group)}
            attempts = {u.serial: ctx.db.next_attempt(u.serial) if ctx.db is not None else 1 for u in group}
            records.extend(run_batch_attempt(ctx, station, serials, operator, attempts))
        finally:
            station.close()
        if ctx.aborted:
            break
    return records
