"""Replay's time axis starts at the run's start (the file's t_start_s, else its earliest recorded
time), never at the alphabetically first stream; exported PNGs draw the same axes."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

pytest.importorskip("pyqtgraph")


def test_run_start_is_the_earliest_time_without_the_attribute(tmp_path):
    from bench.gui.replay import replay_events

    path = tmp_path / "r.h5"
    with h5py.File(path, "w") as f:
        f.attrs["run_id"] = "r1"
        late = f.create_dataset("a_late", data=np.column_stack((np.linspace(1000, 1100, 11), np.ones(11))))
        late.attrs["columns"] = json.dumps(["t_s", "x"])
        early = f.create_dataset("z_early", data=np.column_stack((np.linspace(100, 1100, 11), np.ones(11))))
        early.attrs["columns"] = json.dumps(["t_s", "y"])
    assert replay_events(path)[0].t_sim_s == 100.0  # not 1000 (the alphabetically first stream)


def test_replay_axis_and_png_start_at_the_run_start(tmp_path, monkeypatch, qapp):
    monkeypatch.chdir(tmp_path)
    from bench.composition import load_station
    from bench.engine import Runner
    from procedures import find_procedure

    station = load_station("sim-hrg")
    station.open()
    try:
        runner = Runner(station, runs_dir=tmp_path / "runs")
        runner.run(find_procedure("table-spin")({"rate_dps": 10.0, "hold_s": 0.2}))  # the clock moves on
        spin = find_procedure("table-spin")({"rate_dps": 20.0, "hold_s": 0.5})
        rec = runner.run(spin)
    finally:
        station.close()
    with h5py.File(rec.raw_file, "r") as f:
        t_start = float(f.attrs["t_start_s"])
    assert t_start > 0.5  # the second run starts after the first one's bench time
    from bench.gui.export import export_plot
    from bench.gui.replay_view import ReplayWindow

    win = ReplayWindow(rec.raw_file)
    try:
        win.plots.refresh(force=True)
        assert win.plots.t0_s == pytest.approx(t_start)
        x, _y = win.plots.c_rate.getData()
        assert len(x) > 0 and float(np.min(x)) >= -1e-6  # seconds since the run started
        png = tmp_path / "rate.png"
        assert "written" in export_plot(win.plots, "table rate", None, png)  # the same axes
        assert png.stat().st_size > 1000
    finally:
        win.close()
