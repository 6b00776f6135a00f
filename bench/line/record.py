"""The unit record: one JSON document per unit and attempt (docs/unit_record.schema.json), and its
export in OpenHTF's JSON test-record layout so OpenHTF's tooling reads our records.

The certificate page renders from this dict: keep the field names."""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
from pathlib import Path
from typing import Any

from bench.validation import range_text

from .verdict import COMPLETE, ERROR, MARGINAL, SKIPPED, Limit, judge

SCHEMA_VERSION = 1
SCHEMA_PATH = Path(__file__).resolve().parents[2] / "docs" / "unit_record.schema.json"


def _num(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def sha256_of(path: str | Path | None) -> str | None:
    """The SHA-256 of a raw file (None when there is none or it cannot be read)."""
    if not path:
        return None
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return None
    return h.hexdigest()


def judged(name: str, procedure: str, run_id: str | None, m: dict[str, Any] | None, limit: Limit | None,
           truth: float | None = None, skipped: bool = False, aborted: str | None = None) -> dict[str, Any]:
    """One measurement of the record: the run's value and interval judged against a product limit.
    m is the run's `as_json()` entry (None: never measured); `aborted` (the run's end reason) makes a
    limit the aborted run never reached SKIPPED, not ERROR: the unit was not tested, not faulty."""
    unit = (m or {}).get("unit", "") if m else (limit.unit or "" if limit else "")
    value = None if m is None else _num(m.get("value"))
    ci = None if m is None else m.get("ci95")
    interval = None if ci is None else [_num(ci[0]), _num(ci[1])]
    lim = None if limit is None else {"low": limit.low, "high": limit.high}
    out: dict[str, Any] = {"name": name, "procedure": procedure, "run_id": run_id, "value": value, "unit": unit,
                           "interval": interval, "limits": lim, "rule": None, "outcome": COMPLETE,
                           "u_low": None, "u_high": None, "note": ""}
    if limit is not None and (limit.marginal_low is not None or limit.marginal_high is not None):
        out["marginal"] = {"low": limit.marginal_low, "high": limit.marginal_high}
    if truth is not None:
        out["truth"] = _num(truth)
    if limit is None:
        return out
    if skipped:
        out.update(rule=limit.rule, outcome=SKIPPED, note="not run: an earlier step stopped the sequence")
    elif aborted is not None and (m is None or m.get("outcome") == "NOT_MEASURED"):
        out.update(rule=limit.rule, outcome=SKIPPED, note=f"not measured: the run ended ({aborted})")
    elif m is None or m.get("outcome") == "NOT_MEASURED":
        out.update(rule=limit.rule, outcome=ERROR, note="named by the limits file, never measured")
    else:
        iv = None if interval is None else (math.nan if interval[0] is None else interval[0],
                                            math.nan if interval[1] is None else interval[1])
        v = judge(math.nan if value is None else value, iv, limit)
        out.update(rule=v.rule, outcome=v.outcome, u_low=_num(v.u_low), u_high=_num(v.u_high), note=v.note)
        if v.condition:
            out["condition"] = v.condition
    return out


def judge_measurements(procedure: str, run_id: str | None, measurements: dict[str, dict[str, Any]],
                       limits: list[Limit], truth: dict[str, float] | None = None,
                       aborted: str | None = None) -> list[dict[str, Any]]:
    """A run's measurements (its `as_json()["measurements"]`) judged against the limits that apply
    to it, one entry each (`judged`): the measured ones in the run's order (a NOT_MEASURED one only
    when a limit names it), then each limit the run never reported.  The one path both the line's
    steps and `gyrobench run --limits` take."""
    by_name = {lim.name: lim for lim in limits}
    truth = truth or {}
    out = []
    for name, m in measurements.items():
        lim = by_name.get(name)
        if lim is None and m.get("outcome") == "NOT_MEASURED":
            continue
        out.append(judged(name, procedure, run_id, m, lim, truth.get(name), aborted=aborted))
    for lim in limits:
        if lim.name not in measurements:
            out.append(judged(lim.name, procedure, run_id, None, lim, aborted=aborted))
    return out


def now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat()


def summary(record: dict[str, Any]) -> str:
    """One line for the operator: the outcome and what decided it."""
    bad = [m for m in record["measurements"] if m["outcome"] in (ERROR, "FAIL", MARGINAL)]
    words = []
    for r in record.get("runs", []):  # a run that ended in ERROR or ABORTED: why, first
        if r.get("outcome") in (ERROR, "ABORTED"):
            words.append(f"{r.get('step') or r.get('procedure')} {r['outcome']} ({r.get('end_reason', '')})")
    trims = record.get("trims") or {}
    if trims.get("error"):
        words.append(trims["error"])
    elif trims.get("written"):
        words.append(f"trims in NVM (unit {trims.get('unit_id')}, CRC {trims.get('crc')})")
    if not bad:
        met = sum(1 for m in record["measurements"] if m["rule"] and m["outcome"] == "PASS")
        skipped = sum(1 for m in record["measurements"] if m["rule"] and m["outcome"] == SKIPPED)
        words.append(f"{met} limit(s) met" + (f", {skipped} skipped" if skipped else ""))
        return f"{record['outcome']}: " + "; ".join(words)
    for m in bad[:4]:
        lim = m["limits"] or {}
        value = "-" if m["value"] is None else f"{m['value']:.6g}"
        kind = f" {m['condition']}" if m.get("condition") else ""
        bounds = range_text(lim.get("low"), lim.get("high"), m["unit"]) or "none"
        words.append(f"{m['name']}={value} {m['unit']} {m['outcome']}{kind} (limits {bounds}, rule {m['rule']})")
    return f"{record['outcome']}: " + "; ".join(words) + (f"; +{len(bad) - 4} more" if len(bad) > 4 else "")


def record_path(folder: str | Path, record: dict[str, Any]) -> Path:
    """Where a record lies: folder/<serial>-a<attempt>.json."""
    return Path(folder) / f"{_safe(record['serial'])}-a{record['attempt']}.json"


def write_new_record(record: dict[str, Any], folder: str | Path) -> Path:
    """The record as JSON in folder/<serial>-a<attempt>.json, created whole and never over an
    existing file (written to a temporary name, then hard-linked: FileExistsError if taken)."""
    import os

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = record_path(folder, record)
    record["record_file"] = str(path)  # the record names its own file (not covered by its hash)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(record, indent=1))
    try:
        os.link(tmp, path)
    finally:
        tmp.unlink()
    return path


def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text) or "unit"


# --- OpenHTF's layout ----------------------------------------------------------------------------
def _millis(iso: str | None) -> int | None:
    if not iso:
        return None
    return int(_dt.datetime.fromisoformat(iso).timestamp() * 1000)


def _validator_text(m: dict[str, Any]) -> list[str]:
    """The limits as OpenHTF's in_range validator prints them (`250 <= x <= 400`)."""
    lim = m.get("limits")
    if not lim or (lim["low"] is None and lim["high"] is None):
        return []
    marg = m.get("marginal") or {}
    lo, hi, mlo, mhi = lim["low"], lim["high"], marg.get("low"), marg.get("high")
    if lo is not None and hi is not None and lo == hi:
        return [f"x == {lo}"]
    text = ""
    if lo is not None:
        text += f"{lo} <= "
    if mlo is not None:
        text += f"Marginal:{mlo} <= "
    text += "x"
    if mhi is not None:
        text += f" <= Marginal:{mhi}"
    if hi is not None:
        text += f" <= {hi}"
    return [text]


def _cond(m: dict[str, Any]) -> str:
    return f" ({m['condition']})" if m.get("condition") else ""


HTF_MEAS_OUTCOME = {"PASS": "PASS", MARGINAL: "PASS", "FAIL": "FAIL", ERROR: "UNSET", SKIPPED: "UNSET",
                    COMPLETE: "PASS"}
HTF_TEST_OUTCOME = {"PASS": "PASS", MARGINAL: "PASS", "FAIL": "FAIL", ERROR: "ERROR", "ABORTED": "ABORTED"}
NO_CODE = {"name": "", "docstring": None, "sourcecode": ""}


def openhtf_metadata(record: dict[str, Any]) -> dict[str, Any]:
    """The test record's metadata: identity, our outcome (MARGINAL kept, with each MARGINAL's kind),
    and the checksums: the record's hash, the limits and sequence files', and each raw file's."""
    integrity = record.get("integrity") or {}
    return {"test_name": record["sequence"], "lot": record["lot"], "operator": record["operator"],
            "attempt": record["attempt"], "software_version": record["software_version"],
            "gyrobench_outcome": record["outcome"],
            "conditions": {m["name"]: m["condition"] for m in record["measurements"] if m.get("condition")},
            "checksums": {"record_sha256": integrity.get("sha256"), "signature": integrity.get("signature"),
                          "limits_sha256": record.get("limits_sha256"),
                          "sequence_sha256": record.get("sequence_sha256"),
                          "raw_files": {r["run_id"]: {"file": r.get("raw_file"), "sha256": r.get("sha256")}
                                        for r in record["runs"]}}}


def to_openhtf(record: dict[str, Any]) -> dict[str, Any]:
    """The record in OpenHTF's JSON test-record layout (what its json_factory writes): one phase per
    run, its measurements with OpenHTF's outcomes; MARGINAL is OpenHTF's PASS with marginal = true,
    and our own outcome, rule and interval go in the docstring and the metadata."""
    phases = []
    for i, run in enumerate(record["runs"], 1):
        meas = {}
        for m in record["measurements"]:
            if m["run_id"] != run["run_id"] or m["procedure"] != run["procedure"]:
                continue
            iv = m["interval"]
            doc = f"{m['outcome']}{_cond(m)} by rule {m['rule'] or 'none'}; unit {m['unit'] or '-'}; 95% interval " + (
                "none" if iv is None else f"[{iv[0]}, {iv[1]}]")
            entry = {"name": m["name"], "outcome": HTF_MEAS_OUTCOME[m["outcome"]]}
            if _validator_text(m):
                entry["validators"] = _validator_text(m)
            entry["docstring"] = doc  # OpenHTF keeps a measurement's marginal flag out of its JSON
            if m["value"] is not None:
                entry["measured_value"] = m["value"]
            meas[m["name"]] = entry
        outcomes = {m["outcome"] for m in record["measurements"] if m["run_id"] == run["run_id"]}
        phase_outcome = ("ERROR" if run["outcome"] in (ERROR, "ABORTED") else "FAIL" if "FAIL" in outcomes
                         else "PASS")
        phases.append({
            "measurements": meas, "options": None, "diagnosers": [], "subtest_name": None,
            "start_time_millis": _millis(run.get("started_at")) or 0, "end_time_millis": _millis(run.get("ended_at")),
            "attachments": {}, "diagnosis_results": [], "failure_diagnosis_results": [], "result": None,
            "outcome": phase_outcome, "marginal": MARGINAL in outcomes,
            "descriptor_id": i, "name": run["procedure"], "codeinfo": dict(NO_CODE),
        })
    return {
        "dut_id": record["serial"],
        "start_time_millis": _millis(record["started_at"]) or 0,
        "end_time_millis": _millis(record["ended_at"]),
        "outcome": HTF_TEST_OUTCOME[record["outcome"]],
        "outcome_details": [],
        "marginal": record["outcome"] == MARGINAL,
        "metadata": {**openhtf_metadata(record), "config": None},
        "phases": phases,
        "subtests": [], "branches": [], "diagnosers": [], "diagnoses": [], "log_records": [],
        "station_id": record["station"],
        "code_info": dict(NO_CODE),
    }
