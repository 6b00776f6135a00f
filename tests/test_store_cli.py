"""The results store as a user meets it through `gyrobench` (subprocesses in a temporary
directory): a SIGKILLed run is listed INTERRUPTED with its raw file; a run whose store cannot be
written exits non-zero with one line and its record is submitted by the next run or `runs --sync`."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

from bench.results import ResultsStore

GYROBENCH = [sys.executable, "-m", "bench.cli"]
SHORT = ["run", "table-spin", "--set", "hold_s=0.1", "--json", "--runs-dir", "runs"]


def _run(args, cwd, timeout=120):
    return subprocess.run(GYROBENCH + args, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def _runs(cwd, *extra):
    r = _run(["runs", "--json", "--results", "results.sqlite", *extra], cwd)
    return r, {row["run_id"]: row for row in json.loads(r.stdout or "[]")}


def test_sigkilled_run_is_listed_interrupted_with_its_raw_file(tmp_path):
    proc = subprocess.Popen(
        GYROBENCH + ["run", "table-spin", "--set", "hold_s=600", "--json", "--results", "results.sqlite"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        row = None
        deadline = time.monotonic() + 60
        while row is None and time.monotonic() < deadline:  # the row exists while the run runs
            time.sleep(0.2)
            if (tmp_path / "results.sqlite").exists():
                rows = ResultsStore(tmp_path / "results.sqlite").list_runs()
                row = rows[0] if rows else None
        assert row is not None, "no RUNNING row within 60 s"
        assert row["outcome"] == "RUNNING" and row["pid"] == proc.pid and proc.poll() is None
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    r, rows = _runs(tmp_path)
    got = rows[row["run_id"]]
    assert r.returncode == 0 and got["outcome"] == "INTERRUPTED" and got["end_reason"].startswith("interrupted: ")
    assert got["raw_file"] == row["raw_file"] and os.path.isfile(tmp_path / got["raw_file"])
    shown = _run(["show", "last", "--results", "results.sqlite"], tmp_path)
    assert "INTERRUPTED" in shown.stdout and shown.returncode == 0


def _in_process(args, capsys):
    """The same command through bench.cli.main in this process (cwd: the test's directory): the
    commands after the first run, whose subject is the spool's hand-over, not the process."""
    from bench.cli import main

    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def _rows(out):
    return {row["run_id"]: row for row in json.loads(out or "[]")}


def test_read_only_store_exits_nonzero_and_the_next_run_or_sync_submits_the_record(tmp_path, capsys, monkeypatch):
    """The run against the read-only store is a real process (its exit code and its one line on
    stderr); the listings, the next run and the sync run in this process: a subprocess each cost
    ~0.5-2 s of CPU to import and open again and checked nothing more (`runs` keeps its own
    subprocess tests above and below, `run` in the first command here and in test_cli.py)."""
    monkeypatch.chdir(tmp_path)
    assert _in_process(["runs", "--results", "results.sqlite"], capsys)[0] == 0  # an existing store
    read_only = f"sqlite:///file:{tmp_path / 'results.sqlite'}?mode=ro&uri=true"
    first = _run([*SHORT, "--results", read_only], tmp_path)
    js = json.loads(first.stdout)
    assert first.returncode == 1 and js["outcome"] == "PASS", first.stderr
    assert first.stderr.count("\n") == 1 and "Traceback" not in first.stderr
    assert "readonly database" in first.stderr and f"runs/spool/{js['run_id']}.json" in first.stderr
    assert "gyrobench runs --sync" in first.stderr
    code, out, err = _in_process(["runs", "--json", "--results", "results.sqlite"], capsys)
    assert code == 0 and _rows(out) == {} and "1 run(s) wait in runs/spool" in err
    # the next run (store writable again) submits it at its start
    code, _, err = _in_process([*SHORT, "--results", "results.sqlite"], capsys)
    assert code == 0, err
    rows = _rows(_in_process(["runs", "--json", "--results", "results.sqlite"], capsys)[1])
    assert rows[js["run_id"]]["outcome"] == "PASS" and len(rows) == 2
    assert list((tmp_path / "runs" / "spool").glob("*.json")) == []
    # read-only again; this time `runs --sync` submits it
    code, out, err = _in_process([*SHORT, "--results", read_only], capsys)
    third = json.loads(out)
    assert code == 1 and "readonly database" in err and f"runs/spool/{third['run_id']}.json" in err
    code, out, err = _in_process(["runs", "--json", "--results", "results.sqlite", "--sync"], capsys)
    rows = _rows(out)
    assert code == 0 and "submitted 1 spooled run(s)" in err
    assert rows[third["run_id"]]["outcome"] == "PASS" and len(rows) == 3


def test_postgresql_down_exits_nonzero_then_sync_submits(pg_url, tmp_path):
    down = _run([*SHORT, "--results", "postgresql://postgres@127.0.0.1:1/nowhere"], tmp_path)
    js = json.loads(down.stdout)
    assert down.returncode == 1 and "Connection refused" in down.stderr and down.stderr.count("\n") == 1
    r = _run(["runs", "--sync", "--json", "--results", pg_url], tmp_path)
    assert r.returncode == 0, r.stderr
    assert [row["outcome"] for row in json.loads(r.stdout) if row["run_id"] == js["run_id"]] == ["PASS"]
