"""Campaigns (bench.campaign, `gyrobench campaign`): the file's expansion and the summary's numbers
against known truth; then one small campaign (8 short hrg-free-decay runs) on a LocalCluster of one
worker process (the runs in order), the same on a separately started scheduler with 2 workers (the
same summary bit for bit, whatever order the runs finished in), and a campaign on a LocalCluster of
2 worker processes killed after half its runs and restarted on one (no run twice, none missing)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from computed_once import computed_once
from needs import need

from bench.campaign.spec import CampaignError, parse_campaign
from bench.campaign.summary import binomial_band, summarise

ROOT = Path(__file__).resolve().parents[1]
SMALL = """
[campaign]
id = "{cid}"
procedure = "hrg-free-decay"
station = "sim-hrg"

[params]
record_s = 20.0
stream_hz = 10.0
rate_dps = 20.0

[vary.unit]
split_hz = [0.005, 0.01]

[draw]
seed = 7
[draw.unit]
tau_s = {{ normal = [300.0, 20.0] }}

[seeds]
start = 100
count = 4

[summary]
measurements = ["tau_s", "split_hz", "theta_tau_deg", "maslov_gamma"]
"""


def _doc(**over):
    import tomllib

    doc = tomllib.loads(SMALL.format(cid="t"))
    doc.update(over)
    return doc


def test_expansion_is_fixed_and_draws_are_per_run():
    camp = parse_campaign(_doc())
    runs = camp.runs()
    assert [r.run_id for r in runs] == [f"t-{i:05d}" for i in range(8)]
    assert [r.unit["split_hz"] for r in runs] == [0.005] * 4 + [0.01] * 4
    assert [r.seed for r in runs] == [100, 101, 102, 103] * 2
    taus = [r.unit["tau_s"] for r in runs]
    assert taus == [r.unit["tau_s"] for r in parse_campaign(_doc()).runs()]  # seeded: the same again
    assert len(set(taus)) == 8 and all(200 < t < 400 for t in taus)
    assert runs[3].varied == {"unit.split_hz": 0.005, "unit.tau_s": taus[3]}
    assert runs[0].params == {"record_s": 20.0, "stream_hz": 10.0, "rate_dps": 20.0}
    other = parse_campaign(_doc(seeds={"start": 100, "count": 5}))
    assert other.fingerprint != camp.fingerprint  # another study under the same id is refused


@pytest.mark.parametrize("change, words", [
    ({"seeds": [1, 1]}, "repeat"),
    ({"draw": {"unit": {"tau_s": {"gamma": [1.0, 2.0]}}}}, "one distribution"),
    ({"vary": {"unit": {"split_hz": []}}}, "non-empty list"),
    ({"campaign": {"id": "a b", "procedure": "x"}}, "id"),
    ({"extra": {}}, "unknown table"),
])
def test_bad_files_are_named(change, words):
    with pytest.raises(CampaignError, match=words):
        parse_campaign(_doc(**change))


def test_summary_against_known_truth():
    """400 synthetic runs: error N(0.1, 1), intervals +-1.96: bias, std and coverage as drawn."""
    rng = np.random.default_rng(5)
    err = rng.normal(0.1, 1.0, 400)
    results = [{"index": i, "run_id": f"r{i}", "outcome": "COMPLETE", "values": {"x": 10.0 + e},
                "ci95": {"x": [10.0 + e - 1.96, 10.0 + e + 1.96]}, "truth": {"x": 10.0}, "units": {"x": "s"},
                "crlb": {"x": 0.5}} for i, e in enumerate(err)]
    results.append({"index": 400, "run_id": "bad", "outcome": "ERROR", "values": {}, "truth": {}})
    (s,) = summarise(results)
    assert s.n == 400 and s.n_ci == 400
    assert s.bias == pytest.approx(err.mean(), abs=1e-12)
    assert s.std == pytest.approx(err.std(ddof=1), abs=1e-12)
    assert s.std_over_crlb == pytest.approx(err.std(ddof=1) / 0.5, abs=1e-12)
    assert s.coverage == pytest.approx(np.mean(np.abs(err) <= 1.96))
    lo, hi = binomial_band(400)
    assert (lo, hi) == (s.band_low, s.band_high) and lo < 0.95 < hi
    assert hi - lo == pytest.approx(2 * 1.96 * np.sqrt(0.95 * 0.05 / 400), abs=0.006)
    assert s.covered


def _cli(args, env=None, **kw):
    return subprocess.run([sys.executable, "-m", "bench.cli", "campaign", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=240, **kw)


def _need_dask() -> None:
    import importlib.util

    have = all(importlib.util.find_spec(m) is not None for m in ("distributed", "pyarrow"))
    need(have, "dask.distributed or pyarrow is not installed (pip install -e '.[campaign]')")


def _env():
    _need_dask()
    env = dict(os.environ, PYTHONPATH=str(ROOT), DASK_DISTRIBUTED__WORKER__DAEMON="False")
    env.pop("GYROBENCH_DEBUG", None)
    return env


def _campaign(tmp: Path, cid: str) -> tuple[Path, list[str]]:
    path = tmp / f"{cid}.toml"
    path.write_text(SMALL.format(cid=cid))
    return path, ["--runs-dir", str(tmp / "runs"), "--results", str(tmp / "results.sqlite"), "--json"]


@pytest.fixture(scope="module")
def local_summary(tmp_path_factory):
    """The small campaign on a LocalCluster of one worker process (2 run in the tests below): its JSON
    and folder; once a session (tests/computed_once.py: the tests only read them)."""
    return computed_once(tmp_path_factory, "campaign-local", lambda: _local_summary(tmp_path_factory.mktemp("local")))


def _local_summary(tmp: Path) -> tuple[dict, Path]:
    path, opts = _campaign(tmp, "small")
    proc = _cli([str(path), *opts, "--workers", "1"], env=_env())
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "dashboard: http://" in proc.stderr
    return json.loads(proc.stdout), tmp / "runs" / "campaigns" / "small"


def test_local_cluster_campaign(local_summary):
    out, folder = local_summary
    assert out["ran"] == 8 and out["counts"] == {"COMPLETE": 8}
    rows = {s["name"]: s for s in out["summary"]}
    assert list(rows) == ["tau_s", "split_hz", "theta_tau_deg", "maslov_gamma"]
    assert rows["tau_s"]["n"] == 8 and abs(rows["tau_s"]["bias"]) < 1.0  # the drawn tau is the truth
    # hrg-free-decay states the Cramer-Rao bound of its coefficients: 8 runs' scatter is near it
    assert rows["tau_s"]["std_over_crlb"] is None and 0.3 < rows["maslov_gamma"]["std_over_crlb"] < 3.0
    import pyarrow.parquet as pq

    table = pq.read_table(folder / "runs.parquet").to_pylist()
    tau = [r for r in table if r["measurement"] == "tau_s"]
    assert len(tau) == 8 and len({r["unit.tau_s"] for r in tau}) == 8
    assert all(r["truth"] == pytest.approx(r["unit.tau_s"]) for r in tau)
    assert "data:image/png;base64" in (folder / "report.html").read_text()


def _start(cmd, env, log):
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(procs) -> None:
    """SIGTERM to each process group, then wait for them (SIGKILL after 20 s)."""
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)


def test_separate_scheduler_gives_the_same_summary(local_summary, tmp_path):
    env = _env()
    from distributed import Client

    sched_file = tmp_path / "scheduler.json"
    procs = []
    with open(tmp_path / "dask.log", "w") as log:
        try:
            procs.append(_start([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                 "--port", "0", "--no-dashboard", "--scheduler-file", str(sched_file)], env, log))
            deadline = time.monotonic() + 60
            while not sched_file.exists() and time.monotonic() < deadline:
                time.sleep(0.2)
            assert sched_file.exists(), "the scheduler did not start in 60 s"
            for _ in range(2):  # no nanny: two worker processes are the claim, a nanny process each is not
                procs.append(_start([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file",
                                     str(sched_file), "--nthreads", "1", "--no-dashboard", "--no-nanny"], env, log))
            address = json.loads(sched_file.read_text())["address"]
            with Client(address, timeout="30s") as client:
                client.wait_for_workers(2, timeout=90)
            path, opts = _campaign(tmp_path, "small")
            proc = _cli([str(path), *opts, "--scheduler", address], env=env)
            assert proc.returncode == 0, proc.stderr[-2000:]
        finally:  # the workers first, then the scheduler (a worker stopping as its scheduler goes may hang)
            _stop(procs[1:])
            _stop(procs[:1])
    out, folder = local_summary
    assert json.loads(proc.stdout)["summary"] == out["summary"]
    separate = tmp_path / "runs" / "campaigns" / "small" / "summary.json"
    assert separate.read_bytes() == (folder / "summary.json").read_bytes()  # bit for bit


def test_killed_campaign_resumes_without_running_twice(tmp_path):
    import sqlite3

    path, opts = _campaign(tmp_path, "killed")
    results = tmp_path / "runs" / "campaigns" / "killed" / "results"
    first = subprocess.Popen([sys.executable, "-m", "bench.cli", "campaign", str(path), *opts, "--workers", "2"],
                             cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while len(list(results.glob("*.json"))) < 4 and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)  # the client, its cluster and workers, mid-run
        first.wait(timeout=30)
    assert first.returncode == -signal.SIGKILL, "the first campaign ended before it could be killed"
    kept = {p.stem for p in results.glob("*.json")}
    with sqlite3.connect(tmp_path / "results.sqlite") as db:
        stored = {r[0] for r in db.execute("select run_id from runs where outcome = 'COMPLETE'")}
    done_before = kept | stored
    assert 4 <= len(done_before) <= 8
    # the resume on one worker process: what it must not run twice or miss does not depend on how many
    second = _cli([str(path), *opts, "--workers", "1"], env=_env())
    assert second.returncode == 0, second.stderr[-2000:]
    out = json.loads(second.stdout)
    all_ids = {f"killed-{i:05d}" for i in range(8)}
    ran = set(out["ran_ids"])
    assert out["ran"] + out["skipped"] == 8 and out["skipped"] == len(done_before)
    assert ran.isdisjoint(done_before) and ran | done_before == all_ids  # none twice, none missing
    with sqlite3.connect(tmp_path / "results.sqlite") as db:
        rows = db.execute("select run_id, outcome from runs").fetchall()
    assert sorted(rows) == sorted((i, "COMPLETE") for i in all_ids)


def test_a_run_that_cannot_start_is_an_error_result_not_a_raise(tmp_path):
    from bench.campaign.execute import execute_run

    run = parse_campaign(_doc(params={"record_s": -5.0})).runs()[0].as_dict()
    out = execute_run(run, str(tmp_path), str(tmp_path / "r.sqlite"))
    assert out["outcome"] == "ERROR" and "record_s" in out["error"] and out["run_id"] == "t-00000"
    (s,) = summarise([out, {**out, "index": 1, "outcome": "COMPLETE", "values": {"x": 1.0}, "truth": {"x": 1.5}},
                      {**out, "index": 2, "outcome": "COMPLETE", "values": {"x": 2.0}, "truth": {"x": 1.5}}])
    assert (s.n, s.bias, s.coverage) == (2, 0.0, None)  # the failed run is left out
