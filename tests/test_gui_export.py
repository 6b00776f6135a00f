"""Export from the window (offscreen): "E" holds E and its fit beside cx..sy; a sweep plot is
offered only on a run with a sweep; raw data is written by a worker thread (the GUI thread keeps
drawing) and the status bar then says where the file is and how large."""

from __future__ import annotations

import threading

import h5py
import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.engine import events as ev  # noqa: E402
from bench.recorder import Recorder  # noqa: E402

Q_COLS = ("t_s", "cx", "sx", "cy", "sy")
TAU_S = 2.0


def _write(path, n: int = 3000, sweep: bool = False) -> np.ndarray:
    """A decay raw file as the recorder writes it: fpga rows with E = exp(-2t/tau), its stored fit
    (every 10th sample), and, when asked, a sweep stream."""
    t = np.arange(n) * 1e-3
    a = np.exp(-t / TAU_S)
    rows = np.column_stack((t, a, 0 * t, 0 * t, 0 * t))
    rec = Recorder(path, {"run_id": "r1", "procedure": "mems-sweep" if sweep else "hrg-free-decay",
                          "station_id": "sim-hrg", "params": {}, "simulated": True, "station": {"id": "sim-hrg"}},
                   {})
    rec.on_event(ev.SampleBlock("r1", t[-1], stream="fpga", columns=Q_COLS, data=rows))
    rec.on_event(ev.FitUpdate("r1", t[-1], name="hrg-free-decay elements",
                              curves={"t_s": t[::10], "energy_fit": a[::10] ** 2}))
    if sweep:
        rec.on_event(ev.SampleBlock("r1", 1.0, stream="sweep", columns=("t_s", "freq_hz", "amplitude", "phase_deg"),
                                    data=np.array([[0.0, 100.0, 1.0, 0.0], [1.0, 101.0, 2.0, 45.0]])))
    rec.close()
    with h5py.File(path, "a") as f:
        f.attrs.update({"outcome": "COMPLETE", "end_reason": "", "safe_state": True})
    return rows


@pytest.fixture
def replay(tmp_path, qtbot):
    from bench.gui.replay_view import ReplayWindow

    raw = tmp_path / "run.h5"
    rows = _write(raw)
    win = ReplayWindow(raw)
    qtbot.addWidget(win)
    win.show()
    return win, rows


def test_exporting_e_holds_e_and_its_fit(replay, tmp_path):
    from bench.gui.export import ExportDialog

    win, rows = replay
    dialog = ExportDialog(win.plots, win.raw_file, win, "E")
    assert dialog.plot.currentText() == "E"
    dialog.export_to(str(tmp_path / "e.csv"))
    assert "with E and its fit" in dialog.wait()
    with open(tmp_path / "e.csv") as fh:
        head = [next(fh) for _ in range(3)]
    assert head[2].strip().split(",")[-2:] == ["E [1]", "E_fit [1]"]
    back = np.loadtxt(tmp_path / "e.csv", delimiter=",", comments="#", skiprows=3)
    e_true = np.exp(-2 * rows[:, 0] / TAU_S)
    np.testing.assert_allclose(back[:, 5], e_true, rtol=1e-12)  # E = cx^2 + ... from the record
    np.testing.assert_allclose(back[:-9, 6], e_true[:-9], rtol=1e-9)  # the fit, at every sample it spans
    assert np.all(np.isnan(back[-9:, 6]))  # beyond the fit's last point: no fit, not an extrapolation
    dialog.plot.setCurrentText("E")
    dialog.export_to(str(tmp_path / "e.h5"))
    dialog.wait()
    with h5py.File(tmp_path / "e.h5") as f:
        assert f["fpga"].shape == (len(rows), 7)


def test_sweep_plots_are_offered_only_on_a_run_with_a_sweep(replay, tmp_path, qtbot):
    from bench.gui.export import ExportDialog
    from bench.gui.replay_view import ReplayWindow

    win, _rows = replay
    offered = [ExportDialog(win.plots, win.raw_file, win).plot.itemText(i) for i in range(9)]
    assert "E" in offered and "sweep amplitude" not in offered and "sweep phase" not in offered
    raw = tmp_path / "sweep.h5"
    _write(raw, sweep=True)
    sweep_win = ReplayWindow(raw)
    qtbot.addWidget(sweep_win)
    sweep_win.show()
    dialog = ExportDialog(sweep_win.plots, sweep_win.raw_file, sweep_win)
    offered = [dialog.plot.itemText(i) for i in range(dialog.plot.count())]
    assert "sweep amplitude" in offered and "sweep phase" in offered


def test_raw_data_is_written_off_the_gui_thread_and_the_status_says_where_and_how_large(
        replay, tmp_path, monkeypatch):
    from bench.gui import export
    from bench.gui.export import ExportDialog

    win, rows = replay
    threads: list[int] = []
    original = export.export_csv

    def spy(*args, **kwargs):
        threads.append(threading.get_ident())
        return original(*args, **kwargs)

    monkeypatch.setattr(export, "export_csv", spy)
    monkeypatch.setattr(export, "CSV_CHUNK_ROWS", 500)  # several progress reports
    seen: list[float] = []
    dialog = ExportDialog(win.plots, win.raw_file, win, "cx sx cy sy")
    dialog.signals.progress.connect(seen.append)
    out = tmp_path / "q.csv"
    started = dialog.export_to(str(out))
    assert started.startswith("exporting") and dialog.worker is not None
    note = dialog.wait()
    assert threads and threads[0] != threading.get_ident()  # not the GUI thread
    assert seen and seen[-1] == pytest.approx(1.0) and len(seen) >= 5
    size_kb = out.stat().st_size / 1e3
    assert f"{len(rows)} rows" in note and str(out) in note and f"({size_kb:.1f} kB)" in note
    assert win.statusBar().currentMessage() == note
