"""A simulated station loads every compiled kernel before it serves (simulators/warm.py): a run
then calls no kernel with argument types not yet compiled or loaded, so no compile or cache load
(10-30 s on a fresh checkout) stalls the world lock while links wait with wall-clock timeouts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = r"""
import gc, json, sys, tempfile
from numba.core.registry import CPUDispatcher
from bench.engine import Runner
from bench.composition.sim_station import SimStation
from procedures import find_procedure

def signatures():
    return {f"{d.py_func.__module__}.{d.py_func.__name__}{sig}" for d in gc.get_objects()
            if isinstance(d, CPUDispatcher) for sig in d.overloads}

new = {}
for station, procedure, sets in (("sim-hrg-wa", "cvg-allan", {"record_s": "60"}), ("sim-hrg", "table-spin", {})):
    st = SimStation(station, seed=0).open()
    before = signatures()
    try:
        rec = Runner(st, runs_dir=tempfile.mkdtemp()).run(find_procedure(procedure), sets)
    finally:
        st.close()
    new[procedure] = [rec.outcome, sorted(signatures() - before), len(before)]
print(json.dumps(new))
"""


def test_a_run_on_an_opened_simulated_station_compiles_and_loads_no_kernel():
    r = subprocess.run([sys.executable, "-c", _SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    for procedure, (outcome, added, loaded) in out.items():
        assert outcome in ("COMPLETE", "PASS"), (procedure, outcome)
        assert loaded >= 8, (procedure, loaded)  # the station's opening loaded them
        assert added == [], f"{procedure} loaded or compiled kernels during the run: {added}"
