"""The procedure engine: events, typed parameters, procedures as named steps, the runner and
the safe state.  See `bench.engine.procedure` for an example procedure."""

from .context import Devices, GuardedClock, RunAborted, RunContext
from .demands import KINDS, Demand, StationMismatch, check_station
from .measurement import (
    ABORTED,
    COMPLETE,
    ERROR,
    FAIL,
    MARGINAL,
    NOT_MEASURED,
    OUTCOMES,
    PASS,
    Limits,
    Measurement,
    MeasurementError,
    Result,
    combine_outcomes,
)
from .params import Param, ParamError
from .procedure import Procedure, step
from .recording import EXCLUDE, RESTART, RecordSpan, recorded_length_s, recorded_text
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
    "EXCLUDE",
    "RESTART",
    "RecordSpan",
    "recorded_length_s",
    "recorded_text",
    "FAIL",
    "MARGINAL",
    "OUTCOMES",
    "PASS",
    "SAFE_ORDER",
    "Devices",
    "GuardedClock",
    "Limits",
    "Measurement",
    "MeasurementError",
    "NOT_MEASURED",
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
