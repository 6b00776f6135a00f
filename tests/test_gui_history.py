"""Runs you can find (offscreen): the store's search by procedure, station, DUT, outcome and date;
the history browser that opens a run for replay in its own window; a replay that says when its
raw file is incomplete or corrupt; the export of a plot's recorded samples (CSV, HDF5) and figure
(PNG, SVG); and "Open report" where no browser can be started."""

from __future__ import annotations

import datetime as dt
import json
import os

import h5py
import numpy as np
import pytest

pytest.importorskip("pytestqt")
pytest.importorskip("pyqtgraph")

from bench.engine import events as ev  # noqa: E402
from bench.recorder import Recorder, open_run  # noqa: E402
from bench.results import ResultsStore  # noqa: E402
from bench.results.query import RunFilter, find_runs  # noqa: E402

Q_COLS = ("t_s", "cx", "sx", "cy", "sy")


def run_doc(run_id: str, *, procedure: str = "hrg-free-decay", station: str = "sim-hrg", outcome: str = "COMPLETE",
            started: str = "2026-11-20T10:00:00+00:00", duts: tuple[str, ...] = (), raw_file: str | None = None,
            pid: int | None = None) -> dict:
    """A run document as the store keeps it (what `ResultsStore.record_doc` makes of a record)."""
    row = {"run_id": run_id, "procedure": procedure, "station_id": station, "simulated": True, "outcome": outcome,
           "end_reason": "" if outcome == "COMPLETE" else f"the run ended {outcome}", "safe_state": True,
           "failed_step": None, "started_at": started, "finished_at": started, "simulated_s": 12.5,
           "wall_s": 1.0, "raw_file": raw_file, "software_version": "test", "operator": "", "seed": 0,
           "params": {"record_s": 3.0}, "safe_detail": None, "host": "elsewhere" if pid is None else os.uname()[1],
           "pid": pid, "heartbeat_at": started}
    return {"run": row, "duts": list(duts), "truth": {}, "measurements": []}


def write_raw(path, run_id: str = "r1", n: int = 4321, outcome: str | None = "COMPLETE", seed: int = 3) -> np.ndarray:
    """A raw file as the recorder writes it: an fpga stream of n random rows (returned), a table
    stream, parameters with units, one measurement; `outcome=None` leaves it unfinished."""
    rng = np.random.default_rng(seed)
    rows = np.column_stack([np.arange(n) * 1e-3, rng.normal(size=(n, 4)) * 1e-3 + [1.0, 0.0, 0.0, 0.0]])
    rec = Recorder(path, {"run_id": run_id, "procedure": "hrg-free-decay", "station_id": "sim-hrg",
                          "params": {"record_s": 3.0, "rate_dps": 200.0}, "simulated": True,
                          "station": {"id": "sim-hrg", "devices": {"table": {"driver": "modbus-table"}}},
                          "truth": {"tau_s": 300.0}},
                   {"record_s": "s", "rate_dps": "deg/s"})
    for i in range(0, n, 1000):
        rec.on_event(ev.SampleBlock(run_id, rows[min(i + 999, n - 1), 0], stream="fpga", columns=Q_COLS,
                                    data=rows[i:i + 1000]))
    rec.on_event(ev.SampleBlock(run_id, 1.0, stream="table", columns=("t_s", "rate_dps"),
                                data=np.array([[0.0, 0.0], [1.0, 200.0]])))
    rec.on_event(ev.Measurement(run_id, 1.0, name="tau_s", value=299.5, unit="s", outcome="COMPLETE",
                                ci95=(298.0, 301.0)))
    rec.close()
    if outcome is not None:
        with h5py.File(path, "a") as f:
            f.attrs["outcome"] = outcome
            f.attrs["end_reason"] = ""
            f.attrs["safe_state"] = True
    else:
        with h5py.File(path, "a") as f:
            for k in ("outcome",):
                if k in f.attrs:
                    del f.attrs[k]
    return rows


@pytest.fixture
def store(tmp_path):
    s = ResultsStore(tmp_path / "results.sqlite")
    yield s
    s.close()


def test_find_runs_filters_by_procedure_station_dut_outcome_and_date(store_url):
    """The same query on SQLite and PostgreSQL (store_url: both engines, conftest.py)."""
    store = ResultsStore(store_url)
    docs = [
        run_doc("a", started="2026-11-01T09:00:00+00:00", duts=("HRG-001",)),
        run_doc("b", procedure="mems-sweep", station="sim-mems", started="2026-11-02T09:00:00+00:00"),
        run_doc("c", outcome="ERROR", started="2026-11-03T23:59:59+00:00", duts=("HRG-002", "HRG-003")),
        run_doc("d", outcome="RUNNING", started="2026-11-04T09:00:00+00:00", pid=2**22 + 12345),  # gone
    ]
    for d in docs:
        store.save_doc(d)
    rows, total = find_runs(store, RunFilter())
    assert [r["run_id"] for r in rows] == ["d", "c", "b", "a"] and total == 4
    assert rows[0]["outcome"] == "INTERRUPTED"  # its process is gone: shown as such, not RUNNING
    assert rows[1]["duts"] == "HRG-002, HRG-003"

    def ids(**kw) -> list[str]:
        return [r["run_id"] for r in find_runs(store, RunFilter(**kw))[0]]

    assert ids(procedure="mems-sweep") == ["b"]
    assert ids(station_id="sim-hrg") == ["d", "c", "a"]
    assert ids(dut="HRG-00") == ["c", "a"] and ids(dut="003") == ["c"]
    assert ids(outcome="ERROR") == ["c"] and ids(outcome="INTERRUPTED") == ["d"]
    assert ids(since=dt.date(2026, 11, 2), until=dt.date(2026, 11, 3)) == ["c", "b"]  # whole days, inclusive
    rows, total = find_runs(store, RunFilter(limit=2))
    assert len(rows) == 2 and total == 4
    store.close()


def test_history_browser_filters_and_opens_a_run_in_its_own_replay_window(store, tmp_path, qtbot):
    from bench.gui.history import HistoryBrowser

    raw = tmp_path / "r1.h5"
    rows = write_raw(raw, "r1")
    store.save_doc(run_doc("r1", raw_file=str(raw), duts=("HRG-007",)))
    store.save_doc(run_doc("r0", outcome="ABORTED", started="2026-11-19T10:00:00+00:00"))
    win = HistoryBrowser(store.url)
    qtbot.addWidget(win)
    qtbot.waitUntil(lambda: not win.busy() and win.model.rowCount() == 2, timeout=10_000)
    win.outcome.setCurrentText("COMPLETE")
    qtbot.waitUntil(lambda: not win.busy() and win.model.rowCount() == 1, timeout=10_000)
    assert win.select_run("r1") and win.replay_button.isEnabled()
    assert win.raw_path.text() == str(raw)
    replay = win.open_replay()
    qtbot.addWidget(replay)
    assert replay.plots.fpga.total_rows == len(rows)
    np.testing.assert_allclose(replay.plots.recent.view()[-1, 1:5], rows[-1, 1:5])  # the recorded values
    params = {replay.params.item(r, 0).text(): (replay.params.item(r, 1).text(), replay.params.item(r, 2).text())
              for r in range(replay.params.rowCount())}
    assert params == {"record_s": ("3", "s"), "rate_dps": ("200", "deg/s")}
    assert replay.results.table.rowCount() == 1 and "COMPLETE" in replay.banner.text()
    assert replay.station.topLevelItem(0).text(0) == "id" and replay.station.topLevelItem(0).text(1) == "sim-hrg"
    win.dut.setText("nothing-like-it")
    qtbot.waitUntil(lambda: not win.busy() and win.model.rowCount() == 0, timeout=10_000)
    assert win.count.text().startswith("0 run(s)")


def test_replay_says_when_the_raw_file_is_corrupt_or_incomplete(tmp_path, qtbot):
    from bench.gui.replay_view import ReplayWindow

    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(np.random.default_rng(0).bytes(50_000))
    good = tmp_path / "good.h5"
    write_raw(good)
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    unfinished = tmp_path / "unfinished.h5"
    write_raw(unfinished, outcome=None)
    for path in (garbage, truncated):
        win = ReplayWindow(path)
        qtbot.addWidget(win)
        assert "truncated or corrupt" in win.banner.text() and path.name in win.banner.text()
        assert "8b0000" in win.banner.styleSheet() and win.raw_file is None  # red; nothing to export
        assert win.plots.fpga.total_rows == 0
    win = ReplayWindow(unfinished)
    qtbot.addWidget(win)
    assert win.banner.text().startswith("Incomplete raw file: the run did not finish")
    assert win.plots.fpga.total_rows == 4321  # what was recorded is shown
    missing = ReplayWindow(tmp_path / "nope.h5")
    qtbot.addWidget(missing)
    assert "does not exist" in missing.banner.text()


def test_export_holds_exactly_the_recorded_samples_with_names_and_units(tmp_path, qtbot):
    from bench.gui.export import ExportDialog, export_plot, plot_sources
    from bench.gui.replay_view import ReplayWindow

    raw = tmp_path / "run.h5"
    rows = write_raw(raw, n=25_000)  # more rows than the plot draws (1200 per curve)
    win = ReplayWindow(raw)
    qtbot.addWidget(win)
    win.show()
    title = next(t for t, (_p, s) in plot_sources(win.plots).items() if s == "fpga")
    assert len(win.plots.c_q[0].getData()[0]) < len(rows)  # what is drawn is decimated
    dialog = ExportDialog(win.plots, win.raw_file, win)
    dialog.plot.setCurrentText(title)
    dialog.export_to(str(tmp_path / "q.csv"))  # written by a worker thread
    assert "25000 rows" in dialog.wait()
    with open(tmp_path / "q.csv") as fh:
        head = [next(fh) for _ in range(3)]
    with open_run(raw) as data:
        units = data.units("fpga")
    assert head[2].strip() == ",".join(f"{c} [{units[c]}]" for c in Q_COLS) and units["t_s"] == "s"
    back = np.loadtxt(tmp_path / "q.csv", delimiter=",", comments="#", skiprows=3)
    assert back.shape == rows.shape and np.array_equal(back, rows)  # bit for bit
    export_plot(win.plots, title, win.raw_file, tmp_path / "q.h5")
    with h5py.File(tmp_path / "q.h5") as f:
        assert np.array_equal(f["fpga"][()], rows)
        assert json.loads(f["fpga"].attrs["columns"]) == list(Q_COLS)
        stored = [u.decode() if isinstance(u, bytes) else u for u in f["fpga"].attrs["units"]]
        assert stored == [units[c] for c in Q_COLS]
        assert f.attrs["run_id"] == "r1"
    for suffix in ("png", "svg"):
        out = tmp_path / f"q.{suffix}"
        export_plot(win.plots, title, win.raw_file, out)
        assert out.stat().st_size > 2_000
    assert (tmp_path / "q.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "q.svg").read_bytes()[:2000]


def test_open_report_without_a_browser_shows_the_path_and_copies_it(tmp_path, qtbot, monkeypatch):
    from PySide6.QtGui import QDesktopServices, QGuiApplication

    from bench.gui import open_report

    page = tmp_path / "report.html"
    page.write_text("<html></html>")
    monkeypatch.setattr(open_report, "launcher_missing", lambda: None)
    monkeypatch.setattr(open_report, "opener_argv", lambda _p: None)  # Qt's own call (not Linux)
    monkeypatch.setattr(QDesktopServices, "openUrl", staticmethod(lambda _url: False))
    dialog = open_report.open_in_browser(page)
    qtbot.addWidget(dialog)
    assert dialog.isVisible() and dialog.path.text() == str(page.resolve())
    assert "could not be opened in a browser" in dialog.message.text()
    dialog.copy_button.click()
    assert QGuiApplication.clipboard().text() == str(page.resolve())
    monkeypatch.setattr(open_report, "launcher_missing", lambda: "no launcher (xdg-open) is installed")
    dialog = open_report.open_in_browser(page)
    qtbot.addWidget(dialog)
    assert "xdg-open" in dialog.message.text()


def test_each_plot_menu_opens_the_export_dialog_on_that_plot(tmp_path, qtbot):
    from bench.gui.export import ExportDialog, offered_plots, plot_sources
    from bench.gui.replay_view import ReplayWindow

    raw = tmp_path / "run.h5"
    write_raw(raw, n=500)
    win = ReplayWindow(raw)
    qtbot.addWidget(win)
    offered = offered_plots(win.plots, win.raw_file)  # the plots shown with data in the file
    assert {"cx sx cy sy", "E", "wave angle", "table rate"} <= set(offered) and "sweep phase" not in offered
    for title, (plot_item, _s) in plot_sources(win.plots).items():
        if title not in offered:
            continue
        entry = next(a for a in plot_item.getViewBox().menu.actions() if a.text().startswith("Export recorded"))
        entry.trigger()
        dialog = win.findChildren(ExportDialog)[-1]
        assert dialog.plot.currentText() == title and dialog.raw_file == str(raw)
        dialog.close()


def test_history_browser_on_a_store_that_is_down_says_so_in_one_line(qtbot):
    pytest.importorskip("psycopg")
    from bench.gui.history import HistoryBrowser

    win = HistoryBrowser("postgresql+psycopg://nobody@127.0.0.1:9/nothing?connect_timeout=2")
    qtbot.addWidget(win)
    qtbot.waitUntil(lambda: not win.busy() and win.count.text() != "searching...", timeout=20_000)
    text = win.count.text()
    assert text.startswith("results store postgresql+psycopg://nobody@127.0.0.1:9/nothing") and "\n" not in text
    assert "Traceback" not in text and win.model.rowCount() == 0 and "c00000" in win.count.styleSheet()


def test_replay_shows_the_recorded_interval_and_the_declared_truth(tmp_path, qtbot):
    """The replay's results table holds what the live one showed: the 95 % interval from the file and
    the truth its procedure declares, from the truth the file recorded."""
    from bench.gui.replay_view import ReplayWindow

    raw = tmp_path / "run.h5"
    write_raw(raw)
    win = ReplayWindow(raw)
    qtbot.addWidget(win)
    t = win.results.table
    heads = [t.horizontalHeaderItem(c).text() for c in range(t.columnCount())]
    row = {h: (t.item(0, c).text() if t.item(0, c) else "") for c, h in enumerate(heads)}
    assert row["measurement"] == "tau_s" and "298" in row["95% interval"] and "301" in row["95% interval"]
    assert row["truth"].startswith("300"), row
