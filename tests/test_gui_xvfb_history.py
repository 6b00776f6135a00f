"""Runs you can find, clicked through on a real X server (Xvfb): a run to the end, the history
browser filtered, the run opened for replay in its own window with the recorded values, a plot
exported to CSV, HDF5 and PNG, and the report opened.  Under CI=true a missing Xvfb fails."""

from __future__ import annotations

import os
import shutil

import pytest
from xvfb import ROOT, run_under_xvfb

pytest.importorskip("pyqtgraph")



@pytest.mark.xvfb
def test_history_replay_and_export_on_a_real_x_server(tmp_path):
    shots = tmp_path / "history.png", tmp_path / "replay.png"
    out = tmp_path / "export"
    out.mkdir()
    seen = run_under_xvfb("gui_history_script.py", *map(str, shots), str(out), cwd=tmp_path)
    assert seen["platform"] == "xcb"
    assert seen["aborted"] == "ABORTED" and seen["completed"] == "COMPLETE"
    assert seen["history_all"] == 2 and seen["history_filtered"] == [seen["run_id"]] and seen["selected"]
    assert seen["replay_rows"] == seen["file_rows"] > 1000 and seen["replay_last_equal"]
    assert seen["replay_results"] == seen["file_measurements"] > 0
    assert seen["param_record_s"] == ["5", "s"] and seen["live_log_separate"]
    assert seen["banner"].startswith("Replay of a recorded run (COMPLETE)")
    assert seen["csv_equal"] and seen["h5_equal"] and seen["png_bytes"] > 5_000
    assert f"{seen['file_rows']} rows" in seen["export_csv"] and f"{seen['file_rows']} rows" in seen["export_h5"]
    assert seen["report_exists"] and seen["report_handed"] and seen["report_handed"][0].endswith(".html")
    assert seen["report_dialog"] == seen["report_handed"][0]  # refused: the window shows the path
    assert all(s.stat().st_size > 10_000 for s in shots)
    if os.environ.get("GYROBENCH_DOCS_SHOTS"):  # refresh the docs' screenshots on request
        shutil.copy(shots[0], ROOT / "docs" / "window_history.png")
        shutil.copy(shots[1], ROOT / "docs" / "window_replay.png")
