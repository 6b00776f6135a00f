"""A campaign's summary: for each measurement with a truth, over the runs that measured it, the
bias, the scatter, std/CRLB where the procedure states a bound, and the coverage of the 95 %
interval against its binomial band (scipy.stats).  Pure: results in, rows out, in a fixed order
(runs by index, measurements by first appearance), so two executions of the same runs give the
same summary bit for bit whatever order the runs finished in."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

#: the interval whose coverage is counted
NOMINAL = 0.95
#: outcomes of runs that did not measure: left out of the summary (they are counted)
NOT_MEASURED = ("ERROR", "ABORTED", "INTERRUPTED")


@dataclass(frozen=True)
class MeasurementSummary:
    """One measurement over a campaign's runs (errors are value - truth)."""

    name: str
    unit: str
    n: int  # runs with a finite value and a truth
    bias: float  # mean error
    bias_ci95: float  # half width of the bias's 95 % interval (t, n - 1)
    std: float  # scatter of the errors (ddof 1)
    rms_error: float
    std_over_crlb: float | None  # std / rms of the stated bound, when the procedure states one
    n_ci: int  # runs with an interval
    coverage: float | None  # fraction of the 95 % intervals that hold the truth
    band_low: float | None  # the binomial band of that fraction for n_ci runs at 0.95
    band_high: float | None
    covered: bool | None  # coverage inside the band

    def as_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


def binomial_band(n: int, level: float = 0.95, p: float = NOMINAL) -> tuple[float, float]:
    """The central `level` band of the fraction of n intervals of nominal coverage p that hold the truth."""
    low, high = stats.binom.interval(level, n, p)
    return float(low) / n, float(high) / n


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def measurement_names(results: list[dict[str, Any]], wanted: tuple[str, ...] | None = None) -> list[str]:
    """The measurements with a truth in any run, in order of first appearance (or those wanted)."""
    seen: dict[str, None] = {}
    for r in sorted(results, key=lambda r: r["index"]):
        for name in r.get("values", {}):
            if name in r.get("truth", {}):
                seen.setdefault(name)
    names = list(seen)
    return names if wanted is None else [n for n in wanted if n in seen]


def summarise(results: list[dict[str, Any]], wanted: tuple[str, ...] | None = None,
              band: float = 0.95) -> list[MeasurementSummary]:
    """The summary rows of a campaign's results (each a dict as bench.campaign.execute returns)."""
    ordered = sorted((r for r in results if r["outcome"] not in NOT_MEASURED), key=lambda r: r["index"])
    rows = []
    for name in measurement_names(ordered, wanted):
        err, bounds, hits = [], [], []
        unit = ""
        for r in ordered:
            value, truth = r.get("values", {}).get(name), r.get("truth", {}).get(name)
            if not (_finite(value) and _finite(truth)):
                continue
            unit = r.get("units", {}).get(name, unit)
            err.append(value - truth)
            bound = r.get("crlb", {}).get(name)
            if _finite(bound) and bound > 0:
                bounds.append(bound)
            ci = r.get("ci95", {}).get(name)
            if ci is not None and _finite(ci[0]) and _finite(ci[1]):
                hits.append(ci[0] <= truth <= ci[1])
        e = np.asarray(err, dtype=float)
        n = e.size
        std = float(e.std(ddof=1)) if n > 1 else math.nan
        half = float(stats.t.ppf(0.975, n - 1) * std / math.sqrt(n)) if n > 1 else math.nan
        crlb = float(np.sqrt(np.mean(np.square(bounds)))) if len(bounds) == n and n > 1 else None
        cov = lo = hi = covered = None
        if hits:
            cov = float(np.mean(hits))
            lo, hi = binomial_band(len(hits), band)
            covered = lo <= cov <= hi
        rows.append(MeasurementSummary(
            name=name, unit=unit, n=n, bias=float(e.mean()) if n else math.nan, bias_ci95=half, std=std,
            rms_error=float(np.sqrt(np.mean(e * e))) if n else math.nan,
            std_over_crlb=None if crlb is None else std / crlb, n_ci=len(hits), coverage=cov,
            band_low=lo, band_high=hi, covered=covered))
    return rows


def counts(results: list[dict[str, Any]]) -> dict[str, int]:
    """How many runs ended how (COMPLETE, PASS, ERROR ...)."""
    out: dict[str, int] = {}
    for r in results:
        out[r["outcome"]] = out.get(r["outcome"], 0) + 1
    return dict(sorted(out.items()))
