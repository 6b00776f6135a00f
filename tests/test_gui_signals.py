"""Ctrl+C and SIGTERM on `gyrobench gui`: the run is aborted to the safe state, the window closes,
the process exits 128 + signal with no traceback; `gui --open RUN.h5` opens the replay only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pyqtgraph")

ROOT = Path(__file__).resolve().parents[1]


def _gui(tmp_path: Path, *args: str) -> subprocess.Popen:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "bench.cli", "gui", *args], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.serial  # a run at 1x real time with its link watchdogs: run alone
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_aborts_the_run_to_the_safe_state_and_exits(tmp_path, sig):
    proc = _gui(tmp_path, "--station", "sim-hrg", "--run", "hrg-free-decay", "--set", "record_s=3600",
                "--speed", "1", "--start")
    try:
        line = proc.stdout.readline()  # the window says when the run is going on
        assert "hrg-free-decay started" in line, proc.stderr.read()[-2000:]
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + int(sig), err[-2000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert f"stopped by {sig.name}" in out and "safe state confirmed" in out, out


def test_open_alone_is_a_replay_without_a_station(tmp_path, monkeypatch, qapp):
    monkeypatch.chdir(tmp_path)
    from bench.composition import load_station
    from bench.engine import Runner
    from procedures import find_procedure

    station = load_station("sim-hrg")
    station.open()
    try:
        spin = find_procedure("table-spin")({"rate_dps": 20.0, "hold_s": 0.2})
        rec = Runner(station, runs_dir=tmp_path / "runs").run(spin)
    finally:
        station.close()
    import bench.gui.app as app

    def no_station(*_a, **_k):
        raise AssertionError("a replay opens no station")

    monkeypatch.setattr(app, "make_backend", no_station)
    png = tmp_path / "replay.png"
    assert app.run_gui(open_run=str(rec.raw_file), screenshot=str(png)) == 0
    assert png.stat().st_size > 10_000
