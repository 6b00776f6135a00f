"""The lab engineer's window, offscreen (pytest-qt): start, pause and abort from the window,
parameter validation, plots that receive the stream, the replay of a recorded run, the
screenshot option, and the bridge that keeps widgets in the GUI thread.

The source is the engine itself (`EngineBackend`) on the built-in simulated stations: the
simulators on loopback transports, one World integrated at 1 kHz in virtual time.
"""

from __future__ import annotations

import json
import math
import threading
import time

import h5py
import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import Qt, QThread  # noqa: E402
from PySide6.QtGui import QImage  # noqa: E402

from bench.engine import events as ev  # noqa: E402
from bench.gui.bridge import EventBridge  # noqa: E402
from bench.gui.engine_backend import EngineBackend  # noqa: E402
from bench.gui.main_window import MainWindow  # noqa: E402

WAIT_MS = 60_000  # generous wall timeouts: 2 shared cores


@pytest.fixture
def window(qtbot, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.ask_close_during_run = lambda: True  # a test that fails mid-run must not wait on a question box
    qtbot.addWidget(win)
    win.show()
    yield win
    backend.close()


def _start(qtbot, win: MainWindow, procedure: str, **values) -> None:
    win.procedure.setCurrentText(procedure)
    for k, v in values.items():
        win.form.set_value(k, v)
    assert win.start_button.isEnabled(), win.form.errors
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)


def test_param_form_is_the_engines_params_and_disables_start(window, qtbot):
    from procedures import find_procedure

    win = window
    win.procedure.setCurrentText("table-spin")
    declared = find_procedure("table-spin").param_specs()
    assert all(p is declared[p.name] for p in win.form.specs)  # the engine's own Param objects
    assert win.start_button.isEnabled()
    win.form.set_value("hold_s", "-5")
    assert not win.start_button.isEnabled()
    assert win.form.errors["hold_s"] == "hold_s=-5 s is below the limit 0.1 s"
    assert "c00000" in win.form.fields["hold_s"].styleSheet()
    win.form.set_value("hold_s", "abc")
    assert win.form.errors["hold_s"] == "hold_s='abc' is not a number"
    win.form.set_value("rate_dps", "2000")
    assert win.form.errors["rate_dps"] == "rate_dps=2000 deg/s is above the limit 1000 deg/s"
    qtbot.mouseClick(win.start_button, Qt.MouseButton.LeftButton)  # disabled: nothing starts
    assert not win.backend.running()
    win.form.set_value("hold_s", "2")
    win.form.set_value("rate_dps", "100")
    assert win.form.is_valid() and win.start_button.isEnabled()
    assert win.form.fields["hold_s"].styleSheet() == ""
    assert win.form.values() == {"rate_dps": 100.0, "hold_s": 2.0, "tolerance_dps": 0.5}


def test_decay_run_fills_the_plots_and_results(window, qtbot):
    win = window
    _start(qtbot, win, "hrg-free-decay", record_s=5.0, rate_dps=100.0)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    fin = win.last_finished
    assert fin.outcome in ("PASS", "COMPLETE") and fin.safe_state, fin.end_reason
    assert win.backend.join(60)  # the runner closes the raw file after it announced the end
    with h5py.File(fin.raw_file, "r") as f:
        cols = json.loads(f["streams/fpga"].attrs["columns"])
        fpga = f["streams/fpga"][:][:, [cols.index(c) for c in ("t_s", "cx", "sx", "cy", "sy")]]
        t0_s, t1_s = f["streams/decay_window"][-1][:2]
    # every 1 kHz sample the engine recorded reached the window's buffers, unchanged
    assert win.plots.fpga.total_rows == len(fpga)
    recent = win.plots.recent.view()
    np.testing.assert_array_equal(recent[:, :5], fpga[-len(recent):])
    rec = recent[(recent[:, 0] >= t0_s) & (recent[:, 0] <= t1_s)]
    assert rec[-1, 0] - rec[0, 0] == pytest.approx(5.0, abs=0.01)
    # in the free decay E falls as exp(-2 t / tau) (the station's resonator): the derived column
    truth = win.backend.station.world.params
    span_s = rec[-1, 0] - rec[0, 0]
    assert rec[-1, 5] / rec[0, 5] == pytest.approx(math.exp(-2 * span_s / truth.tau_s), rel=0.02)
    # theta precesses at -K Omega (Bryan factor) and is drawn unwrapped
    slope = np.polyfit(rec[:, 0], rec[:, 6], 1)[0]
    assert slope == pytest.approx(-truth.bryan_factor * 100.0, rel=0.02)
    qtbot.waitUntil(lambda: win.plots.refresh_count > 0, timeout=WAIT_MS)
    x, y = win.plots.c_q[0].getData()
    assert x is not None and 10 < len(x) <= win.plots.max_points + 1
    xe, _ = win.plots.c_e.getData()
    assert xe is not None and len(xe) > 10  # E on its log axis
    _, y_r = win.plots.c_rate.getData()
    assert np.max(y_r) == pytest.approx(100.0, abs=0.5)
    # the results table carries the procedure's measurements
    names = [win.results.table.item(i, 0).text() for i in range(win.results.table.rowCount())]
    assert "tau_s" in names and "bryan_factor" in names
    assert set(win.steps.status.values()) == {"done"}


def test_start_pause_and_abort_from_the_window(window, qtbot):
    win = window
    win.station.speed.setCurrentText("max")  # lockstep: pause holds the world with the run
    _start(qtbot, win, "hrg-free-decay", record_s=3600.0)
    qtbot.waitUntil(lambda: win.run_active and win.plots.fpga.total_rows > 0, timeout=WAIT_MS)
    assert not win.start_button.isEnabled() and win.abort_button.isEnabled()
    qtbot.waitUntil(lambda: win.steps.progress.value() > 0, timeout=WAIT_MS)
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    assert win.pause_button.text() == "Resume"
    qtbot.wait(300)  # at most one step of the procedure after the pause
    held = win.steps.progress.value()
    qtbot.wait(700)  # tens of simulated seconds at max: several progress events if it were running
    assert win.steps.progress.value() == held
    qtbot.mouseClick(win.pause_button, Qt.MouseButton.LeftButton)
    assert win.pause_button.text() == "Pause"
    qtbot.waitUntil(lambda: win.steps.progress.value() > held, timeout=WAIT_MS)
    qtbot.mouseClick(win.abort_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    assert win.last_finished.outcome == "ABORTED"
    assert win.last_finished.safe_state
    assert win.safe_label.text() == "safe state confirmed"
    assert win.steps.status["record"] == "aborted"
    # at rest: the driver confirmed |rate| < 0.05 deg/s on its (noisy) reading
    assert win.backend.station.world.case_rate_dps == pytest.approx(0.0, abs=0.1)
    assert win.start_button.isEnabled() and not win.abort_button.isEnabled()
    assert win.t_sim_s < 3600.0


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


@pytest.mark.serial  # 40 unheld publishes within 0.5 s of wall time: run alone
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


def test_replay_of_a_recorded_run(window, qtbot):
    win = window
    _start(qtbot, win, "hrg-damping", record_s=3.0, compensate=False)
    qtbot.waitUntil(lambda: win.last_finished is not None, timeout=WAIT_MS)
    path = win.last_finished.raw_file
    assert win.backend.join(60)  # the runner closes the raw file after it announced the end
    with h5py.File(path, "r") as f:
        n_fpga, n_table = len(f["streams/fpga"]), len(f["streams/table"])
        n_results = len(f["measurements"])

    n_live_log = win.log.text.blockCount()
    replay = win.open_run(str(path))  # its own window: the live window's plots, results and log stay
    qtbot.addWidget(replay)
    assert replay is not win and replay.plots is not win.plots
    assert replay.plots.fpga.total_rows == n_fpga
    assert replay.plots.table.total_rows == n_table
    xf, yf = replay.plots.c_fit.getData()
    assert xf is not None and len(xf) > 10  # the run's stored fit
    assert replay.results.table.rowCount() == n_results
    assert replay.raw_file == str(path)
    assert win.log.text.blockCount() == n_live_log


def test_screenshot_writes_a_non_blank_png(window, tmp_path):
    from bench.gui.app import take_screenshot

    win = window
    out = take_screenshot(win, "hrg-free-decay", tmp_path / "shot.png", at_s=3.0, timeout_s=120)
    assert win.t_sim_s == pytest.approx(3.0, abs=0.11)  # held at the chosen simulated second
    assert win.last_finished is not None and win.last_finished.safe_state
    img = QImage(str(out))
    assert img.width() >= 800 and img.height() >= 600
    colours = {img.pixel(x, y) for x in range(0, img.width(), 7) for y in range(0, img.height(), 7)}
    assert len(colours) > 20  # plots, text and widgets, not one flat colour


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
        param = {p.name: p for p in win.form.specs}["rate_dps"]
        assert (param.unit, param.low, param.high) == ("deg/s", -1000.0, 1000.0)
        win.form.set_value("rate_dps", "5000")
        assert not win.start_button.isEnabled()
        _start(qtbot, win, "table-spin", rate_dps=50.0, hold_s=0.5)
        qtbot.waitUntil(lambda: win.last_finished is not None, timeout=60_000)
        assert win.last_finished.outcome == "PASS" and win.last_finished.safe_state
        assert win.plots.fpga.total_rows > 0 and win.plots.table.total_rows > 0
        table = win.station._items["table"]
        rows = {table.child(i).text(0): table.child(i).text(1) for i in range(table.childCount())}
        assert float(rows["rate_dps"]) == pytest.approx(0.0, abs=0.5)  # after the safe state: at rest
        axis = win.plots.p_rate.getAxis("left")
        assert (axis.labelText, axis.labelUnits) == ("rate_dps", "deg/s")  # the stream's declared unit
        from bench.gui.replay import replay_events

        assert backend.join(60)  # the runner closes the raw file after it announced the end
        declared = {e.schema.name: e.schema for e in replay_events(win.last_finished.raw_file)
                    if isinstance(e, ev.StreamDeclared)}
        assert declared["table"].units == ("s", "deg/s", "deg") and declared["fpga"].source == "fpga"
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
