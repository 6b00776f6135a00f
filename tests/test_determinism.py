"""A seeded run on a simulated station is reproducible end to end: the same seed gives the same
recorded stream bit for bit and the same measurements (lockstep, real transports in between)."""

from __future__ import annotations

import numpy as np

from bench.composition.sim_station import SimStation
from bench.engine import Runner
from bench.recorder import open_run
from procedures.hrg_free_decay import HrgFreeDecay

PARAMS = {"record_s": 5.0, "rate_dps": 100.0, "amplitude_timeout_s": 60.0}


def _run(tmp_path, seed: int, tag: str):
    station = SimStation("sim-hrg", seed=seed).open()
    try:
        rec = Runner(station, runs_dir=tmp_path / tag).run(HrgFreeDecay, PARAMS)
    finally:
        station.close()
    assert rec.outcome == "COMPLETE", rec.traceback
    with open_run(rec.raw_file) as data:
        fpga = data.table("fpga")
        stream = np.column_stack([fpga[c] for c in ("t_s", "cx", "sx", "cy", "sy")])
    return stream, {m.name: m.value for m in rec.measurements}


def test_same_seed_same_stream_and_measurements(tmp_path):
    a, ma = _run(tmp_path, 7, "a")
    b, mb = _run(tmp_path, 7, "b")
    assert a.shape == b.shape and len(a) > 1000
    assert np.array_equal(a, b)
    assert ma == mb
    c, _ = _run(tmp_path, 8, "c")
    assert not (c.shape == a.shape and np.array_equal(c, a))
