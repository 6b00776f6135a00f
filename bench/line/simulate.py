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

from typing import Any

import numpy as np

from simulators.lot import SPREADS, DrawnUnit, draw_units

from .verdict import ERROR, FAIL, MARGINAL, PASS


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


def draw_lot(preset: str, n: int, seed: int, lot: str) -> list[DrawnUnit]:
    """n units of a simulated lot around `preset` (simulators.lot); ValueError naming the presets
    that have a spread when `preset` has none."""
    if preset not in SPREADS:
        raise ValueError(f"preset {preset!r} has no spread to draw units from (known: {', '.join(SPREADS)})")
    return draw_units(preset, n, seed, lot)


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
    from bench.composition.sim_station import SimStation
    from bench.station_config import load_config

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
    from bench.composition.sim_batch_station import SimBatchStation
    from simulators.physics.params import preset

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
