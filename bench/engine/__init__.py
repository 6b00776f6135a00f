"""The procedure engine: events, typed parameters, procedures as named steps, the runner and
the safe state.  See `bench.engine.procedure` for an example procedure."""

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

_WHERE = {  # name -> the module that defines it, imported on first use (PEP 562)
    "Devices": "context",
    "GuardedClock": "context",
    "RunAborted": "context",
    "RunContext": "context",
    "KINDS": "demands",
    "Demand": "demands",
    "StationMismatch": "demands",
    "check_station": "demands",
    "ABORTED": "measurement",
    "COMPLETE": "measurement",
    "ERROR": "measurement",
    "FAIL": "measurement",
    "MARGINAL": "measurement",
    "NOT_MEASURED": "measurement",
    "OUTCOMES": "measurement",
    "PASS": "measurement",
    "Limits": "measurement",
    "Measurement": "measurement",
    "MeasurementError": "measurement",
    "Result": "measurement",
    "combine_outcomes": "measurement",
    "Param": "params",
    "ParamError": "params",
    "Procedure": "procedure",
    "step": "procedure",
    "EXCLUDE": "recording",
    "RESTART": "recording",
    "RecordSpan": "recording",
    "recorded_length_s": "recording",
    "recorded_text": "recording",
    "Runner": "runner",
    "RunRecord": "runner",
    "software_version": "runner",
    "SAFE_ORDER": "safety",
    "SafeStateReport": "safety",
    "bring_to_safe_state": "safety",
}


def __getattr__(name: str) -> Any:
    """A name of the engine's API from its module on first use: reading a run's file (the report,
    bench.recorder) imports only what it uses, not the runner with every driver and numba."""
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


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
