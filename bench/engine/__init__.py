"""The procedure engine: events, typed parameters, procedures as named steps, the runner and
the safe state.  See `bench.engine.procedure` for an example procedure."""

from .context import Devices, GuardedClock, RunAborted, RunContext
from .demands import KINDS, Demand, StationMismatch, check_station
from .measurement import ABORTED, COMPLETE, ERROR, FAIL, MARGINAL, OUTCOMES, PASS, Limits, Result, combine_outcomes
from .params import Param, ParamError
from .procedure import Procedure, step
from .runner import Runner, RunRecord, software_version
from .safety import SAFE_ORDER, SafeStateReport, bring_to_safe_state

__all__ = [
    "ABORTED",
    "KINDS",
    "Demand",
    "StationMismatch",
    "check_station",
    "COMPLETE",
    "ERROR",
    "FAIL",
    "MARGINAL",
    "OUTCOMES",
    "PASS",
    "SAFE_ORDER",
    "Devices",
    "GuardedClock",
    "Limits",
    "Param",
    "ParamError",
    "Procedure",
    "Result",
    "RunAborted",
    "RunContext",
    "RunRecord",
    "Runner",
    "SafeStateReport",
    "bring_to_safe_state",
    "combine_outcomes",
    "software_version",
    "step",
]
