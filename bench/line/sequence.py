"""A line sequence (TOML): the procedures a unit goes through, their parameters, stop-on-fail and
the retest policy, so a line engineer writes a new one without Python.

    [sequence]
    name = "eol-mems"
    station = "sim-mems"           # default station (--station overrides)
    limits = "mems"                # default product limits (--limits overrides)
    stop_on_fail = true            # skip the remaining steps once a step FAILs or ERRORs

    [retest]
    max_attempts = 2               # attempts of one unit in one `line run` (1 = no retest)
    on = ["MARGINAL", "ERROR"]     # unit outcomes that start another attempt

    [trims]
    write = true                   # last step, PASS units only: the compensation into the FPGA's NVM,
                                   # read back, its unit id checked (bench/line/trims.py)

    [[step]]
    procedure = "mems-sweep"       # a registered procedure (`gyrobench list`)
    [step.params]                  # parameter overrides, checked as `--set` is
    n_points = 41
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import LineError
from .tomlfile import find_file, read_toml, table
from .verdict import ABORTED, ERROR, FAIL, MARGINAL, PASS

RETEST_OUTCOMES = (MARGINAL, FAIL, ERROR, ABORTED)
SEQ_KEYS = {
    "name": (str, "", None, None, None, True),
    "description": (str, "", None, None, None, False),
    "station": (str, "", None, None, None, False),
    "limits": (str, "", None, None, None, False),
    "stop_on_fail": (bool, True, None, None, None, False),
}
RETEST_KEYS = {
    "max_attempts": (int, 1, 1, 10, None, False),
    "on": (list, [], None, None, None, False),
}
TRIMS_KEYS = {
    "write": (bool, False, None, None, None, False),
}
STEP_KEYS = {
    "procedure": (str, "", None, None, None, True),
    "name": (str, "", None, None, None, False),
    "stop_on_fail": (bool, None, None, None, None, False),
    "params": (dict, {}, None, None, None, False),
}


@dataclass(frozen=True)
class Step:
    """One procedure of a sequence with its checked parameters."""

    procedure: str
    label: str
    params: dict[str, Any]
    stop_on_fail: bool

    def make(self):
        """A fresh procedure instance with this step's parameters."""
        from procedures import find_procedure

        return find_procedure(self.procedure)(dict(self.params))


@dataclass(frozen=True)
class Sequence:
    """A checked sequence file."""

    source: str
    name: str
    description: str
    station: str
    limits: str
    steps: tuple[Step, ...]
    max_attempts: int = 1
    retest_on: tuple[str, ...] = field(default_factory=tuple)
    write_trims: bool = False  # [trims] write: the compensation into the unit's NVM as the last step

    def requires(self) -> set[str]:
        from procedures import find_procedure

        return {r for s in self.steps for r in find_procedure(s.procedure).requires}


def load_sequence(name_or_path: str | Path) -> Sequence:
    """Read and check a sequence (a shipped name such as `eol-hrg`, or a path); LineError names the
    file, the table, the key, the value and what was allowed."""
    from bench.engine.params import ParamError
    from procedures import ProcedureNotFound, all_procedures, find_procedure

    path = find_file(name_or_path, "sequences", "sequence")
    raw = read_toml(path)
    for top in raw:
        if top not in ("sequence", "retest", "trims", "step"):
            raise LineError(f"{path}: unknown table [{top}] (allowed: sequence, retest, trims, [[step]])")
    if "sequence" not in raw:
        raise LineError(f'{path}: missing table [sequence] with name = "..."')
    seq = table(f"{path}: [sequence]", raw["sequence"], SEQ_KEYS, name="sequence")
    retest = table(f"{path}: [retest]", raw.get("retest", {}), RETEST_KEYS, name="retest")
    trims = table(f"{path}: [trims]", raw.get("trims", {}), TRIMS_KEYS, name="trims")
    for o in retest["on"]:
        if o not in RETEST_OUTCOMES:
            raise LineError(f"{path}: [retest] on={o!r} is not one of {', '.join(RETEST_OUTCOMES)}")
    if PASS in retest["on"]:
        raise LineError(f"{path}: [retest] on: a PASS is never retested")
    steps_raw = raw.get("step")
    if not isinstance(steps_raw, list) or not steps_raw:
        raise LineError(f"{path}: missing [[step]] (at least one procedure)")
    steps = []
    for i, body in enumerate(steps_raw, 1):
        where = f"{path}: [[step]] #{i}"
        t = table(where, body, STEP_KEYS, name="step")
        try:
            cls = find_procedure(t["procedure"])
        except ProcedureNotFound:
            raise LineError(f"{where} procedure={t['procedure']!r} is not one of "
                            f"{', '.join(all_procedures())}") from None
        try:
            proc = cls(dict(t["params"]))
        except ParamError as exc:
            raise LineError(f"{where} [step.params] {exc}") from None
        stop = seq["stop_on_fail"] if t["stop_on_fail"] is None else t["stop_on_fail"]
        del proc  # built only to check the parameters
        steps.append(Step(cls.name, t["name"] or cls.name, dict(t["params"]), stop))
    return Sequence(str(path), seq["name"], seq["description"], seq["station"], seq["limits"], tuple(steps),
                    retest["max_attempts"], tuple(retest["on"]), trims["write"])
