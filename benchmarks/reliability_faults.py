"""Reliability audit: injected faults and signals against `python -m bench.cli run`, each run a
subprocess as a user would start it.  Prints, for each class, how many cases were tried and how
many were clean: safe state confirmed, one clear message (the run's end reason names what
happened; no Python traceback on stderr), the run's record in the store, the raw file readable
to its last dataset.

    .venv/bin/python benchmarks/reliability_faults.py [--jobs 2] [--quick]

Faults: every `--fault` kind (bench.station.FAULTS) at several simulated times in each of four
procedures (shortened so the audit takes minutes).  Signals: SIGINT and SIGTERM at several wall
times after the run began (its raw file appeared), and a few before it began.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import h5py

from bench.fault_kinds import FAULTS
from bench.results import ResultsStore

ROOT = Path(__file__).resolve().parents[1]
#: (procedure, station, --set values, fault times in simulated s within the run)
FAULT_RUNS = [
    ("table-spin", "sim-hrg", ["hold_s=6"], [0.5, 2.5, 5.0]),
    ("hrg-damping", "sim-hrg", ["record_s=20", "verify_s=5", "verify_settle_s=1"], [2.0, 15.0, 35.0]),
    ("hrg-free-decay", "sim-hrg", ["record_s=20"], [5.0, 22.0]),
    ("mems-sweep", "sim-mems", ["n_points=7"], [1.0, 5.0]),
]
#: (procedure, station, --set values) long enough to be signalled while running
SIGNAL_RUNS = [
    ("table-spin", "sim-hrg", ["hold_s=600"]),
    ("hrg-damping", "sim-hrg", ["record_s=300", "verify_s=30"]),
    ("hrg-free-decay", "sim-hrg", ["record_s=200"]),
    ("mems-sweep", "sim-mems", ["n_points=61"]),
]
SIGNAL_OFFSETS_S = [0.05, 0.3, 0.6, 1.0, 2.5]  # wall s after the raw file appeared
EARLY_OFFSETS_S = [0.3, 1.5]  # wall s after the process started (before the run begins)


@dataclass
class Case:
    label: str
    argv: list[str]
    signal: int | None = None
    offset_s: float = 0.0
    early: bool = False
    clean: bool = False
    signalled: bool = True
    problems: list[str] = field(default_factory=list)
    outcome: str = ""
    end_reason: str = ""


def _cmd(proc: str, station: str, sets: list[str], workdir: Path, extra: list[str]) -> list[str]:
    argv = [sys.executable, "-m", "bench.cli", "run", proc, "--station", station, "--json",
            "--runs-dir", str(workdir / "runs"), "--results", str(workdir / "results.sqlite"), *extra]
    for s in sets:
        argv += ["--set", s]
    return argv


def _raw_readable(path: str) -> str | None:
    """None if every dataset of the raw file reads back, else what failed."""
    try:
        with h5py.File(path, "r") as f:
            names: list[str] = []
            f.visit(names.append)
            for name in names:
                obj = f[name]
                if isinstance(obj, h5py.Dataset):
                    obj[()]
        return None
    except Exception as exc:  # noqa: BLE001 - reported
        return f"raw file {path}: {type(exc).__name__}: {exc}"


def _judge(case: Case, rc: int, out: str, err: str, workdir: Path) -> None:
    p = case.problems
    if "Traceback" in err:
        p.append("traceback on stderr: " + err[err.index("Traceback"):][:300].replace("\n", " | "))
    if "internal error" in err:
        p.append("internal error: " + err[err.index("internal error"):][:200])
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    if case.early and not lines:
        # stopped before the run began: nothing moved, nothing to record; a clean exit is all
        if rc < 0:
            p.append(f"killed by signal {-rc} with no message")
        elif rc == 0:
            p.append("exit 0 after a signal")
        elif not err.strip():
            p.append("no message")
        case.clean = not p
        return
    if not lines:
        p.append(f"no JSON result (rc {rc}); stderr: {err.strip()[-300:]}")
        case.clean = False
        return
    js = json.loads(lines[-1])
    case.outcome, case.end_reason = js["outcome"], js["end_reason"]
    if not js["safe_state"]:
        p.append("safe state NOT confirmed")
    if not js["end_reason"]:
        p.append("no end reason")
    if case.signal is not None and js["outcome"] != "ABORTED":
        if js["outcome"] in ("PASS", "COMPLETE", "FAIL", "MARGINAL"):
            case.signalled = False  # finished before the signal arrived: not counted
        else:
            p.append(f"outcome {js['outcome']} after a signal")
    if case.signal is None and js["outcome"] in ("PASS", "COMPLETE", "FAIL", "MARGINAL"):
        p.append(f"the fault went unnoticed: outcome {js['outcome']}")
    signalled = case.signal is not None and js["outcome"] == "ABORTED"
    expected = {128 + case.signal} if signalled else {0, 1}  # 130 / 143 after a signal, as a shell says
    if rc not in expected:
        p.append(f"exit code {rc} (expected {sorted(expected)})")
    try:
        ResultsStore(str(workdir / "results.sqlite"), upgrade=False).get_run(js["run_id"])
    except Exception as exc:  # noqa: BLE001 - reported
        p.append(f"no record in the store: {type(exc).__name__}: {exc}")
    if js.get("raw_file"):
        bad = _raw_readable(js["raw_file"])
        if bad:
            p.append(bad)
    else:
        p.append("no raw file")
    case.clean = not p


def build(quick: bool) -> tuple[list[Case], list[Case]]:
    faults, signals = [], []
    for proc, station, sets, times in FAULT_RUNS:
        for kind in FAULTS:
            for at in times[:1] if quick else times:
                faults.append(Case(f"{proc} --fault {kind}@{at:g}",
                                   _cmd(proc, station, sets, Path("{w}"), ["--fault", f"{kind}@{at:g}"])))
    for proc, station, sets in SIGNAL_RUNS:
        for sig in (signal.SIGINT, signal.SIGTERM):
            for off in SIGNAL_OFFSETS_S[:1] if quick else SIGNAL_OFFSETS_S:
                signals.append(Case(f"{proc} {sig.name} at run start + {off:g} s",
                                    _cmd(proc, station, sets, Path("{w}"), []), signal=sig, offset_s=off))
    for sig in (signal.SIGINT, signal.SIGTERM):
        for off in EARLY_OFFSETS_S[:1] if quick else EARLY_OFFSETS_S:
            signals.append(Case(f"table-spin {sig.name} at process start + {off:g} s",
                                _cmd("table-spin", "sim-hrg", ["hold_s=120"], Path("{w}"), []),
                                signal=sig, offset_s=off, early=True))
    return faults, signals


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="runs at the same time")
    ap.add_argument("--quick", action="store_true", help="one time per procedure and kind (a smoke test)")
    args = ap.parse_args()
    faults, signals = build(args.quick)
    t0 = time.monotonic()
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        done_faults = list(pool.map(_run_templated, faults))
        done_signals = list(pool.map(_run_templated, signals))
    for title, cases in (("injected faults", done_faults), ("signals", [c for c in done_signals if not c.early]),
                         ("signals before the run began", [c for c in done_signals if c.early])):
        tried = [c for c in cases if c.signalled]
        clean = [c for c in tried if c.clean]
        print(f"{title}: tried {len(tried)}, clean {len(clean)}")
        for c in tried:
            if not c.clean:
                print(f"  NOT CLEAN {c.label}: {'; '.join(c.problems)}")
        skipped = [c for c in cases if not c.signalled]
        if skipped:
            print(f"  ({len(skipped)} more finished before their signal: not counted)")
    outcomes: dict[str, int] = {}
    for c in done_faults:
        outcomes[c.outcome] = outcomes.get(c.outcome, 0) + 1
    print(f"fault outcomes: {outcomes}; {time.monotonic() - t0:.0f} s wall")
    return 0


def _run_templated(case: Case) -> Case:
    with tempfile.TemporaryDirectory(prefix="gyrobench-audit-") as tmp:
        case.argv = [a.replace("{w}", tmp) for a in case.argv]
        return _run_in(case, Path(tmp))


def _run_in(case: Case, workdir: Path) -> Case:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(case.argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    if case.signal is not None:
        if case.early:
            time.sleep(case.offset_s)
        else:
            deadline = time.monotonic() + 120.0
            runs = workdir / "runs"
            while time.monotonic() < deadline and proc.poll() is None:
                if runs.is_dir() and any(runs.glob("*.h5")):
                    break
                time.sleep(0.02)
            time.sleep(case.offset_s)
        if proc.poll() is None:
            proc.send_signal(case.signal)
        else:
            case.signalled = False
    try:
        out, err = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        case.problems.append("no exit within 300 s")
    _judge(case, proc.returncode, out, err, workdir)
    return case


if __name__ == "__main__":
    sys.exit(main())
