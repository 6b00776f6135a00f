"""`gyrobench run`'s record as a table: each measurement with its interval, its verdict against the
lab's limits (`--limits FILE`: the line's limits format and ILAC G8 rules, judged by
bench.line.record.judge_measurements, the line's own path) and, on a simulated station, its truth
flagged when it lies outside the value's 95 % interval, with the count on top."""

from __future__ import annotations

from typing import Any

NO_LIMITS = "no limits given"
#: ILAC G8's words for an interval that straddles a limit (the line's MARGINAL)
CONDITIONAL = "conditional"


def load_lab_limits(path: str | None) -> Any:
    """The limits file, checked before any device moves (LineError names the key); None without."""
    if not path:
        return None
    from bench.line.limits import load_limits

    return load_limits(path)


def apply_limits(js: dict[str, Any], limits: Any, declared: set[str]) -> dict[str, Any] | None:
    """Judge the run's measurements against the lab's limits (the line's code path), put each
    verdict into js["measurements"][name]["verdict"] and the summary into js["limits"] (and the
    truths outside their intervals into js["truth_outside"] on a simulated station), and store it
    in the raw file (attribute `lab_limits`, which the report reads); declared: the procedure's
    declared measurement names (the limits that apply, as the line picks them); None without limits."""
    flags = truth_flags(js) if js.get("truth") else {}
    js["truth_outside"] = ({"outside": sorted(n for n, f in flags.items() if f), "compared": len(flags)}
                           if flags else None)
    if limits is None:
        js["limits"] = None
        return None
    from bench.line.record import judge_measurements
    from bench.line.verdict import ABORTED, ERROR, worst

    applied = limits.for_procedure(js["procedure"], declared)
    aborted = js["end_reason"] if js["outcome"] == ABORTED else None
    entries = judge_measurements(js["procedure"], js["run_id"], js["measurements"], applied, None, aborted)
    decided = [e["outcome"] for e in entries if e["rule"]]
    if js["outcome"] in (ERROR, ABORTED):
        decided.append(js["outcome"])
    summary = {"file": limits.source, "product": limits.name, "outcome": worst(decided) if decided else ERROR,
               "measurements": {e["name"]: e for e in entries if e["rule"]}}
    if not summary["measurements"]:
        summary["note"] = f"no limit in {limits.source} applies to {js['procedure']}'s measurements"
    for name, e in summary["measurements"].items():
        if name in js["measurements"]:
            js["measurements"][name]["verdict"] = e["outcome"]
    js["limits"] = summary
    if js.get("raw_file"):
        from bench.recorder import annotate

        annotate(js["raw_file"], "lab_limits", summary)
    return summary


def truth_flags(js: dict[str, Any]) -> dict[str, bool]:
    """{measurement: truth outside its 95 % interval} for each measurement with a truth and an
    interval (an axis angle's truth by its image nearest the value)."""
    from bench.numbers import truth_outside
    from procedures import measurement_periods, measurement_truth

    truth = measurement_truth(js.get("procedure"), js.get("truth"))
    periods = measurement_periods(js.get("procedure"))
    out = {}
    for name, m in js["measurements"].items():
        if name in truth:
            flag = truth_outside(m.get("value"), truth[name], m.get("ci95"), periods.get(name))
            if flag is not None:
                out[name] = flag
    return out


def truth_count_line(flags: dict[str, bool]) -> str:
    """'7 of 16 truths outside their 95 % intervals'."""
    return f"{sum(flags.values())} of {len(flags)} truths outside their 95 % intervals"


def print_record(js: dict[str, Any]) -> None:
    """The run's record as a table, truths flagged, verdicts beside the values."""
    from bench import numbers
    from procedures import measurement_truth, no_truth_reasons

    print(f"run {js['run_id']}  {js['procedure']}  {js['outcome']}  ({js['end_reason']})")
    lab = js.get("limits")
    if lab is not None:
        print(f"  limits {lab['file']} (product {lab['product']}): {lab['outcome']}"
              + (f" - {lab['note']}" if lab.get("note") else ""))
    else:
        print(f"  {NO_LIMITS}: values measured, not judged")
    truth = measurement_truth(js.get("procedure"), js.get("truth"))  # by declaration
    flags = truth_flags(js) if truth else {}
    if flags:
        print(f"  {truth_count_line(flags)}" + (" (marked !)" if any(flags.values()) else ""))

    def num(x: Any) -> str:  # a set value (a limit) as written; None: an open side or NaN/inf
        return "-" if x is None else numbers.plain(x)

    judged = (lab or {}).get("measurements", {})
    why_no_truth = no_truth_reasons(js.get("procedure")) if truth else {}  # said where the truth would be
    notes: list[str] = []
    rows = [("measurement", "value", "unit", "95% interval", "limits", "outcome", "truth" if truth else "")]
    for name, m in js["measurements"].items():
        value, ci = numbers.with_interval(m["value"], m["ci95"])  # the report's digit rule
        ci = "" if ci == numbers.DASH else ci
        lim, outcome = _limits_and_outcome(m, judged.get(name), num)
        t = numbers.truth_text(truth[name], m["ci95"]) + (" !" if flags.get(name) else "") if name in truth else ""
        if name not in truth and name in why_no_truth:
            if why_no_truth[name] not in notes:
                notes.append(why_no_truth[name])
            t = "*" * (notes.index(why_no_truth[name]) + 1)
        rows.append((name, value, m["unit"], ci, lim, outcome, t))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        print("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
    for i, why in enumerate(notes):
        print(f"  {'*' * (i + 1)} {why}")
    print(
        f"  safe state {'confirmed' if js['safe_state'] else 'NOT CONFIRMED'}; "
        f"{js['simulated_s']:.3f} s bench time, {js['wall_s']:.2f} s wall"
        + (f" ({js['speed_achieved']:.3g}x real time)" if js.get("speed_achieved") else "")
        + f"; raw {js['raw_file']}" + _gone(js["raw_file"])
    )


def _limits_and_outcome(m: dict[str, Any], entry: dict[str, Any] | None, num) -> tuple[str, str]:
    """A row's limits and outcome: the lab's verdict when a limit names it (MARGINAL is ILAC G8's
    conditional outcome), else the procedure's own limits, else 'measured' / NOT_MEASURED."""
    if entry is not None:
        lim = entry.get("limits") or {}
        outcome = entry["outcome"] + (f" ({CONDITIONAL})" if entry["outcome"] == "MARGINAL" else "")
        return f"[{num(lim.get('low'))}, {num(lim.get('high'))}] {entry['rule']}", outcome
    lim = "" if m["limits"] is None else "[" + ", ".join(num(x) for x in m["limits"]) + "]"
    outcome = m["outcome"]
    if outcome == "COMPLETE":  # no limit judged it: it was measured, nothing more
        outcome = "measured"
    return lim, outcome


def _gone(path: str | None) -> str:
    """' (deleted during the run)' when the raw file a record names is no longer there."""
    from pathlib import Path

    return " (deleted during the run)" if path and not Path(path).exists() else ""
