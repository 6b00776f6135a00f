"""Measurements with units, optional limits and a marginal band, and the run outcome they give.

`Limits(low, high, marginal_low=None, marginal_high=None)`: a value outside [low, high] FAILs;
inside, but below marginal_low or above marginal_high (a band just inside the limits), is
MARGINAL; otherwise PASS.  No limits: COMPLETE.  NaN against limits FAILs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

PASS, FAIL, MARGINAL, COMPLETE, ERROR, ABORTED = "PASS", "FAIL", "MARGINAL", "COMPLETE", "ERROR", "ABORTED"
# a run's row in the results store while it runs, and once its process is gone without a record
RUNNING, INTERRUPTED = "RUNNING", "INTERRUPTED"
OUTCOMES = (PASS, FAIL, MARGINAL, COMPLETE, ERROR, ABORTED, RUNNING, INTERRUPTED)


@dataclass(frozen=True)
class Limits:
    """Inclusive limits with an optional marginal band inside them."""

    low: float | None = None
    high: float | None = None
    marginal_low: float | None = None
    marginal_high: float | None = None

    def __post_init__(self) -> None:
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"Limits low={self.low!r} > high={self.high!r}")

    @classmethod
    def of(cls, limits: Limits | tuple | list | dict | None) -> Limits | None:
        """Accept Limits, (low, high), (low, high, marginal_low, marginal_high) or a dict."""
        if limits is None or isinstance(limits, Limits):
            return limits
        if isinstance(limits, dict):
            return cls(**limits)
        return cls(*limits)

    def evaluate(self, value: float) -> str:
        if not math.isfinite(value):
            return FAIL
        if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
            return FAIL
        if (self.marginal_low is not None and value < self.marginal_low) or (
            self.marginal_high is not None and value > self.marginal_high
        ):
            return MARGINAL
        return PASS

    def as_list(self) -> list[float | None]:
        return [self.low, self.high]


@dataclass(frozen=True)
class Result:
    """One measured value: what a procedure's analysis hook returns and `ctx.measure` records."""

    name: str
    value: float
    unit: str = ""
    ci95: tuple[float, float] | None = None
    limits: Limits | None = None
    dut: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "limits", Limits.of(self.limits))  # accept (low, high) too

    @property
    def outcome(self) -> str:
        return COMPLETE if self.limits is None else self.limits.evaluate(self.value)

    def as_json(self) -> dict[str, Any]:
        lim = self.limits
        return {
            "value": _num(self.value),
            "unit": self.unit,
            "ci95": None if self.ci95 is None else [_num(self.ci95[0]), _num(self.ci95[1])],
            "limits": None if lim is None else lim.as_list(),
            "outcome": self.outcome,
        }


def _num(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def combine_outcomes(outcomes: Iterable[str]) -> str:
    """Worst of the measurement outcomes: FAIL > MARGINAL > PASS > COMPLETE (nothing limited)."""
    seen = set(outcomes)
    for o in (FAIL, MARGINAL, PASS):
        if o in seen:
            return o
    return COMPLETE
