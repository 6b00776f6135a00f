"""Measurements with units, optional limits and a marginal band, and the run outcome they give.

`Limits(low, high, marginal_low=None, marginal_high=None)`: a value outside [low, high] FAILs;
inside, but below marginal_low or above marginal_high (a band just inside the limits), is
MARGINAL; otherwise PASS.  No limits: COMPLETE.  NaN against limits FAILs.

`Measurement(name, unit, doc, truth=..., limits=..., when=...)`: what a procedure declares up front
(class attribute `measurements`), as OpenHTF declares measurements on a phase.  A reported Result
must carry a declared name and the declared unit; it takes the declaration's doc and default limits.
A declaration whose condition holds but that was never reported is recorded as NOT_MEASURED.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

PASS, FAIL, MARGINAL, COMPLETE, ERROR, ABORTED = "PASS", "FAIL", "MARGINAL", "COMPLETE", "ERROR", "ABORTED"
# a run's row in the results store while it runs, and once its process is gone without a record
RUNNING, INTERRUPTED = "RUNNING", "INTERRUPTED"
# a declared measurement (whose condition held) that the run never reported
NOT_MEASURED = "NOT_MEASURED"
OUTCOMES = (PASS, FAIL, MARGINAL, COMPLETE, ERROR, ABORTED, RUNNING, INTERRUPTED, NOT_MEASURED)


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

    def marginal_list(self) -> list[float | None] | None:
        """[marginal_low, marginal_high], or None without a marginal band."""
        if self.marginal_low is None and self.marginal_high is None:
            return None
        return [self.marginal_low, self.marginal_high]


@dataclass(frozen=True)
class Result:
    """One measured value: what a procedure's analysis hook returns and `ctx.measure` records."""

    name: str
    value: float
    unit: str | None = None  # None: the declaration's unit (filled in when reported)
    ci95: tuple[float, float] | None = None
    limits: Limits | None = None
    dut: str | None = None
    doc: str = ""
    measured: bool = True  # False: declared, never reported (outcome NOT_MEASURED, value NaN)

    def __post_init__(self) -> None:
        object.__setattr__(self, "limits", Limits.of(self.limits))  # accept (low, high) too

    @property
    def outcome(self) -> str:
        if not self.measured:
            return NOT_MEASURED
        return COMPLETE if self.limits is None else self.limits.evaluate(self.value)

    def as_json(self) -> dict[str, Any]:
        lim = self.limits
        return {
            "value": _num(self.value),
            "unit": self.unit or "",
            "ci95": None if self.ci95 is None else [_num(self.ci95[0]), _num(self.ci95[1])],
            "limits": None if lim is None else lim.as_list(),
            "marginal": None if lim is None else lim.marginal_list(),
            "outcome": self.outcome,
        }


class MeasurementError(ValueError):
    """A reported measurement that its procedure did not declare, or in another unit."""


TruthRule = str | Callable[[Mapping[str, float]], float] | None


@dataclass(frozen=True)
class Measurement:
    """A measurement a procedure declares: its stable public name, unit ('' = dimensionless), what
    it is, how the simulator's truth gives its true value (a key of the station's truth dict or a
    function of that dict; None: no truth), default limits (Limits, a tuple, or a function of the
    procedure) and the condition (a function of the procedure) under which the run measures it."""

    name: str
    unit: str
    doc: str
    truth: TruthRule = None
    limits: Limits | tuple | Callable[[Any], Any] | None = None
    when: Callable[[Any], bool] | None = None
    when_doc: str = ""  # the condition in words, for `gyrobench list` and the docs' reference
    period: float | None = None  # a periodic quantity (an axis angle: 90 deg): truth compared modulo it
    no_interval: str = ""  # why the value comes without a 95 % interval (shown where the interval would be)
    no_truth: str = ""  # why no simulator truth is compared with it (shown where the truth would be)

    def applies(self, proc: Any) -> bool:
        """Whether the run measures it (its condition, on the procedure's parameters and state)."""
        return self.when is None or bool(self.when(proc))

    def limits_for(self, proc: Any) -> Limits | None:
        lim = self.limits(proc) if callable(self.limits) else self.limits
        return Limits.of(lim)

    def truth_of(self, truth: Mapping[str, float] | None) -> float | None:
        """The true value on a simulated station (None without truth, or when the rule does not apply)."""
        if truth is None or self.truth is None:
            return None
        try:
            value = truth[self.truth] if isinstance(self.truth, str) else self.truth(truth)
        except (KeyError, TypeError, ValueError, ZeroDivisionError):
            return None
        return None if value is None else float(value)

    def resolve(self, res: Result, proc: Any, procedure_name: str) -> Result:
        """The reported Result with the declared unit, doc and (unless given) default limits."""
        if res.unit is not None and res.unit != self.unit:
            raise MeasurementError(
                f"measurement {res.name!r} of procedure {procedure_name!r} reported in {res.unit!r}; "
                f"it is declared in {self.unit!r}"
            )
        limits = res.limits if res.limits is not None else self.limits_for(proc)
        return replace(res, unit=self.unit, doc=self.doc, limits=limits)

    def not_measured(self, proc: Any, dut: str | None = None) -> Result:
        return Result(self.name, math.nan, self.unit, limits=self.limits_for(proc), dut=dut, doc=self.doc,
                      measured=False)

    def describe(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "unit": self.unit,
            "doc": self.doc,
            "truth": self.truth if isinstance(self.truth, str) or self.truth is None else "(computed)",
            "condition": self.when_doc or ("" if self.when is None else "(conditional)"),
            **({"period": self.period} if self.period is not None else {}),
            **({"no_interval": self.no_interval} if self.no_interval else {}),
            **({"no_truth": self.no_truth} if self.no_truth else {}),
        }


def _num(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def combine_outcomes(outcomes: Iterable[str]) -> str:
    """Worst of the measurement outcomes: FAIL > MARGINAL > PASS > COMPLETE (nothing limited);
    NOT_MEASURED does not count here (the runner makes a limited one that was not measured FAIL)."""
    seen = set(outcomes)
    for o in (FAIL, MARGINAL, PASS):
        if o in seen:
            return o
    return COMPLETE
