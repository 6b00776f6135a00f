"""At "max" speed the window draws less often (benchmarks/gui_max_speed.py: each frame's Python
painting takes the interpreter from the engine's thread): 5 redraws a second instead of 25, back
to 25 at a real-time speed; the time and progress labels follow at most ten times a second (four at
"max": setting a progress bar repaints it at once), and always catch up."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.engine import events as ev  # noqa: E402
from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import (  # noqa: E402
    LABELS_EVERY_S,
    MAX_SPEED_LABELS_EVERY_S,
    MAX_SPEED_REFRESH_HZ,
    MainWindow,
)


def test_max_speed_draws_fewer_frames_and_sets_labels_at_a_bounded_rate(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    try:
        win = MainWindow(backend, refresh_hz=25.0)
        win.ask_close_during_run = lambda: True  # a failure mid-test must not wait on a question box
        qtbot.addWidget(win)
        win.station.set_speed(math.inf)
        assert win.plots.timer.interval() == round(1000 / MAX_SPEED_REFRESH_HZ) == 200
        assert win.labels_every_s == MAX_SPEED_LABELS_EVERY_S == 0.25 and win._labels_timer.interval() == 250
        win.station.set_speed(1.0)
        assert win.plots.timer.interval() == 40
        assert win.labels_every_s == LABELS_EVERY_S == 0.1 and win._labels_timer.interval() == 100
        win.station.set_speed(math.inf)
        every = MAX_SPEED_LABELS_EVERY_S
        clock = iter([100.0, 100.0 + every / 2, 100.0 + 2 * every])
        monkeypatch.setattr("bench.gui.main_window._wall_s", lambda: next(clock, 200.0))
        win.run_active = True
        texts = []
        for t in (1.0, 2.0, 3.0):
            win.on_events([ev.Progress("r1", t, fraction=0.5)])
            texts.append(win.station.sim_time.text())
        assert texts == ["t = 1.0 s", "t = 1.0 s", "t = 3.0 s"]  # the middle batch came too soon after
        win._labels_wall_s = 200.0  # the clock's next reading (200 s) is then too soon again:
        win.on_events([ev.Progress("r1", 4.0, fraction=0.6)])  # the labels follow by the timer, not never
        assert win.station.sim_time.text() == "t = 3.0 s"
        qtbot.waitUntil(lambda: win.station.sim_time.text() == "t = 4.0 s", timeout=5000)
        win.run_active = False
    finally:
        backend.close()
