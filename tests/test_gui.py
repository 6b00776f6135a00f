"""The lab engineer's window, offscreen (pytest-qt): start, pause and abort from the window,
parameter validation, plots that receive the stream, the replay of a recorded run, the
screenshot option, and the bridge that keeps widgets in the GUI thread.

The source is the in-process HRG world (`SimWorldBackend`): real integration of the averaged
model at 1 kHz, published as the engine's SampleBlock events.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import Qt, QThread  # noqa: E402
from PySide6.QtGui import QImage  # noqa: E402

from bench.engine import events as ev  # noqa: E402
from bench.gui.bridge import EventBridge  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402
from bench.gui.sim_backend import SimWorldBackend  # noqa: E402

WAIT_MS = 30_000  # generous wall timeouts: 2 shared cores


@pytest.fixture
def window(qtbot):
    backend = SimWorldBackend(seed=0)
    win = MainWindow(backend)
    qtbot.addWidget(win)
    win.show()
    yield win
    backend.close()


def _start(qtbot, win: MainWindow, procedure: str, **values) -> None:
    win.procedure.setCurrentText(procedure)
    for k, v in values.items():
        win.form.set_value(k, v)
    assert win.start_button.isEnabled()
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)


def test_param_form_marks_invalid_values_and_disables_start(window, qtbot):
    win = window
    win.procedure.setCurrentText("demo-decay")
    assert win.start_button.isEnabled()
    win.form.set_value("duration_s", "-5")
    assert not win.start_button.isEnabled()
    err = win.form.errors["duration_s"]
    assert "-5" in err and "0.1" in err  # names the value and the limit
    assert "c00000" in win.form.fields["duration_s"].styleSheet()
    win.form.set_value("duration_s", "abc")
    assert "not a number" in win.form.errors["duration_s"]
    win.form.set_value("rate_dps", "2000")
    assert "above the limit 1000" in win.form.errors["rate_dps"]
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)  # disabled: nothing starts
    assert not win.backend.running()
    win.form.set_value("duration_s", "2")
    win.form.set_value("rate_dps", "100")
    assert win.form.is_valid() and win.start_button.isEnabled()
    assert win.form.fields["duration_s"].styleSheet() == ""


def test_decay_run_fills_the_plots_and_results(window, qtbot):
    win = window
    _start(qtbot, win, "demo-decay", duration_s=5.0, rate_dps=100.0)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.outcome == "PASS" and win.last_finished.safe_state
    # every 1 kHz sample of the 5 s decay reached the ring buffer (5000 rows)
    assert win.plots.fpga.total_rows == 5000
    f = win.plots.recent.view()
    assert f[-1, 0] == pytest.approx(5.0, abs=1e-9)
    # E decays as exp(-2 t / tau) (HRG tau from the preset): checks the derived column
    tau = win.backend.params.tau_s
    assert f[-1, 5] / f[0, 5] == pytest.approx(math.exp(-2 * 5.0 / tau), rel=0.02)
    # theta precesses at -K Omega (Bryan factor) and is drawn unwrapped
    k = win.backend.params.bryan_factor
    slope = np.polyfit(f[:, 0], f[:, 6], 1)[0]
    assert slope == pytest.approx(-k * 100.0, rel=0.02)
    qtbot.waitUntil(lambda: win.plots.refresh_count > 0, timeout=WAIT_MS)
    x, y = win.plots.c_q[0].getData()
    assert x is not None and 10 < len(x) <= win.plots.max_points + 1
    xf, yf = win.plots.c_fit.getData()
    assert xf is not None and len(xf) > 10  # the fit is drawn over E
    x_r, y_r = win.plots.c_rate.getData()
    assert np.allclose(y_r, 100.0)
    # the results table carries the measurement with its PASS colour
    assert win.results.table.rowCount() == 1
    assert win.results.table.item(0, 5).text() == "PASS"
    assert win.results.table.item(0, 0).background().color().name() == "#b7e4b7"
    assert win.steps.status == {"settle": "done", "measure": "done", "safe state": "done"}


def test_start_pause_and_abort_from_the_window(window, qtbot):
    win = window
    win.station.speed.setCurrentText("10x")  # slow enough to abort mid-run
    assert win.backend.clock.speed == 10.0
    _start(qtbot, win, "demo-decay", duration_s=3600.0)
    qtbot.waitUntil(lambda: win.run_active and win.plots.fpga.total_rows > 0, timeout=WAIT_MS)
    assert not win.start_button.isEnabled() and win.abort_button.isEnabled()
    qtbot.waitUntil(lambda: win.steps.progress.value() > 0, timeout=WAIT_MS)
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    assert win.pause_button.text() == "Resume"
    qtbot.wait(300)  # at most one step of the procedure after the pause
    held = win.steps.progress.value()
    qtbot.wait(700)  # 7 simulated seconds at 10x: 7 progress events if it were running
    assert win.steps.progress.value() == held
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    assert win.pause_button.text() == "Pause"
    qtbot.waitUntil(lambda: win.steps.progress.value() > held, timeout=WAIT_MS)
    qtbot.mouseClick(win.abort_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.outcome == "ABORTED"
    assert win.last_finished.safe_state
    assert win.safe_label.text() == "safe state confirmed"
    assert win.steps.status["measure"] == "aborted"
    assert win.backend.world.case_rate_dps == 0.0
    assert win.start_button.isEnabled() and not win.abort_button.isEnabled()
    assert win.t_sim_s < 3600.0


def test_sweep_fills_point_by_point(window, qtbot):
    win = window
    _start(qtbot, win, "demo-sweep", points=11, dwell_s=0.05)
    seen: list[int] = []
    win.bridge.events.connect(lambda _b: seen.append(len(win.plots.sweep)))
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert len(win.plots.sweep) == 11
    x, y = win.plots.c_amp.getData()
    assert len(x) == 11 and np.all(np.diff(x) > 0)
    # the peak sits at the resonance (within the sweep step) of the HRG preset
    f0 = win.backend.params.f0_hz
    assert abs(x[np.argmax(y)] - f0) <= 0.02 / 10 + win.backend.params.split_hz


def test_bridge_delivers_in_the_gui_thread(qtbot):
    bus = ev.EventBus()
    bridge = EventBridge(bus)
    threads: list[QThread] = []
    got: list[int] = []

    def on_batch(batch):
        threads.append(QThread.currentThread())
        got.extend(e.t_sim_s for e in batch)

    bridge.events.connect(on_batch)

    def worker():
        for i in range(2000):
            bus.publish(ev.Log("r", float(i), message="x"))

    t = threading.Thread(target=worker)
    t.start()
    t.join(10)
    qtbot.waitUntil(lambda: len(got) == 2000, timeout=WAIT_MS)
    assert got == list(range(2000))  # in order, none lost
    assert all(th is bridge.thread() for th in threads)
    assert len(threads) < 2000  # batched: the event loop was not woken per event
    assert not bus.errors


def test_bridge_holds_the_publisher_only_when_asked(qtbot):
    """Backpressure (lockstep only): beyond max_pending queued events each publish waits up to
    max_wait_s for the GUI; with max_wait_s = 0 (real time, real bench) it never waits."""
    bus = ev.EventBus()
    bridge = EventBridge(bus, max_pending=10)

    def publish_all() -> float:
        t = threading.Thread(target=lambda: [bus.publish(ev.Log("r", float(i))) for i in range(40)])
        t0 = time.perf_counter()
        t.start()
        t.join(30)  # the GUI thread does not drain meanwhile
        return time.perf_counter() - t0

    assert publish_all() < 0.5  # nothing held
    bridge.drain()
    bridge.max_wait_s = 0.02
    assert publish_all() >= 30 * 0.02 * 0.9  # events 11..40 each waited max_wait_s
    got: list = []
    bridge.events.connect(got.extend)
    bridge.drain()
    assert len(got) == 40


def test_replay_of_a_recorded_run(qtbot, tmp_path):
    from bench.recorder import Recorder

    backend = SimWorldBackend(seed=1)
    path = tmp_path / "run.h5"
    rec = Recorder(path, {"run_id": "rec1", "procedure": "demo-decay", "params": '{"duration_s": 3.0}'})
    backend.bus.subscribe(rec.on_event)
    backend.start("demo-decay", {"duration_s": 3.0})
    assert backend.join(30)
    rec.close()
    backend.close()

    win = MainWindow(SimWorldBackend(seed=2))
    qtbot.addWidget(win)
    win.open_run(str(path))
    assert win.plots.fpga.total_rows == 3000
    assert win.plots.table.total_rows == 3000
    xf, yf = win.plots.c_fit.getData()
    assert xf is not None and len(xf) > 10  # the run's stored fit
    assert win.results.table.rowCount() == 1 and win.results.table.item(0, 0).text() == "tau"
    assert win.last_finished.raw_file == str(path)
    win.backend.close()


def test_screenshot_writes_a_non_blank_png(qtbot, tmp_path):
    from bench.gui.app import take_screenshot

    backend = SimWorldBackend(seed=0)
    win = MainWindow(backend)
    qtbot.addWidget(win)
    out = take_screenshot(win, "demo-decay", tmp_path / "shot.png", at_s=3.0, timeout_s=60)
    assert win.t_sim_s == pytest.approx(3.0, abs=0.11)  # held at the chosen simulated second
    assert win.last_finished is not None and win.last_finished.safe_state
    img = QImage(str(out))
    assert img.width() >= 800 and img.height() >= 600
    colours = {img.pixel(x, y) for x in range(0, img.width(), 7) for y in range(0, img.height(), 7)}
    assert len(colours) > 20  # plots, text and widgets, not one flat colour
    backend.close()


def test_window_on_the_engine_station_runs_and_reports(qtbot, tmp_path, monkeypatch):
    """The real engine on the built-in sim-hrg station (simulators on loopback): the form comes
    from the procedure's declared Params, the run ends PASS with its safe state, the station
    panel shows the table's rate and the report renders from the raw file."""
    monkeypatch.chdir(tmp_path)
    from bench.gui.engine_backend import EngineBackend

    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    qtbot.addWidget(win)
    try:
        win.station.speed.setCurrentText("100x")  # the station's SimClock follows the control
        assert backend.station.clock.speed == 100.0
        win.station.speed.setCurrentText("max")
        assert math.isinf(backend.station.clock.speed)
        win.procedure.setCurrentText("table-spin")
        spec = {s.name: s for s in win.form.specs}["rate_dps"]
        assert (spec.unit, spec.low, spec.high) == ("deg/s", -1000.0, 1000.0)
        win.form.set_value("rate_dps", "5000")
        assert not win.start_button.isEnabled()
        _start(qtbot, win, "table-spin", rate_dps=50.0, hold_s=0.5)
        qtbot.waitUntil(lambda: win.last_finished is not None, timeout=60_000)
        assert win.last_finished.outcome == "PASS" and win.last_finished.safe_state
        assert win.plots.fpga.total_rows > 0 and win.plots.table.total_rows > 0
        table = win.station._items["table"]
        rows = {table.child(i).text(0): table.child(i).text(1) for i in range(table.childCount())}
        assert float(rows["rate_dps"]) == pytest.approx(50.0, abs=0.5)
        assert win.results.report_button.isEnabled()
        html = win.render_report()
        assert html is not None and "table_rate_dps" in open(html).read()
    finally:
        backend.close()


def test_mems_sweep_on_the_engine_fills_amplitude_and_phase_with_the_fit(qtbot, tmp_path, monkeypatch):
    """The MEMS forced sweep on sim-mems: amplitude and phase fill in point by point (the sweep
    row appears with the first point) and the procedure's model is drawn over them."""
    monkeypatch.chdir(tmp_path)
    from bench.gui.engine_backend import EngineBackend

    backend = EngineBackend("sim-mems", seed=0)
    win = MainWindow(backend)
    qtbot.addWidget(win)
    counts: list[int] = []
    win.bridge.events.connect(lambda _b: counts.append(len(win.plots.sweep)))
    try:
        assert not win.plots.sweep_shown
        win.procedure.setCurrentText("mems-sweep")
        assert win.form.fields["both_directions"].isChecked()
        win.form.set_value("both_directions", False)
        _start(qtbot, win, "mems-sweep", n_points=9)
        qtbot.waitUntil(lambda: win.last_finished is not None, timeout=120_000)
        assert win.last_finished.safe_state, win.last_finished.end_reason
        assert len(win.plots.sweep) == 9 and win.plots.sweep_shown
        assert len(set(counts)) > 2  # points arrived over several batches, not all at the end
        x, y = win.plots.c_amp.getData()
        assert np.all(np.diff(x) > 0) and np.all(y > 0)
        xf, yf = win.plots.c_amp_fit.getData()
        assert xf is not None and len(xf) > 9  # the model curve over the points
        xp, _ = win.plots.c_phase.getData()
        assert len(xp) == 9
    finally:
        backend.close()
