"""Screenshots of the operator station (offscreen Qt) for the notes: login with the station's
calibration line, a station with slots filled with one left empty, the batch running (live step
and progress), the verdicts (a link drop into slot 3 makes it ERROR), slot 3 retested alone, and a
station past its calibration refusing to run.

Run: QT_QPA_PLATFORM=offscreen .venv/bin/python benchmarks/operator_screens.py OUT_DIR"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "screens")
    out.mkdir(parents=True, exist_ok=True)
    runs = Path(tempfile.mkdtemp(prefix="gyrobench-screens-"))
    from PySide6.QtWidgets import QApplication

    import bench.composition as composition
    from bench.gui.operator_station import OperatorStation

    app = QApplication.instance() or QApplication([])
    armed = {"on": False}
    real = composition.load_station

    def with_fault(name, **kw):  # the first batch: slot 3's FPGA link drops mid-sweep
        st = real(name, **kw)
        if armed["on"]:
            armed["on"] = False
            st.schedule_fault("link-drop", 2.0, 3)
        return st

    composition.load_station = with_fault

    def shot(win, name: str) -> None:
        app.processEvents()
        path = out / f"operator_{name}.png"
        win.grab().save(str(path), "PNG")
        print(path)

    def wait(win, cond, grab_running: str | None = None) -> None:
        t0 = time.monotonic()
        while not cond() and time.monotonic() - t0 < 600:
            app.processEvents()
            if win.waiting():
                win.yes_button.click()
            if grab_running and any(0 < p.bar.value() < 1000 for p in win.slots.values()):
                win._show_progress()
                shot(win, grab_running)
                grab_running = None
            time.sleep(0.01)
        app.processEvents()

    win = OperatorStation("sim-mems-4", sequence="ci-mems", runs_dir=str(runs), seed=0, lot="LOT-2611")
    win.resize(1200, 780)
    win.show()
    win.operator.setEditText("Ada L")
    shot(win, "login")
    win.log_in()
    for text in ("MR-2611-0001", "", "MR-2611-0003", "MR-2611-0004"):
        win.serial_field.setText(text)
        win.serial_field.returnPressed.emit()
    shot(win, "slots_filled")
    armed["on"] = True
    win.start_batch()
    wait(win, lambda: bool(win.batches_done), grab_running="running")
    shot(win, "verdicts")
    win.retest_kind.setCurrentText("retest reason")
    win.retest.setText("link cable reseated")
    win.retest_slot(3)
    wait(win, lambda: len(win.batches_done) == 2)
    shot(win, "retest")
    win.close()

    from bench.station_config import find_station_file

    st = runs / "sim-hrg-cal.toml"
    st.write_text(find_station_file("sim-hrg").read_text() + "\n[calibration]\ntable = 2026-03-01\n"
                  "frontend = 2027-06-30\nreference_1 = 2027-01-15\n")
    win = OperatorStation(str(st), sequence="ci-spin", runs_dir=str(runs), seed=0)
    win.resize(1200, 780)
    win.show()
    win.operator.setEditText("Ada L")
    win.log_in()
    win.serial_field.setText("HRG-2611-0042")
    win.serial_field.returnPressed.emit()
    shot(win, "refused")
    win.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
