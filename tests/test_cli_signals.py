"""Signals end a command with one line and the shell's exit code (issue 39): 130 for SIGINT, 143
for SIGTERM, at any moment: while the CLI imports its own modules (the moment found by an audit
hook in the process itself, not by a sleep) and on `sim`; a run's own case is in test_cli.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: the CLI as `gyrobench` starts it, sending itself `sig` the moment module `target` starts importing
AT_IMPORT = """
import os, signal, sys
target, sig = sys.argv[1], getattr(signal, sys.argv[2])
fired = []
def hook(event, args):
    if event == "import" and args[0] == target and not fired:
        fired.append(1)
        os.kill(os.getpid(), sig)
sys.addaudithook(hook)
sys.argv = ["gyrobench", *sys.argv[3:]]
from bench.cli import main
sys.exit(main())
"""


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("target", ["bench.cli.analysis", "bench.cli.store"])
def test_a_signal_while_the_cli_imports_its_modules_is_one_line(tmp_path, sig, target):
    r = subprocess.run([sys.executable, "-c", AT_IMPORT, target, sig.name, "runs", "--results", "x.sqlite"],
                       cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=120)
    name = "Ctrl-C" if sig == signal.SIGINT else "SIGTERM"
    assert r.returncode == 128 + sig and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    assert r.stderr == f"gyrobench: interrupted ({name}) before anything started\n"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_sim_stopped_by_a_signal_exits_128_plus_the_signal(tmp_path, sig):
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "sim", "--duration-s", "300"], cwd=tmp_path,
                            env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()  # the devices' addresses: serving
        assert json.loads(first)["station"] == "sim-hrg"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig and "Traceback" not in err, (proc.returncode, err)
