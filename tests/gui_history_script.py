"""Driven by tests/test_gui_xvfb_history.py under xvfb-run: an aborted run and a run to the end,
then the history browser (File > Run history...), filtered, opens the finished run for replay
in its own window; the replay's values are checked against the raw file, a plot is exported to
CSV, HDF5 and PNG, and the report is opened.  Prints one JSON line of what it saw; argv[1:]:
the history and replay screenshot paths, and the export folder."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import h5py
import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

from bench.gui.engine_backend import EngineBackend
from bench.gui.main_window import MainWindow


def wait(cond, timeout_s: float = 90.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        QApplication.processEvents()
        if cond():
            return True
        time.sleep(0.01)
    return False


def click(button) -> None:
    QTest.mouseClick(button, Qt.MouseButton.LeftButton)
    QApplication.processEvents()


def run(win: MainWindow, backend: EngineBackend, record_s: str, abort_after_rows: int | None = None) -> str:
    win.procedure.setCurrentText("hrg-free-decay")
    win.form.set_value("record_s", record_s)
    win.last_finished = None
    click(win.start_button)
    if abort_after_rows is not None:
        wait(lambda: win.plots.fpga.total_rows > abort_after_rows)
        click(win.abort_button)
    wait(lambda: win.last_finished is not None)
    wait(lambda: not backend.running(), 30)
    return win.last_finished.outcome


def main(history_shot: str, replay_shot: str, out_dir: str) -> int:
    app = QApplication.instance() or QApplication(["gyrobench"])
    backend = EngineBackend("sim-hrg", seed=0)
    win = MainWindow(backend)
    win.show()
    seen: dict[str, object] = {"platform": app.platformName()}
    out = Path(out_dir)
    try:
        win.station.speed.setCurrentText("max")
        seen["aborted"] = run(win, backend, "60", abort_after_rows=2000)
        seen["completed"] = run(win, backend, "5")
        run_id, raw = win.run_id, win.last_finished.raw_file
        seen["run_id"] = run_id
        win.history_action.trigger()
        hist = win.side_windows[-1]
        seen["history_all"] = wait(lambda: not hist.busy() and hist.model.rowCount() >= 2, 30) and \
            hist.model.rowCount()
        hist.procedure.setCurrentText("hrg-free-decay")
        hist.outcome.setCurrentText("COMPLETE")
        seen["history_filtered"] = wait(lambda: not hist.busy() and hist.model.rowCount() == 1, 30) and \
            [r["run_id"] for r in hist.model.rows]
        hist.outcome.setCurrentIndex(0)  # any outcome again, for the screenshot
        wait(lambda: not hist.busy() and hist.model.rowCount() >= 2, 30)
        seen["selected"] = hist.select_run(run_id)
        hist.resize(1200, 420)
        wait(lambda: False, 0.3)
        seen["history_shot"] = hist.grab().save(history_shot, "PNG")
        click(hist.replay_button)
        replay = hist.replays[-1]
        replay.show()
        with h5py.File(raw, "r") as f:
            fpga = f["streams/fpga"][()]
            cols = json.loads(f["streams/fpga"].attrs["columns"])
            n_meas = len(f["measurements"])
        idx = [cols.index(c) for c in ("cx", "sx", "cy", "sy")]
        seen["replay_rows"] = replay.plots.fpga.total_rows
        seen["file_rows"] = len(fpga)
        seen["replay_last_equal"] = bool(np.allclose(replay.plots.recent.view()[-1, 1:5], fpga[-1, idx]))
        seen["replay_results"] = replay.results.table.rowCount()
        seen["file_measurements"] = n_meas
        params = {replay.params.item(r, 0).text(): (replay.params.item(r, 1).text(), replay.params.item(r, 2).text())
                  for r in range(replay.params.rowCount())}
        seen["param_record_s"] = params.get("record_s")
        seen["banner"] = replay.banner.text()
        seen["live_log_separate"] = replay.log is not win.log and replay.plots is not win.plots
        wait(lambda: False, 0.3)
        replay.plots.refresh(force=True)
        seen["replay_shot"] = replay.grab().save(replay_shot, "PNG")
        # export from the replay's File > Export... dialog (its Save without the file picker)
        from bench.gui.export import plot_sources

        title = next(t for t, (_p, s) in plot_sources(replay.plots).items() if s == "fpga")
        dialog = replay.export_dialog()
        dialog.plot.setCurrentText(title)
        for ext in ("csv", "h5", "png"):
            dialog.export_to(str(out / f"fpga.{ext}"))  # raw data: written by a worker thread
            seen[f"export_{ext}"] = dialog.wait()
        dialog.close()
        back = np.loadtxt(out / "fpga.csv", delimiter=",", comments="#", skiprows=3)
        seen["csv_equal"] = bool(back.shape == fpga.shape and np.array_equal(back, fpga))
        with h5py.File(out / "fpga.h5", "r") as f:
            seen["h5_equal"] = bool(np.array_equal(f["fpga"][()], fpga))
        seen["png_bytes"] = (out / "fpga.png").stat().st_size
        # the report from the history browser: rendered, then handed to the system; here the system
        # refuses (as where no browser can start; a real one would open windows on the test's X server)
        from PySide6.QtGui import QDesktopServices

        from bench.gui import open_report

        handed: list[str] = []
        open_report.opener_argv = lambda _path: None  # Qt's own call, stubbed: no xdg-open on the test's display
        QDesktopServices.openUrl = staticmethod(lambda url: handed.append(url.toLocalFile()) and False)
        click(hist.report_button)
        seen["report_handed"] = handed
        seen["report_exists"] = Path(raw).with_suffix(".html").exists()
        dlg = hist.dialog
        seen["report_dialog"] = None if dlg is None else dlg.path.text()
        replay.close()
        hist.close()
    finally:
        win.close()
        backend.close()
    print(json.dumps(seen))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:4]))
