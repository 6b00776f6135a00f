"""Bad inputs to every command and signals at any moment (issue 39), through the real CLI
(`python -m bench.cli ...`), each case in its own process and directory.  A case is clean when:
the exit code is the one expected, stderr holds the expected number of lines (one, for an error)
and never "internal error" or a Python traceback, the output holds the words the case lists, and
no raw file, reserve or stub was left behind by a command refused before it ran.

Run: .venv/bin/python benchmarks/reliability_commands.py [--jobs 2] [--verbose]
Prints one line a case that is not clean, then "bad inputs to every command: tried N, clean M".
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GYROBENCH = [sys.executable, "-m", "bench.cli"]
#: the CLI as `gyrobench` starts it, sending itself a signal the moment a module starts importing
AT_IMPORT = """
import os, signal, sys
target, sig = sys.argv[1], getattr(signal, sys.argv[2])
fired = []
def hook(event, args):
    if event == "import" and args[0] == target and not fired:
        fired.append(1)
        os.kill(os.getpid(), sig)
sys.addaudithook(hook)
sys.argv = ["gyrobench", *sys.argv[3:]]
from bench.cli import main
sys.exit(main())
"""
NUL_STATION = '[station]\nid = "a\\u0000b"\n[simulation]\npreset = "hrg"\n[devices.table]\ndriver = "modbus-table"\n'
BAD_STATION = NUL_STATION.replace('preset = "hrg"', 'preset = "hrg"\nseed = -1') + 'max_rate_dps = "fast"\n'


@dataclass
class Case:
    """One command: its arguments (after `python -m bench.cli`, or a full argv with `raw`), the exit
    code and stderr line count expected, the words its output must hold."""

    name: str
    args: list[str]
    code: int
    expect: list[str]
    lines: int = 1
    env: dict[str, str] = field(default_factory=dict)
    raw: bool = False  # args is the whole command line
    signal_after_line: int | None = None  # send this signal once stdout's first line is out (sim)


def _write_files(cwd: Path) -> None:
    """The files the cases name, in the case's own directory."""
    import h5py
    import numpy as np

    (cwd / "nul.toml").write_text(NUL_STATION)
    (cwd / "bad.toml").write_text(BAD_STATION)
    (cwd / "exits.py").write_text("import sys\nsys.exit(0)\n")
    (cwd / "hangs.py").write_text("import time\ntime.sleep(600)\n")
    (cwd / "raises.py").write_text("raise RuntimeError('boom')\n")
    with h5py.File(cwd / "other.h5", "w") as f:  # HDF5 from another program
        f["x"] = np.arange(3)
    for name, params in (("run.h5", json.dumps({"rate_dps": 100.0})), ("badparams.h5", "{not json")):
        with h5py.File(cwd / name, "w") as f:  # a run's parts, as the recorder writes them
            for group in ("streams", "fits"):
                f.create_group(group)
            text = h5py.string_dtype()
            f.create_dataset("log", data=np.array([], dtype=object), dtype=text, maxshape=(None,))
            row = {"name": "table_rate_dps", "value": 100.0, "unit": "deg/s", "ci95": [99.9, 100.1], "low": 99.5,
                   "high": 100.5, "outcome": "PASS", "dut": None}
            f.create_dataset("measurements", data=np.array([json.dumps(row)], dtype=object), dtype=text)
            f.attrs.update({"run_id": name[:-3], "procedure": "table-spin", "params": params, "outcome": "PASS",
                            "end_reason": "completed", "safe_state": True, "station_id": "audit"})


def cases() -> list[Case]:
    no_display = {"DISPLAY": "", "WAYLAND_DISPLAY": "", "QT_QPA_PLATFORM": ""}
    c = [
        Case("runs-limit-overflow", ["runs", "--limit", "100000000000000000000"], 2,
             ["--limit=100000000000000000000 is above the limit 1000000"]),
        Case("runs-empty-store", ["runs"], 0, ["no runs yet in"]),
        Case("station-id-nul", ["run", "table-spin", "--station", "nul.toml"], 2, ["holds a control character (NUL)"]),
        Case("analyze-foreign-h5", ["analyze", "other.h5"], 2, ["other.h5: not a gyrobench raw file"]),
        Case("report-foreign-h5", ["report", "other.h5"], 2, ["other.h5: not a gyrobench raw file"]),
        Case("show-foreign-h5", ["show", "other.h5"], 2, ["other.h5: not a gyrobench raw file"]),
        Case("analyze-params-not-json", ["analyze", "badparams.h5"], 2, ["'params' is not a JSON object"]),
        Case("report-params-not-json", ["report", "badparams.h5"], 2, ["'params' is not a JSON object"]),
        Case("show-raw-file", ["show", "run.h5"], 0, ["95% [99.9, 100.1]", "limits [99.5, 100.5]"], lines=0),
        Case("procedure-sys-exit", ["run", "exits.py"], 2, ["it called sys.exit(0) while being imported"]),
        Case("procedure-hangs", ["run", "hangs.py"], 2, ["did not finish within 2 s"],
             env={"GYROBENCH_IMPORT_TIMEOUT_S": "2"}),
        Case("procedure-raises", ["run", "raises.py"], 2, ["loading it failed: RuntimeError: boom"]),
        Case("line-window-no-display", ["line", "run", "ci-spin", "--station", "sim-hrg-4", "--operator", "ann",
                                        "--dut", "A1", "--dut", "A2", "--window", "--yes"], 2,
             ["no display"], env=no_display),
        Case("dut-escape", ["run", "table-spin", "--dut", "A\nB\x1b[31mRED"], 2, ["holds a control character"]),
        Case("dut-10kB", ["run", "table-spin", "--dut", "S" * 10_000], 2, ["above the limit 64"]),
        Case("operator-escape", ["run", "table-spin", "--operator", "ann\x1b[2J"], 2, ["(U+001B)"]),
        Case("check-station-every-problem", ["check-station", "bad.toml"], 2,
             ["id='a\\x00b'", "seed=-1", "max_rate_dps='fast'", "bad.toml: 3 problem(s)"], lines=0),
    ]
    for sig in (signal.SIGINT, signal.SIGTERM):
        for target in ("bench.cli.analysis", "bench.results"):
            c.append(Case(f"{sig.name}-at-import-of-{target}",
                          [sys.executable, "-c", AT_IMPORT, target, sig.name, "runs"], 128 + sig,
                          ["interrupted"], raw=True))
        c.append(Case(f"sim-{sig.name}", ["sim", "--duration-s", "300"], 128 + sig, [], lines=0,
                      signal_after_line=sig))
    return c


def run_case(case: Case, root: Path) -> tuple[bool, str]:
    """(clean, why) for one case, in its own directory."""
    cwd = Path(tempfile.mkdtemp(dir=root, prefix=case.name + "-"))
    _write_files(cwd)
    before = set(cwd.rglob("*"))
    env = {**os.environ, "PYTHONPATH": str(ROOT), **case.env}
    env = {k: v for k, v in env.items() if v != ""}
    argv = case.args if case.raw else GYROBENCH + case.args
    if case.signal_after_line is None:
        r = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
        rc, out, err = r.returncode, r.stdout, r.stderr
    else:
        proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        first = proc.stdout.readline()
        proc.send_signal(case.signal_after_line)
        out, err = proc.communicate(timeout=120)
        rc, out = proc.returncode, first + out
    why = []
    if rc != case.code:
        why.append(f"exit {rc}, expected {case.code}")
    if "Traceback" in err:
        why.append("traceback")
    if "internal error" in err:
        why.append("internal error")
    n_lines = len(err.strip().splitlines())
    if case.lines and n_lines != case.lines:
        why.append(f"{n_lines} message lines")
    missing = [w for w in case.expect if w not in out + err]
    if missing:
        why.append(f"output lacks {missing}")
    if case.code not in (0, 128 + signal.SIGINT, 128 + signal.SIGTERM):
        left = [p.name for p in set(cwd.rglob("*")) - before if p.suffix == ".h5" or ".reserve" in p.name]
        if left:
            why.append(f"left {left}")
    return not why, f"{case.name}: {'; '.join(why) or 'clean'} | {err.strip()[-200:]!r}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--verbose", action="store_true")
    opts = ap.parse_args()
    all_cases = cases()
    with tempfile.TemporaryDirectory() as tmp:
        with ThreadPoolExecutor(opts.jobs) as pool:
            results = list(pool.map(lambda c: run_case(c, Path(tmp)), all_cases))
    for ok, text in results:
        if opts.verbose or not ok:
            print(("clean   " if ok else "UNCLEAN ") + text)
    print(f"bad inputs to every command: tried {len(results)}, clean {sum(ok for ok, _ in results)}")


if __name__ == "__main__":
    main()
