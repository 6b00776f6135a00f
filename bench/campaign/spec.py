"""A campaign file (TOML) read and checked, and expanded into its runs in a fixed order.

The study: the procedure(s), the station (and preset), fixed procedure parameters, grids of
procedure parameters and of the simulated unit's true parameters (every combination), seeded
random draws of the unit's true parameters (one draw a run), the seeds, and what to summarise.
The expansion is deterministic: the same file gives the same runs with the same ids, which is
what makes a campaign resumable (docs/campaigns.md gives the format).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,39}$")
#: the distributions a unit parameter may be drawn from, with their arguments' meaning
DISTRIBUTIONS = {"normal": "[mean, std]", "uniform": "[low, high]", "lognormal": "[median, sigma of the log]"}
TOP_KEYS = {"campaign", "params", "unit", "vary", "draw", "seeds", "summary"}


class CampaignError(ValueError):
    """A campaign file that cannot be run as written: the message names the key."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a campaign: what a worker needs to make it a normal run."""

    run_id: str
    index: int
    procedure: str
    station: str
    preset: str | None
    params: dict[str, Any]
    unit: dict[str, float]
    seed: int
    varied: dict[str, Any]  # the grid's and the draws' values of this run, by "params.x" / "unit.x"

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class Campaign:
    """A checked campaign file."""

    id: str
    source: str
    procedures: tuple[str, ...]
    station: str
    preset: str | None
    params: dict[str, Any]
    grid_params: dict[str, list[Any]]
    grid_unit: dict[str, list[float]]
    unit: dict[str, float]
    draws: dict[str, tuple[str, tuple[float, float]]]
    draw_seed: int
    seeds: tuple[int, ...]
    measurements: tuple[str, ...] | None  # None: every measurement with a truth
    band: float = 0.95
    fingerprint: str = field(default="")

    def runs(self) -> list[RunSpec]:
        """Every run, in a fixed order: procedure, then the grid (in the file's key order), then seed."""
        p_names, u_names = list(self.grid_params), list(self.grid_unit)
        combos = list(itertools.product(*(self.grid_params[n] for n in p_names),
                                        *(self.grid_unit[n] for n in u_names)))
        out: list[RunSpec] = []
        index = 0
        for proc in self.procedures:
            for combo in combos:
                gp = dict(zip(p_names, combo[:len(p_names)], strict=True))
                gu = dict(zip(u_names, combo[len(p_names):], strict=True))
                for seed in self.seeds:
                    drawn = self._draw(index)
                    varied = {**{f"params.{k}": v for k, v in gp.items()},
                              **{f"unit.{k}": v for k, v in {**gu, **drawn}.items()}}
                    out.append(RunSpec(
                        run_id=f"{self.id}-{index:05d}", index=index, procedure=proc, station=self.station,
                        preset=self.preset, params={**self.params, **gp}, unit={**self.unit, **gu, **drawn},
                        seed=seed, varied=varied))
                    index += 1
        return out

    def _draw(self, index: int) -> dict[str, float]:
        """This run's draws of the unit's true parameters: a generator of its own per run (the draw
        seed and the run's index), so a run's draw does not depend on which runs came before."""
        if not self.draws:
            return {}
        rng = np.random.default_rng([self.draw_seed, index])
        out = {}
        for name, (dist, (a, b)) in self.draws.items():
            if dist == "normal":
                out[name] = float(rng.normal(a, b))
            elif dist == "uniform":
                out[name] = float(rng.uniform(a, b))
            else:  # lognormal: median a, log-sigma b
                out[name] = float(a * np.exp(rng.normal(0.0, b)))
        return out


def _table(doc: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise CampaignError(f"{where}: [{key}] must be a table")
    return value


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise CampaignError(f"{where}: {value!r} is not a finite number")
    return float(value)


def _grid(table: dict[str, Any], where: str, numbers: bool) -> dict[str, list[Any]]:
    out = {}
    for name, values in table.items():
        if not isinstance(values, list) or not values:
            raise CampaignError(f"{where}.{name}: a grid is a non-empty list of values")
        out[name] = [_number(f"{where}.{name}", v) for v in values] if numbers else list(values)
    return out


def _seeds(doc: dict[str, Any], where: str) -> tuple[int, ...]:
    seeds = doc.get("seeds", [0])
    if isinstance(seeds, dict):
        unknown = set(seeds) - {"start", "count"}
        if unknown or "count" not in seeds:
            raise CampaignError(f"{where}: [seeds] takes start and count (or seeds = [list]); got {sorted(seeds)}")
        start, count = seeds.get("start", 0), seeds["count"]
        if not (isinstance(start, int) and isinstance(count, int) and start >= 0 and count >= 1):
            raise CampaignError(f"{where}: [seeds] start >= 0 and count >= 1 must be integers")
        return tuple(range(start, start + count))
    if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and s >= 0 for s in seeds):
        raise CampaignError(f"{where}: seeds must be a list of integers >= 0 or a table {{start, count}}")
    if len(set(seeds)) != len(seeds):
        raise CampaignError(f"{where}: seeds repeat a seed (the same run twice)")
    return tuple(seeds)


def _draws(table: dict[str, Any], where: str) -> dict[str, tuple[str, tuple[float, float]]]:
    out = {}
    for name, rule in table.items():
        if not (isinstance(rule, dict) and len(rule) == 1 and next(iter(rule)) in DISTRIBUTIONS):
            known = ", ".join(f"{d} = {a}" for d, a in DISTRIBUTIONS.items())
            raise CampaignError(f"{where}.unit.{name}: one distribution, e.g. {{ normal = [300.0, 20.0] }} ({known})")
        dist, args = next(iter(rule.items()))
        if not (isinstance(args, list) and len(args) == 2):
            raise CampaignError(f"{where}.unit.{name}: {dist} takes two numbers {DISTRIBUTIONS[dist]}")
        a, b = (_number(f"{where}.unit.{name}", x) for x in args)
        if (dist in ("normal", "lognormal") and b < 0) or (dist == "uniform" and b < a):
            raise CampaignError(f"{where}.unit.{name}: {dist} {DISTRIBUTIONS[dist]} = {args} is not a distribution")
        out[name] = (dist, (a, b))
    return out


def parse_campaign(doc: dict[str, Any], source: str = "<campaign>") -> Campaign:
    """Check a campaign document (the TOML file's tables); CampaignError names what is wrong."""
    unknown = set(doc) - TOP_KEYS
    if unknown:
        raise CampaignError(f"{source}: unknown table(s) {sorted(unknown)}; known: {sorted(TOP_KEYS)}")
    head = _table(doc, "campaign", source)
    procs = head.get("procedures", [head["procedure"]] if "procedure" in head else [])
    if not procs or not all(isinstance(p, str) and p for p in procs):
        raise CampaignError(f"{source}: [campaign] needs procedure = \"name\" (or procedures = [...])")
    station = head.get("station", "sim-hrg")
    preset = head.get("preset")
    vary, draw = _table(doc, "vary", source), _table(doc, "draw", source)
    if set(vary) - {"params", "unit"}:
        raise CampaignError(f"{source}: [vary] holds [vary.params] and [vary.unit] only")
    if set(draw) - {"seed", "unit"}:
        raise CampaignError(f"{source}: [draw] holds seed and [draw.unit] only")
    fixed_unit = _table(doc, "unit", source)
    summary = _table(doc, "summary", source)
    band = _number(f"{source} [summary] band", summary.get("band", 0.95))
    if not 0.5 <= band < 1.0:
        raise CampaignError(f"{source}: [summary] band = {band} must be in [0.5, 1)")
    names = summary.get("measurements")
    if names is not None and not (isinstance(names, list) and all(isinstance(n, str) for n in names)):
        raise CampaignError(f"{source}: [summary] measurements must be a list of names")
    draw_seed = draw.get("seed", 0)
    if not isinstance(draw_seed, int) or draw_seed < 0:
        raise CampaignError(f"{source}: [draw] seed must be an integer >= 0")
    study = {k: doc.get(k) for k in ("campaign", "params", "unit", "vary", "draw", "seeds")}
    fingerprint = hashlib.sha256(json.dumps(study, sort_keys=True, default=str).encode()).hexdigest()[:12]
    cid = head.get("id", f"c{fingerprint[:10]}")
    if not isinstance(cid, str) or not ID_RE.match(cid):
        raise CampaignError(f"{source}: [campaign] id = {cid!r}: 1 to 40 letters, digits, '.', '_' or '-'")
    grid_unit = _grid(_table(vary, "unit", source), f"{source} [vary.unit]", numbers=True)
    draws = _draws(_table(draw, "unit", source), f"{source} [draw]")
    both = set(grid_unit) & set(draws)
    if both:
        raise CampaignError(f"{source}: unit parameter(s) {sorted(both)} both on a grid and drawn")
    return Campaign(
        id=cid, source=source, procedures=tuple(procs), station=str(station),
        preset=None if preset is None else str(preset), params=_table(doc, "params", source),
        grid_params=_grid(_table(vary, "params", source), f"{source} [vary.params]", numbers=False),
        grid_unit=grid_unit, unit={k: _number(f"{source} [unit] {k}", v) for k, v in fixed_unit.items()},
        draws=draws, draw_seed=draw_seed, seeds=_seeds(doc, source),
        measurements=None if names is None else tuple(names), band=band, fingerprint=fingerprint)


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file."""
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{p}: not valid TOML ({exc})") from None
    return parse_campaign(doc, str(p))
