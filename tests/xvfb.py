"""Run a window script under a real X server (xvfb-run) and return what it printed last (JSON);
the Xvfb tests share it.  Under CI=true a missing Xvfb or Qt xcb library fails (tests/needs.py)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

from needs import need

ROOT = Path(__file__).resolve().parents[1]


def display_args() -> list[str]:
    """xvfb-run's display choice: from a number of this xdist worker's own (gw0 100, gw1 110, ...),
    the next free one (-a, retried by xvfb-run when another Xvfb takes it first)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    return ["-n", str(100 + 10 * index), "-a"]  # -n before -a: xvfb-run searches from -n


def run_under_xvfb(script: str, *args: str, cwd: Path, timeout_s: float = 300.0) -> dict[str, Any]:
    """tests/<script> with args on a 1600x1000 Xvfb screen, Qt on xcb; its last stdout line as JSON."""
    from test_gui_exit import _xcb_missing_libs

    xvfb_run = shutil.which("xvfb-run")
    need(xvfb_run is not None and shutil.which("Xvfb") is not None, "Xvfb is not installed")
    missing = _xcb_missing_libs()
    need(not missing, f"the Qt xcb plugin lacks {', '.join(missing)}")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["QT_QPA_PLATFORM"] = "xcb"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    cmd = [xvfb_run, *display_args(), "-s", "-screen 0 1600x1000x24", sys.executable, str(ROOT / "tests" / script),
           *args]
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])
