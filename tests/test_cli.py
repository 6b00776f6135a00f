"""The gyrobench CLI as a user runs it (subprocesses in a temporary directory): the --json shape,
exit codes, procedures from a file, list / runs / show / analyze / report, SIGINT and SIGTERM
abort into a confirmed safe state, and a SIGKILLed run leaves a readable HDF5 file."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from bench.cli import main
from procedures.examples.table_spin import TableSpin

GYROBENCH = [sys.executable, "-m", "bench.cli"]
JSON_KEYS = {
    "limits",  # the lab's limits and verdicts (`--limits`), None without
    "truth_outside",  # on a simulated station: the truths outside their intervals, None when none compared
    "run_id",
    "procedure",
    "outcome",
    "measurements",
    "truth",
    "simulated_s",
    "wall_s",
    "safe_state",
    "end_reason",
    "raw_file",
}
MEAS_KEYS = {"value", "unit", "ci95", "limits", "marginal", "outcome"}

FAILING = '''
from bench.engine import Measurement, Param, Procedure, step


class AlwaysHigh(Procedure):
    """Measures the table's rate at rest against limits it cannot meet."""

    offset_dps = Param(1.0, unit="deg/s", low=0.0, high=10.0)
    measurements = (Measurement("rest_rate_dps", "deg/s", "rate the table reports at rest"),)

    @step
    def measure_rest(self, ctx):
        ctx.sleep(0.2)
        rate = ctx.devices.table.status().rate_dps
        ctx.measure("rest_rate_dps", rate, "deg/s", limits=(self.offset_dps, self.offset_dps + 1.0))
'''


def _run(args, cwd, timeout=120):
    return subprocess.run(GYROBENCH + args, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def test_run_json_shape_then_runs_show_analyze_report(tmp_path):
    r = _run(
        [
            "run",
            "table-spin",
            "--station",
            "sim-hrg",
            "--set",
            "hold_s=0.5",
            "--set",
            "rate_dps=120",
            "--seed",
            "4",
            "--json",
        ],
        tmp_path,
    )
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)  # stdout is exactly one JSON object
    assert set(out) == JSON_KEYS
    assert out["procedure"] == "table-spin" and out["outcome"] == "PASS" and out["safe_state"] is True
    assert out["end_reason"] == "completed"
    m = out["measurements"]["table_rate_dps"]
    assert set(m) == MEAS_KEYS and m["unit"] == "deg/s" and m["limits"] == [119.5, 120.5] and m["outcome"] == "PASS"
    assert out["truth"]["tau_s"] == 300.0 and out["simulated_s"] > 0.5 and out["wall_s"] > 0
    assert set(out["measurements"]) == {m.name for m in TableSpin.measurements}  # exactly the declared set
    raw = Path(out["raw_file"])
    assert raw.is_file() and raw.parent == tmp_path / "runs"

    runs = json.loads(_run(["runs", "--json"], tmp_path).stdout)
    assert [x["run_id"] for x in runs] == [out["run_id"]]
    show = json.loads(_run(["show", out["run_id"][:17], "--json"], tmp_path).stdout)
    assert show["params"]["rate_dps"] == 120.0 and show["seed"] == 4 and show["outcome"] == "PASS"
    ana = _run(["analyze", "last", "--json"], tmp_path)
    assert ana.returncode == 0, ana.stderr
    refit = json.loads(ana.stdout)["measurements"]["table_rate_dps"]
    # the re-fit averages the recorded table readings at rate: the same rate within the noise
    assert refit["value"] == pytest.approx(120.0, abs=0.01) and refit["outcome"] == "PASS"
    rep = _run(["report", "last"], tmp_path)
    html = Path(rep.stdout.strip()).read_text()
    assert rep.returncode == 0 and "<svg" in html and "table_rate_dps" in html and "PASS" in html


def test_procedure_from_a_file_that_fails_exits_nonzero(tmp_path, capsys, monkeypatch):
    """In this process (a process cost ~1.5 s of CPU more; the exit code is main's return value, which
    `gyrobench` exits with: the process tests of `run` are the others in this file)."""
    path = tmp_path / "always_high.py"
    path.write_text(FAILING)
    monkeypatch.chdir(tmp_path)
    code = main(["run", str(path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1 and out["outcome"] == "FAIL" and out["procedure"] == "always-high"
    assert out["measurements"]["rest_rate_dps"]["outcome"] == "FAIL" and out["safe_state"] is True


def test_bad_parameter_and_station_exit_2_naming_them(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", "table-spin", "--set", "rate_dps=5000"]) == 2
    err = capsys.readouterr().err
    assert "rate_dps=5000 deg/s is above the limit 1000 deg/s" in err
    assert main(["run", "table-spin", "--set", "spin=1"]) == 2
    assert "spin" in capsys.readouterr().err
    assert main(["run", "table-spin", "--station", "nowhere.toml"]) == 2
    assert "nowhere.toml" in capsys.readouterr().err
    assert main(["run", "table-spin", "--fault", "meteor@1"]) == 2
    assert "meteor" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # nothing was started


def test_run_with_report_prints_truth_and_the_report_path(tmp_path):
    r = _run(["run", "table-spin", "--set", "hold_s=0.5", "--report"], tmp_path)
    assert r.returncode == 0, r.stderr
    report = Path(r.stdout.strip().splitlines()[-1].split("report ", 1)[1])
    assert report.is_file() and report.suffix == ".html" and "table_rate_dps" in report.read_text()
    assert "safe state confirmed" in r.stdout


def test_design_recommends_a_slower_table_than_the_patent(capsys):
    """docs/free_decay_identification.md: the scatter of D falls in proportion to the rate, so for the HRG
    preset the recommended rate is far below 500 deg/s and the predicted gain is large."""
    assert main(["design", "hrg-damping", "--stream-hz", "100"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.strip().startswith("recommended: table rate"))
    rate_dps = float(line.split("table rate ")[1].split(" deg/s")[0])
    assert 0.1 < rate_dps < 50.0
    gain = float(out.split("recommended is ")[1].split("x better")[0])
    assert gain > 10.0
    assert main(["design", "hrg-damping", "--tau-s", "-3"]) == 2
    assert "tau" in capsys.readouterr().err


def test_design_matches_what_the_procedures_run(capsys):
    """Both designs use the procedure's stream rate (100 Hz, boxcar from the 1 kHz FPGA samples, so
    the noise per fitted sample is 1e-4 / sqrt(10)), cite docs/ only, and print the run command
    with the chosen rate and record length."""
    assert main(["design", "hrg-free-decay"]) == 0
    out = capsys.readouterr().out
    assert "stream 100 Hz" in out and "noise 3.16e-05 per fitted sample" in out
    assert "docs/free_decay_identification.md" in out and "PHYSICS" not in out
    run = next(x for x in out.splitlines() if "run it:" in x)
    rate = float(run.split("rate_dps=")[1].split()[0])
    record = float(run.split("record_s=")[1].split()[0])
    assert rate * record >= 720.0 and "stream_hz=100" in run
    rec = next(x for x in out.splitlines() if x.strip().startswith("recommended:"))
    assert f"record {record:.0f} s" in rec
    assert main(["design", "hrg-damping", "--split-hz", "0"]) == 0
    out = capsys.readouterr().out
    assert "stream 100 Hz" in out and "PHYSICS" not in out and "--set stream_hz=100" in out
    assert main(["design", "hrg-free-decay", "--stream-hz", "5000"]) == 2
    assert "--sample-hz" in capsys.readouterr().err


def test_list_json(capsys):
    assert main(["list", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    spin = out["procedures"]["table-spin"]
    assert spin["steps"] == ["spin_up", "hold"]
    assert {"name": "rate_dps", "default": 100.0, "unit": "deg/s", "low": -1000.0, "high": 1000.0}.items() <= next(
        p for p in spin["params"] if p["name"] == "rate_dps"
    ).items()
    assert {"sim-hrg", "sim-mems"} <= set(out["stations"]) and "link-drop" in out["faults"]


def _start_long_run(tmp_path):
    proc = subprocess.Popen(
        # 100x real time: a lockstep 600 s hold now runs in about a second, gone before the signal
        GYROBENCH + ["run", "table-spin", "--set", "hold_s=600", "--speed", "100", "--json"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # wait until the hold is being recorded
        files = list((tmp_path / "runs").glob("*.h5")) if (tmp_path / "runs").exists() else []
        if files and _fpga_rows_so_far(files[0]) > 2000:
            return proc, files[0]
        time.sleep(0.2)
    proc.kill()
    raise AssertionError("the run did not start recording within 60 s")


def _fpga_rows_so_far(path) -> int:
    """Rows of the fpga stream in a file being written; -1 while it cannot be read yet (h5py
    raises OSError or RuntimeError, depending on where it meets the half-written metadata)."""
    try:
        with h5py.File(path, "r", locking=False) as f:  # the writer holds the lock
            return f["streams/fpga"].shape[0] if "streams/fpga" in f else -1
    except (OSError, RuntimeError, KeyError, ValueError):
        return -1


def test_the_read_loop_waits_on_a_half_written_file(tmp_path, monkeypatch):
    """CI flaked when h5py raised RuntimeError (not OSError) on a file mid-write (issue 13, item 18)."""

    def half_written(*args, **kwargs):
        raise RuntimeError("Unable to synchronously open object (bad object header version number)")

    monkeypatch.setattr(h5py, "File", half_written)
    assert _fpga_rows_so_far(tmp_path / "run.h5") == -1


@pytest.mark.serial  # a 100x real-time run with its link watchdogs: run alone
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_aborts_into_confirmed_safe_state(tmp_path, sig):
    proc, _ = _start_long_run(tmp_path)
    os.kill(proc.pid, sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, out + err  # 130 / 143, after the safe state
    res = json.loads(out)
    assert res["outcome"] == "ABORTED" and res["end_reason"] == f"aborted: {sig.name}" and res["safe_state"] is True


@pytest.mark.serial  # a 100x real-time run with its link watchdogs: run alone
def test_sigkilled_run_leaves_a_readable_hdf5_file(tmp_path):
    proc, path = _start_long_run(tmp_path)  # returns once over 2000 rows are in the file: killed mid-record
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    with h5py.File(path, "r") as f:
        n = f["streams/fpga"].shape[0]
        t = f["streams/fpga"][:, 1]
        assert n > 2000 and json.loads(f.attrs["params"])["hold_s"] == 600.0
        assert (t[1:] > t[:-1]).all()
        assert "outcome" not in f.attrs  # the run never finished


@pytest.mark.serial  # devices served at 2x real time to drivers with wall-clock timeouts: run alone
def test_sim_serves_devices_that_real_drivers_reach(tmp_path):
    proc = subprocess.Popen(
        GYROBENCH + ["sim", "--duration-s", "20", "--speed", "2"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        info = json.loads(proc.stdout.readline())
        dev = info["devices"]
        assert info["station"] == "sim-hrg" and info["speed"] == 2.0
        from bench.clock import RealClock
        from drivers.fpga.link import FpgaLink
        from drivers.rate_table import ModbusRateTable, TableLimits

        table = ModbusRateTable(
            dev["table"]["host"],
            dev["table"]["port"],
            clock=RealClock(),
            limits=TableLimits(max_rate_dps=100.0, max_accel_dps2=100.0),
        )
        table.connect()
        try:
            assert not table.status().tripped
        finally:
            table.close()
        with FpgaLink(dev["fpga"]["url"]) as link:
            assert link.sample_period_s == pytest.approx(1e-3)
        assert dev["frontend"]["resource"].startswith("TCPIP::127.0.0.1::")
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    assert proc.returncode == 130  # stopped by Ctrl-C: 128 + SIGINT


# --- a disk that fills (issue 13, item 1) --------------------------------------------------------
_FAKE_FULL = """
import os, sys
import bench.recorder as br
real, calls = os.statvfs, [0]
def statvfs(path):  # the disk fills after 30 flushes: 0.5 MB free, below the recorder's 1 MiB
    calls[0] += 1
    st = real(path)
    return os.statvfs_result((st.f_bsize, 1, st.f_blocks, 0, 512 if calls[0] > 30 else 10**9) + tuple(st)[5:])
br.os.statvfs = statvfs
from bench.cli import main
sys.exit(main(sys.argv[1:]))
"""


_SLOW_FULL = _FAKE_FULL.replace("br.os.statvfs = statvfs", """br.os.statvfs = statvfs
import time
_flush = br.Recorder._flush
def slow_flush(self):  # a slow disk: every flush takes 0.3 s of wall time
    time.sleep(0.3)
    _flush(self)
br.Recorder._flush = slow_flush""")


def test_a_slow_disk_that_fills_is_noticed_within_a_second_of_the_run(tmp_path):
    """A slow disk (0.3 s a flush) that fills: in lockstep the raw data are written before the
    clock moves on (bench.writer), so the run stops at its next checkpoint after the failed write;
    when a writer thread took them from a queue, the simulation ran ahead of it by up to the queue
    (87 simulated s here), and the disk test's 5 s allowance held only while the disk was fast."""
    args = ["run", "table-spin", "--set", "hold_s=600", "--json", "--runs-dir", str(tmp_path / "runs")]
    r = subprocess.run([sys.executable, "-c", _SLOW_FULL, *args], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stdout + r.stderr[-3000:]
    out = json.loads(r.stdout)
    assert out["outcome"] == "ERROR" and out["safe_state"] is True, out
    t_fail = float(out["end_reason"].split("at t = ")[1].split(" s")[0])
    # a grid point (0.4 s) to the next checkpoint and the table's stop from 100 deg/s (0.2 s)
    assert out["simulated_s"] < t_fail + 1.0, (out["simulated_s"], t_fail)


def test_a_disk_that_fills_ends_the_run_at_once_in_the_safe_state(tmp_path):
    """--runs-dir on a 3 MB tmpfs (root), else a disk that says it is full: the first failure ends
    the run (ERROR, 'raw data: disk full at t = ... s'), safe state confirmed, one clear message,
    exit 1, no traceback, and the file reads back (h5py, h5dump) up to the failure.  Before, the
    procedure went on for the whole hold and the process died with a segmentation fault."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    tmpfs = os.geteuid() == 0 and subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mnt)], capture_output=True
    ).returncode == 0
    args = ["run", "table-spin", "--set", "hold_s=600", "--json", "--runs-dir", str(mnt)]
    cmd = GYROBENCH + args if tmpfs else [sys.executable, "-c", _FAKE_FULL, *args]
    try:
        r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert r.returncode == 1, r.stdout + r.stderr[-3000:]
        assert "Traceback" not in r.stderr and "Segmentation" not in r.stderr, r.stderr[-3000:]
        out = json.loads(r.stdout)
        assert out["outcome"] == "ERROR" and out["safe_state"] is True, out
        reason = out["end_reason"]
        assert reason.startswith("raw data: disk full at t = ") and "the recorder stops below 1.05 MB" in reason
        t_fail = float(reason.split("at t = ")[1].split(" s")[0])
        assert out["simulated_s"] < t_fail + 5.0 < 600.0  # ended at once, not after the 600 s hold
        with h5py.File(out["raw_file"], "r") as f:
            t = f["streams/fpga"][:, 1]
            assert len(t) > 1000 and (t[1:] > t[:-1]).all() and t[-1] <= t_fail
            assert f.attrs["outcome"] == "ERROR" and f.attrs["incomplete"] == reason
        if shutil.which("h5dump"):
            assert subprocess.run(["h5dump", "-H", out["raw_file"]], capture_output=True).returncode == 0
    finally:
        if tmpfs:
            subprocess.run(["umount", str(mnt)], check=False)


# --- analyze and report of an incomplete run (issue 13, item 6) ----------------------------------
def _cut_short(src: Path, dst: Path, *, drop_streams: tuple[str, ...]) -> Path:
    """A copy of a finished run's raw file as a run killed earlier leaves it: no end attributes,
    and without the streams written only later."""
    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "r+") as f:
        for key in ("outcome", "end_reason", "safe_state", "safe_detail", "result", "finished_at"):
            del f.attrs[key]
        for name in drop_streams:
            del f["streams"][name]
    return dst


def test_analyze_and_report_of_an_incomplete_run_say_so(tmp_path, capsys, monkeypatch):
    """Killed during the record: the decay recorded so far is fitted and marked as from an
    incomplete run; killed before any FPGA data: one message naming what the file lacks.  Both
    used to end in a KeyError traceback.  `analyze` runs as a process for each file's first look
    (its exit code and stderr as a user sees them); the run that makes the file, the text analysis
    and the reports run in this process (a process each cost ~0.7-1.5 s of CPU to import and warm
    again; `run` and `report` have their process tests in test_run_json_shape_then_runs_show_analyze_report)."""
    def in_process(args):
        code = main(args)
        out, err = capsys.readouterr()
        return code, out, err

    monkeypatch.chdir(tmp_path)
    code, out, err = in_process(["run", "hrg-damping", "--set", "record_s=30", "--set", "compensate=false",
                                 "--seed", "3", "--json"])
    assert code == 0, err
    raw = Path(json.loads(out)["raw_file"])
    killed = _cut_short(raw, tmp_path / "killed.h5", drop_streams=("damping_windows", "damping_reference"))
    ana = _run(["analyze", str(killed), "--json"], tmp_path)
    assert ana.returncode == 0 and "Traceback" not in ana.stderr, ana.stderr
    out = json.loads(ana.stdout)
    assert out["incomplete"].startswith("the run did not finish")
    assert any("no damping_windows stream" in n for n in out["notes"])
    tau = out["measurements"]["tau_s"]  # truth 300 s, from the whole record to the last sample
    assert tau["ci95"][0] < 300.0 < tau["ci95"][1] and "q_factor" not in out["measurements"]
    code, text, _ = in_process(["analyze", str(killed)])
    assert code == 0 and "from an INCOMPLETE run: the run did not finish" in text
    code, _, err = in_process(["report", str(killed), "-o", str(tmp_path / "killed.html")])
    assert code == 0 and "INCOMPLETE RUN" in (tmp_path / "killed.html").read_text(), err

    early = _cut_short(raw, tmp_path / "early.h5", drop_streams=("damping_windows", "damping_reference", "fpga"))
    ana = _run(["analyze", str(early)], tmp_path)
    assert ana.returncode == 1 and "Traceback" not in ana.stderr and ana.stdout == ""
    assert ana.stderr.count("\n") == 1 and "early.h5 has no stream 'fpga' (it has: table)" in ana.stderr
    assert "the run did not finish" in ana.stderr
    code, _, err = in_process(["report", str(early), "-o", str(tmp_path / "early.html")])
    assert code == 0 and "INCOMPLETE RUN" in (tmp_path / "early.html").read_text(), err
    bad = tmp_path / "not.h5"
    bad.write_text("not hdf5")
    code, out, err = in_process(["analyze", str(bad)])
    assert code == 1 and out == "" and err.count("\n") == 1 and "not.h5" in err
