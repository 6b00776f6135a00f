"""The window's column per slot (#18): four HRGs in one batch on sim-hrg-4, each column shows its
unit, its outcome, its current step and its own live E(t) -- a slot whose link drops shows ERROR
while the others complete."""

from __future__ import annotations

import threading

import numpy as np


def test_batch_view_shows_a_column_per_slot():
    from PySide6.QtWidgets import QApplication

    from bench.engine.batch import Batch
    from bench.gui.batch_view import BatchView
    from bench.station import Station
    from procedures.hrg_damping import HrgDamping

    app = QApplication.instance() or QApplication([])
    serials = {1: "S1", 2: "S2", 3: "S3", 4: "S4"}
    view = BatchView(serials)
    view.resize(1200, 420)
    view.show()
    station = Station.load("sim-hrg-4", seed=0).open()
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
