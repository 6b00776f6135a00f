"""The window clicked through on a real X server (Xvfb): start, pause, resume, abort, a run to the
end, and the station panel checked against the simulator's own state after the safe state; the
results table's columns; manual control: spin, the panel against the simulator, SAFE STATE, at rest.
Under CI=true a missing Xvfb fails (tests/needs.py), elsewhere it skips."""

from __future__ import annotations

import os
import shutil

import pytest
from xvfb import ROOT, run_under_xvfb

pytest.importorskip("pyqtgraph")



@pytest.mark.xvfb
def test_clicks_on_a_real_x_server(tmp_path):
    shot = tmp_path / "live.png"
    seen = run_under_xvfb("gui_clicks_script.py", str(shot), cwd=tmp_path)
    assert seen["platform"] == "xcb"
    assert seen["idle_rate"] is not None and abs(float(seen["idle_rate"])) < 0.1  # filled before any run
    assert seen["started"] and seen["shot"] and shot.stat().st_size > 10_000
    assert seen["pause_text"] == "Paused \u2014 the table keeps its rate" and seen["resumed"]
    assert seen["aborted"] and seen["outcome"] == "ABORTED" and seen["safe_state"], seen.get("end_reason")
    assert seen["panel_at_rest"] and abs(seen["sim_rate"]) < 0.1 and not seen["sim_drive"]  # panel == simulator
    assert abs(seen["panel_rate"] - seen["sim_rate"]) < 0.1
    assert seen["completed"] == "COMPLETE" and "1a6b1a" in seen["status_style"]  # green only when complete
    assert seen["width"] <= 1280
    # the results table after the run to the end: value, interval, limits, outcome, truth; never "nan"
    assert seen["result_headers"] == ["measurement", "value", "95% interval", "unit", "limits", "outcome", "truth"]
    rows = seen["result_rows"]
    assert rows and not any("nan" in v.lower() for r in rows for v in r.values())
    table_h, rows_h, window_h = seen["results_h"]  # as tall as its rows, up to half the plots' splitter
    assert table_h >= min(rows_h, window_h // 2 - 150), seen["results_h"]
    assert any(r["truth"] for r in rows) and any(r["95% interval"] for r in rows)
    # manual control: opened from the toolbar, the table spun, the panel against the simulator, SAFE STATE
    assert seen["manual_shown"] and seen["manual_active"], seen["manual_message"]
    assert "rate_dps=1500 deg/s is above the station's limit 1000 deg/s" in seen["manual_refusal"]
    assert seen["manual_at_rate"] and abs(seen["manual_panel_rate"] - seen["manual_sim_rate"]) < 1.0
    assert abs(seen["manual_sim_rate"] - 120.0) < 1.0 and seen["manual_sim_drive"]
    assert seen["manual_finished"] and seen["manual_outcome"] == "ABORTED" and seen["manual_safe_state"]
    assert seen["manual_rest"] and abs(seen["manual_sim_rate_after"]) < 0.1 and not seen["manual_sim_drive_after"]
    assert seen["manual_shot"]
    if os.environ.get("GYROBENCH_DOCS_SHOTS"):  # refresh docs/window_live.png on request
        shutil.copy(shot, ROOT / "docs" / "window_live.png")
        shutil.copy(tmp_path / "live_manual.png", ROOT / "docs" / "window_manual.png")
