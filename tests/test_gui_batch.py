"""The window's column per slot (#18): four HRGs in one batch on sim-hrg-4, each column shows its
unit, its outcome, its current step and its own live E(t) -- a slot whose link drops shows ERROR
while the others complete."""

from __future__ import annotations

import threading

import numpy as np


def test_batch_view_shows_a_column_per_slot():
    from PySide6.QtWidgets import QApplication

    from bench.composition import load_station
    from bench.engine.batch import Batch
    from bench.gui.batch_view import BatchView
    from procedures.hrg_damping import HrgDamping

    app = QApplication.instance() or QApplication([])
    serials = {1: "S1", 2: "S2", 3: "S3", 4: "S4"}
    view = BatchView(serials)
    view.resize(1200, 420)
    view.show()
    station = load_station("sim-hrg-4", seed=0).open()
    try:
        station.schedule_fault("link-drop", 20.0, slot=3)
        batch = Batch(station, serials)
        view.attach(batch)
        done = threading.Event()
        out: dict = {}

        def run() -> None:
            out["records"] = batch.run(lambda: HrgDamping({"record_s": 40.0, "compensate": False}))
            done.set()

        th = threading.Thread(target=run, daemon=True)
        th.start()
        seen_steps: set[str] = set()
        while not done.wait(0.05):
            app.processEvents()
            view.drain()
            seen_steps |= {c.step.text() for c in view.columns.values()}
        th.join()
        view.drain()
        app.processEvents()
    finally:
        station.close()
    records = out["records"]
    for n, col in view.columns.items():
        assert col.outcome_text == records[n].outcome
        assert col.points > 10
    assert view.columns[3].outcome_text == "ERROR" and "link lost" in view.columns[3].step.text()
    assert all(view.columns[n].outcome_text == "COMPLETE" for n in (1, 2, 4))
    assert any("Record" in s for s in seen_steps)  # the current step was shown while running
    # each column draws its own slot's energy: slot 3's stops at the link drop, the others go on
    t_end = {n: float(np.concatenate(c.t_s)[-1]) for n, c in view.columns.items()}
    assert t_end[3] < 21.0 < min(t_end[n] for n in (1, 2, 4))
    view.detach()


SEQUENCE = """
[sequence]
name = "batch-window-test"

[[step]]
procedure = "hrg-damping"
[step.params]
compensate = false
record_s = 40.0
"""
LIMITS = """
[product]
name = "batch-window-test"
rule = "value"

[limits.delta_inv_tau_per_s]
high = 1.0
unit = "1/s"
"""


def test_line_run_window_shows_the_batch_and_its_units_outcomes(tmp_path, monkeypatch, capsys):
    """`gyrobench line run ... --window`: the batch runs in a worker thread under the window; slot 3's
    link drop shows ERROR in its column, the others PASS, and the CLI prints the same four records."""
    from bench.cli import main
    from bench.gui import batch_window

    (tmp_path / "seq.toml").write_text(SEQUENCE)
    (tmp_path / "limits.toml").write_text(LIMITS)
    shown: dict = {}
    real = batch_window.BatchWindow.closeEvent

    def keep(self, event):  # what the window shows when the batch ends and it closes
        shown.update({c.serial: c.outcome_text for c in self.view.columns.values()}, status=self.status.text())
        real(self, event)

    monkeypatch.setattr(batch_window.BatchWindow, "closeEvent", keep)
    code = main(["line", "run", str(tmp_path / "seq.toml"), "--limits", str(tmp_path / "limits.toml"),
                 "--station", "sim-hrg-4", "--dut", "W1", "--dut", "W2", "--dut", "W3", "--dut", "W4",
                 "--operator", "ann", "--yes", "--fault", "link-drop@20:slot3", "--window", "--close-when-done",
                 "--runs-dir", str(tmp_path / "runs"), "--db", f"sqlite:///{tmp_path / 'line.sqlite'}"])
    out = capsys.readouterr().out
    assert code == 4  # the worst unit ERROR (docs/line.md: exit codes)
    assert "batch of 4 units on sim-hrg-4: ERROR 1, PASS 3" in out
    assert shown["W3"] == "ERROR" and all(shown[s] == "PASS" for s in ("W1", "W2", "W4"))
    assert shown["status"].startswith("batch done: ERROR 1, PASS 3")


def test_line_run_window_on_a_one_unit_station_says_where_its_window_is(tmp_path, capsys):
    from bench.cli import main

    code = main(["line", "run", "ci-spin", "--dut", "X1", "--operator", "ann", "--yes", "--window",
                 "--runs-dir", str(tmp_path)])
    err = capsys.readouterr().err
    assert code != 0 and "gyrobench gui --operator" in err and "Traceback" not in err


def test_line_run_window_abort_button_aborts_every_slot(tmp_path, monkeypatch, capsys):
    """The window's Abort during the decay: every slot's run ends ABORTED with the window's reason (its
    drive cut, the table to rest); each unit is ABORTED (not ERROR: the limits its run never reached
    are SKIPPED, naming the abort, as for a one-unit run aborted by Ctrl-C), and the window shows it."""
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from bench.cli import main
    from bench.gui import batch_window

    (tmp_path / "seq.toml").write_text(SEQUENCE.replace("record_s = 40.0", "record_s = 600.0"))
    (tmp_path / "limits.toml").write_text(LIMITS)
    shown: dict = {}
    real_close, real_init = batch_window.BatchWindow.closeEvent, batch_window.BatchWindow.__init__

    def init(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        QTimer.singleShot(2500, self.abort_button.click)  # the operator presses Abort mid-run

    def keep(self, event):
        shown.update({c.serial: c.outcome_text for c in self.view.columns.values()}, status=self.status.text())
        real_close(self, event)

    monkeypatch.setattr(batch_window.BatchWindow, "__init__", init)
    monkeypatch.setattr(batch_window.BatchWindow, "closeEvent", keep)
    QApplication.instance() or QApplication([])
    code = main(["line", "run", str(tmp_path / "seq.toml"), "--limits", str(tmp_path / "limits.toml"),
                 "--station", "sim-hrg-4", "--dut", "A1", "--dut", "A2", "--dut", "A3", "--dut", "A4",
                 "--operator", "ann", "--yes", "--window", "--close-when-done",
                 "--runs-dir", str(tmp_path / "runs"), "--db", f"sqlite:///{tmp_path / 'line.sqlite'}"])
    out = capsys.readouterr().out
    assert code == 5  # ABORTED (docs/line.md: exit codes)
    assert all(shown[s] == "ABORTED" for s in ("A1", "A2", "A3", "A4")), (shown, out[-3000:])
    assert "batch of 4 units on sim-hrg-4: ABORTED 4" in out
    import json

    for s in ("A1", "A2", "A3", "A4"):
        rec = json.loads((tmp_path / "runs" / "line" / "no-lot" / f"{s}-a1.json").read_text())
        runs = [(r["outcome"], r["end_reason"]) for r in rec["runs"]]
        assert runs == [("ABORTED", "aborted: operator abort from the window")]
        assert rec["outcome"] == "ABORTED"
        reached = [m for m in rec["measurements"] if m["rule"]]
        assert reached and all(m["outcome"] == "SKIPPED" for m in reached), reached
        assert any(m["note"] == "not measured: the run ended (aborted: operator abort from the window)"
                   for m in reached)
