"""The recorder: streams, log and measurements to HDF5; flushed each second of data, so a
SIGKILLed writer leaves a readable file."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from bench.engine import events as ev
from bench.recorder import Recorder, open_run


def test_streams_log_measurements_roundtrip(tmp_path):
    rec = Recorder(tmp_path / "r.h5", {"params": {"rate_dps": 10.0}, "procedure": "x", "truth": {"tau_s": 2.0}})
    for k in range(5):
        t = np.arange(k * 100, (k + 1) * 100) * 1e-3
        rec.on_event(
            ev.SampleBlock(
                run_id="r", t_sim_s=t[-1], stream="fpga", columns=("t_s", "cx"), data=np.column_stack([t, np.sin(t)])
            )
        )
    rec.on_event(ev.Measurement(run_id="r", t_sim_s=0.5, name="tau_s", value=2.1, unit="s", outcome="COMPLETE"))
    rec.on_event(ev.Log(run_id="r", t_sim_s=0.5, message="hello"))
    rec.on_event(ev.FitUpdate(run_id="r", t_sim_s=0.5, name="decay", curves={"t_s": np.arange(3.0)}))
    mid = rec.data()
    assert mid.table("fpga")["t_s"].shape == (500,)
    rec.close()
    with open_run(tmp_path / "r.h5") as d:
        assert d.params == {"rate_dps": 10.0} and d.truth == {"tau_s": 2.0}
        tab = d.table("fpga")
        np.testing.assert_array_equal(tab["cx"], np.sin(np.arange(500) * 1e-3))
        assert d.measurements()[0]["name"] == "tau_s" and d.log()[0]["msg"] == "hello"
        np.testing.assert_array_equal(d.fits()["decay"]["t_s"], np.arange(3.0))


def test_column_mismatch_is_an_error(tmp_path):
    rec = Recorder(tmp_path / "r.h5")
    rec.append("s", ("a", "b"), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="3 columns"):
        rec.append("s", ("a", "b", "c"), np.zeros((2, 3)))
    rec.close()


_WRITER = textwrap.dedent(
    """
    import sys, numpy as np
    from bench.engine import events as ev
    from bench.recorder import Recorder
    rec = Recorder(sys.argv[1], {"params": {"x": 1}})
    k = 0
    while True:
        t = (np.arange(100) + 100 * k) * 1e-3   # 0.1 s of 1 kHz data a block
        rec.on_event(ev.SampleBlock(run_id="r", t_sim_s=float(t[-1]), stream="fpga", columns=("t_s", "v"),
                                    data=np.column_stack([t, t * 2])))
        k += 1
        if k == 50:
            print("ready", flush=True)
    """
)


def test_sigkilled_writer_leaves_a_readable_file(tmp_path):
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"  # 5 s of data written
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    with h5py.File(path, "r") as f:
        data = f["streams/fpga"][...]
    # flushed every second of data: at least the first 4 s of the 5 s written before "ready"
    assert data.shape[0] >= 4000
    np.testing.assert_allclose(data[:, 0], np.arange(data.shape[0]) * 1e-3)
    np.testing.assert_allclose(data[:, 1], 2 * data[:, 0])
