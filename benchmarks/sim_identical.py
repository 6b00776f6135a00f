"""Seeded simulated runs bit for bit against stored digests: a speed-up of the simulated devices
must not change a single result (issue 14 item 6: "seeded runs bit-identical").

Runs, through the `gyrobench` CLI (real transports, lockstep): hrg-damping on sim-hrg, a short
cvg-allan on sim-hrg-wa, a short hrg-selfcal on sim-hrg-selfcal, and a short thermal-soak and
thermal-ramp on sim-hrg-thermal-quick (the thermal tests' settings) and tests/test_readout_phase.py's
hrg-selfcal on sim-hrg-realistic (every error source, the readout phase trim), seed 3 each; digests the
JSON result (all but run id, wall time and file name) and every dataset of the raw HDF5 file
(dtype, shape and bytes; datasets of wall-clock times are left out), and compares them with
benchmarks/sim_identical_ref.json.  Takes ~1-2 min of one core.

Run: .venv/bin/python benchmarks/sim_identical.py [--write] [--only damping,allan,selfcal,soak,ramp,selfcal_realistic]
(--write stores the digests of this tree as the reference: do it only on a tree whose results are
the reference, e.g. main before a change meant to keep them.)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import subprocess
import sys
import tempfile

import h5py
import numpy as np

REF = pathlib.Path(__file__).with_name("sim_identical_ref.json")
VOLATILE_KEYS = ("run_id", "wall_s", "raw_file")
RUNS = {
    "damping": ("hrg-damping", "sim-hrg", []),
    "allan": ("cvg-allan", "sim-hrg-wa", ["record_s=600"]),
    "selfcal": ("hrg-selfcal", "sim-hrg-selfcal", ["cycles=3", "precession_dps=0.25", "settle_s=10"]),
    "soak": ("thermal-soak", "sim-hrg-thermal-quick", ["t_low_degc=15", "t_high_degc=35", "points=3",
             "ramp_degc_per_min=30", "settle_window_s=30", "settle_ppm_per_min=0.2", "record_s=60"]),
    "ramp": ("thermal-ramp", "sim-hrg-thermal-quick", ["t_low_degc=25", "t_high_degc=35",
             "cycle_degc_per_min=5", "segment_s=20", "tail_s=60", "settle_window_s=20",
             "settle_ppm_per_min=1", "verify_points=1", "record_s=60", "rate_dps=10"]),
    "selfcal_realistic": ("hrg-selfcal", "sim-hrg-realistic", ["cycles=3", "precession_dps=0.25", "settle_s=10",
                          "phase_cal=3"]),
}
SEED = 3


def _is_wall_clock(name: str) -> bool:
    """Datasets of wall-clock time differ between runs by nature (never simulated results)."""
    leaf = name.rsplit("/", 1)[-1].lower()
    return "wall" in leaf


def digest_run(name: str, workdir: pathlib.Path) -> dict:
    """Run one case through the CLI; its JSON digest and its datasets' digests."""
    procedure, station, sets = RUNS[name]
    cli = str(pathlib.Path(sys.executable).with_name("gyrobench"))
    cmd = [cli, "run", procedure, "--station", station, "--seed", str(SEED), "--json"]
    cmd += [a for s in sets for a in ("--set", s)]
    cmd += ["--runs-dir", str(workdir / name), "--results", str(workdir / f"{name}.sqlite")]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    result = json.loads(out)
    raw_file = result["raw_file"]
    for key in VOLATILE_KEYS:
        result.pop(key, None)
    digests = {"json": hashlib.sha256(json.dumps(result, sort_keys=True).encode()).hexdigest()}
    digests["outcome"] = result.get("outcome")
    datasets: dict[str, str] = {}

    def visit(path: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset) and not _is_wall_clock(path):
            data = np.asarray(obj[()])
            h = hashlib.sha256(f"{data.dtype.str}{data.shape}".encode())
            h.update(data.tobytes() if data.dtype.kind != "O" else repr(data.tolist()).encode())
            datasets[path] = h.hexdigest()

    with h5py.File(raw_file, "r") as f:
        f.visititems(visit)
    digests["datasets"] = datasets
    return digests


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="store this tree's digests as the reference")
    ap.add_argument("--only", default=",".join(RUNS), help="cases, comma-separated: " + ", ".join(RUNS))
    args = ap.parse_args()
    cases = [c.strip() for c in args.only.split(",") if c.strip()]
    bad = set(cases) - set(RUNS)
    if bad:
        ap.error(f"--only: unknown cases {sorted(bad)} (expected {', '.join(RUNS)})")
    ref = json.loads(REF.read_text()) if REF.exists() else {}
    ok = True
    with tempfile.TemporaryDirectory(prefix="gyrobench-identical-") as tmp:
        for name in cases:
            got = digest_run(name, pathlib.Path(tmp))
            if args.write:
                ref[name] = got
                print(f"{name}: {got['outcome']}, {len(got['datasets'])} datasets stored")
                continue
            want = ref.get(name)
            if want is None:
                print(f"{name}: no reference digests (run with --write on the reference tree)")
                ok = False
                continue
            diff = [k for k in sorted(set(want["datasets"]) | set(got["datasets"]))
                    if want["datasets"].get(k) != got["datasets"].get(k)]  # fmt: skip
            same_json = want["json"] == got["json"]
            ok &= same_json and not diff
            print(f"{name}: {got['outcome']}; JSON {'identical' if same_json else 'DIFFERS'}; "
                  f"{len(got['datasets']) - len(diff)}/{len(got['datasets'])} datasets identical"
                  + (f"; differ: {', '.join(diff)}" if diff else ""))  # fmt: skip
    if args.write:
        REF.write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
        print(f"wrote {REF}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
