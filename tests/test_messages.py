"""What a user reads when something is wrong (issue 13, items 15-17): never a Python traceback,
one line naming the value and the limit, nothing moved; warnings for a fault that never fired and
for a safe state that needed a retry; the headless window without a display."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from bench.cli import main

GYROBENCH = [sys.executable, "-m", "bench.cli"]
STATION = """[station]
id = "msg"
[simulation]
preset = "hrg"
[devices.table]
driver = "modbus-table"
max_rate_dps = 1000.0
[devices.frontend]
driver = "scpi-frontend"
[devices.fpga]
driver = "fpga-link"
"""


def _run(args, cwd, timeout=120, **kw):
    return subprocess.run(GYROBENCH + args, cwd=cwd, capture_output=True, text=True, timeout=timeout, **kw)


def _clean(r: subprocess.CompletedProcess, cwd: Path, *expect: str, ran: bool = False) -> str:
    """Non-zero exit, no traceback, one line on stderr naming what is expected, and no raw file
    unless the run was meant to go ahead (a store that cannot be written: the record is spooled)."""
    err = r.stderr.strip()
    assert r.returncode != 0, (r.returncode, err)
    assert "Traceback" not in err, err
    assert len(err.splitlines()) == 1 and err.startswith("gyrobench: "), err
    for part in expect:
        assert part in err, err
    if ran:
        assert list(cwd.glob("runs/spool/*.json")), "the record was not spooled"
    else:
        assert not list(cwd.glob("runs/*.h5")), "a run started"
    return err


def _unwritable_dir(tmp_path: Path) -> str:
    """A directory raw data cannot go to: read-only for a user, a /proc path for root."""
    if os.geteuid() == 0:
        return "/proc/gyrobench-no-runs-here"
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    return str(ro / "runs")


@pytest.mark.parametrize(
    "case",
    ["syntax", "import", "runs-dir-file", "runs-dir-readonly", "store-readonly-run", "store-readonly-runs",
     "devices-5", "simulation-5"],
)
def test_no_traceback_reaches_the_user(tmp_path, case):
    """Item 15: each of these printed a Python traceback before the CLI's error boundary."""
    (tmp_path / "bad_syntax.py").write_text("def f(:\n    pass\n")
    (tmp_path / "bad_import.py").write_text("import gyrobench_no_such_module\n")
    (tmp_path / "afile").write_text("")
    (tmp_path / "empty.sqlite").write_text("")
    ro_store = f"sqlite:///file:{tmp_path / 'empty.sqlite'}?mode=ro&uri=true"
    (tmp_path / "dev5.toml").write_text('devices = 5\n[station]\nid = "x"\n[simulation]\n')
    (tmp_path / "sim5.toml").write_text('simulation = 5\n[station]\nid = "x"\n')
    spin = ["run", "table-spin", "--set", "hold_s=0.2"]
    args, expect = {
        "syntax": (["run", "bad_syntax.py"], ["bad_syntax.py, line 1: invalid syntax"]),
        "import": (["run", "./bad_import.py"], ["bad_import.py", "No module named 'gyrobench_no_such_module'"]),
        "runs-dir-file": (spin + ["--runs-dir", "afile"], ["--runs-dir afile: is a file, not a directory"]),
        "runs-dir-readonly": (spin + ["--runs-dir", _unwritable_dir(tmp_path)], ["raw data cannot be written"]),
        "store-readonly-run": (spin + ["--results", ro_store], ["results store", "readonly database"]),
        "store-readonly-runs": (["runs", "--results", ro_store], ["results store", "readonly database"]),
        "devices-5": (["run", "table-spin", "--station", "dev5.toml"], ["dev5.toml: devices=5 is not a table"]),
        "simulation-5": (["run", "table-spin", "--station", "sim5.toml"], ["sim5.toml: simulation=5 is not a table"]),
    }[case]
    _clean(_run(args, tmp_path), tmp_path, *expect, ran=case == "store-readonly-run")


def test_a_closed_pipe_is_a_quiet_exit(tmp_path):
    """`gyrobench runs | head`: the reader leaves before the rows are written (item 15)."""
    for args in (["list"], ["runs", "--json"]):  # both print, even with no run in the store
        proc = subprocess.Popen(GYROBENCH + args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        proc.stdout.close()  # like `head` exiting first
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=60) == 141 and err == "", err


def _maps(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return ""


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc to see how far start-up went")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("when", ["imports", "before-open", "running"])
def test_ctrl_c_in_the_first_second_is_one_line(tmp_path, when, sig):
    """SIGINT while the CLI imports its libraries, while it prepares the station, and just after
    the run began: one line (or the run's ABORTED record), never a traceback (item 15).  The
    moment is found from the process itself, not from a sleep, so the test is not timing-bound."""
    proc = subprocess.Popen(
        GYROBENCH + ["run", "table-spin", "--set", "hold_s=30", "--json"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    ready = {
        "imports": lambda: "_multiarray_umath" in _maps(proc.pid),  # numpy loads inside main()
        "before-open": lambda: (tmp_path / "runs").is_dir(),
        "running": lambda: bool(list(tmp_path.glob("runs/*.h5"))),
    }[when]
    deadline = time.monotonic() + 60
    while not ready() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.002)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert "Traceback" not in err, err
    # 128 + the signal (130 / 143) before the run, and with an ABORTED, safe record once it has begun
    assert proc.returncode == 128 + sig, (proc.returncode, err)
    if out.strip():
        res = json.loads(out)
        assert res["outcome"] == "ABORTED" and res["safe_state"] is True
    else:
        name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
        assert err.strip() == f"gyrobench: interrupted ({name})", err


@pytest.mark.parametrize(
    "args, station, message",
    [
        (["--set", "rate_dps=abc"], None, "gyrobench: rate_dps='abc' is not a number"),
        (["--set", "rate_dps=99999"], None, "gyrobench: rate_dps=99999 deg/s is above the limit 1000 deg/s"),
        (["--set", "hold_s=-1"], None, "gyrobench: hold_s=-1 s is below the limit 0.1 s"),
        (
            ["--set", "nosuchparam=1"],
            None,
            "gyrobench: nosuchparam: not a parameter of table-spin (allowed: hold_s, rate_dps, tolerance_dps)",
        ),
        (["--set", "novalue"], None, "gyrobench: --set 'novalue': expected NAME=VALUE"),
        ([], STATION.replace('driver = "modbus-table"\n', ""),
         "[devices.table] driver: missing key (one of acutrol-table, ascii-table, modbus-table)"),
        ([], STATION.replace("1000.0", '"fast"'), "[devices.table] max_rate_dps='fast' is not a number"),
        ([], STATION.replace("1000.0", "99999.0"),
         "[devices.table] max_rate_dps=99999 deg/s is above the limit 20000 deg/s"),
        ([], STATION.replace('"fpga-link"', '"fpga-lnk"'), "[devices.fpga] driver='fpga-lnk' is not one of fpga-link"),
        ([], STATION.replace('"msg"', '"caf\xe9"').encode("latin-1"), "not UTF-8 text (byte 0xe9 at offset"),
        (["--speed", "-1"], None, "gyrobench: --speed=-1 is below the limit 0 (allowed: 0 = lockstep, or 0 to 1e6"),
        (["--seed", "-2"], None, "gyrobench: --seed=-2 is below the limit 0"),
        (["--fault", "link-drop@soon"], None, "'soon' is not a number of seconds"),
    ],
)
def test_messages_name_the_value_and_what_was_expected(tmp_path, capsys, monkeypatch, args, station, message):
    """Item 16: the words of each message (they said "outside the limit"/"allowed range" before)."""
    monkeypatch.chdir(tmp_path)
    if station is not None:
        path = tmp_path / "st.toml"
        path.write_bytes(station if isinstance(station, bytes) else station.encode())
        args = args + ["--station", str(path)]
    assert main(["run", "table-spin", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    if station is not None:
        assert str(tmp_path / "st.toml") in err  # the file is named
    else:
        assert "sim-hrg.toml" not in err  # an option's fault is not the station file's
    assert not (tmp_path / "runs").exists()  # nothing was started


def test_unexpected_errors_are_one_line_and_a_saved_traceback(tmp_path, capsys, monkeypatch):
    """A bug is one line with the path of its saved traceback; --debug prints the traceback."""
    import bench.cli as cli
    import bench.cli.listing

    def boom(_args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(bench.cli.listing, "cmd", boom)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    assert main(["list"]) == cli.EXIT_INTERNAL
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    saved = Path(re.search(r"traceback saved to (\S+);", err).group(1))
    assert saved.parent == tmp_path / "gyrobench" and "ZeroDivisionError" in saved.read_text()
    assert main(["list", "--debug"]) == cli.EXIT_INTERNAL
    assert "Traceback (most recent call last)" in capsys.readouterr().err


def test_a_fault_that_never_fired_is_warned(tmp_path, capsys, monkeypatch):
    """Item 16: `--fault link-drop@9999` on a 1.3 s run tested nothing; the user is told (the
    process's whole stderr).  The fault that fires runs in this process: it checks only that no
    warning is given (a process cost ~1.5 s of CPU more)."""
    r = _run(["run", "table-spin", "--set", "hold_s=0.5", "--fault", "link-drop@9999", "--json"], tmp_path)
    assert r.returncode == 0, r.stderr
    end_s = json.loads(r.stdout)["simulated_s"]
    assert r.stderr.strip() == f"gyrobench: warning: fault link-drop@9999 s never fired: the run ended at {end_s:.1f} s"
    monkeypatch.chdir(tmp_path)
    main(["run", "table-spin", "--set", "hold_s=0.5", "--fault", "table-fault@0.8", "--json"])
    fired = capsys.readouterr()
    assert "never fired" not in fired.err and json.loads(fired.out)["outcome"] != "PASS"


def test_a_safe_state_retry_is_logged_and_its_failed_attempt_recorded(tmp_path):
    """Item 16: after a front-end hang the first safe-state attempt fails and a retry after
    reconnecting succeeds; the console says so between the driver's trouble and the result,
    and the raw file's safe_detail errors and log keep the failed attempt."""
    r = _run(["run", "table-spin", "--set", "hold_s=5", "--fault", "frontend-hang@1", "--json"], tmp_path)
    out = json.loads(r.stdout)
    assert out["safe_state"] is True and out["outcome"] == "ERROR", r.stderr
    note = re.search(r"safe state: frontend confirmed on attempt (\d), after reconnecting \(attempt 1: (.+)", r.stderr)
    assert note is not None and int(note.group(1)) >= 2 and "link lost" in note.group(2), r.stderr
    with h5py.File(out["raw_file"], "r") as f:
        detail = json.loads(f.attrs["safe_detail"])
        log = [json.loads(x)["msg"] for x in f["log"][:]]
    err = detail["errors"]["frontend"]
    assert err.startswith("attempt 1: ") and "after reconnecting" in err and detail["devices"]["frontend"] is True
    assert any(m.startswith("safe state: frontend confirmed on attempt") for m in log), log


def test_choose_qt_platform_without_a_display(monkeypatch):
    from bench.gui import app

    monkeypatch.setattr(app.sys, "platform", "linux")
    env: dict[str, str] = {}
    assert app.choose_qt_platform(env) == "offscreen" and env == {"QT_QPA_PLATFORM": "offscreen"}
    for given in ({"DISPLAY": ":0"}, {"WAYLAND_DISPLAY": "wayland-0"}, {"QT_QPA_PLATFORM": "xcb"}):
        env = dict(given)
        assert app.choose_qt_platform(env) is None and env == given


def test_readme_headless_screenshot_without_a_display(tmp_path):
    """Item 17: the README's headless command with no DISPLAY and no QT_QPA_PLATFORM (Qt aborted
    with SIGABRT before); the window without --screenshot says why it cannot open."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    r = _run(
        ["gui", "--station", "sim-hrg", "--run", "hrg-damping", "--screenshot", "shot.png",
         "--at", "1"],
        tmp_path, timeout=300, env=env,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "shot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "safe state confirmed" in r.stdout and "Traceback" not in r.stderr
    if sys.platform.startswith("linux"):
        win = _run(["gui", "--station", "sim-hrg"], tmp_path, timeout=120, env=env)
        assert win.returncode == 1 and "no display" in win.stderr and "Traceback" not in win.stderr


def test_gui_options_are_checked_in_the_same_words(capsys):
    """`gyrobench gui --speed fast` was a ValueError from float(); now the shared message."""
    assert main(["gui", "--speed", "fast"]) == 2
    assert capsys.readouterr().err.strip() == "gyrobench: --speed='fast' is not a number"
    assert main(["gui", "--speed", "-3"]) == 2
    assert capsys.readouterr().err.strip() == "gyrobench: --speed=-3 is below the limit 0"
