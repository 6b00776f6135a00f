"""Bad station files and parameters through the real CLI (`python -m bench.cli run ...`), each in
its own process and directory, counted as clean when: the exit is non-zero, stderr holds no Python
traceback and one message line that names the value and the limit or expectation (the parts each
case lists), and nothing moved (no raw file was started).

Run: .venv/bin/python benchmarks/reliability_inputs.py [--jobs 2] [--verbose]
Prints one line a case that is not clean, then "bad station files and parameters: tried N, clean M".
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

GYROBENCH = [sys.executable, "-m", "bench.cli"]
SIM = """[station]
id = "audit"
[simulation]
preset = "hrg"
seed = 0
[devices.table]
driver = "modbus-table"
max_rate_dps = 1000.0
max_accel_dps2 = 500.0
[devices.frontend]
driver = "scpi-frontend"
max_amplitude_v = 5.0
[devices.fpga]
driver = "fpga-link"
"""
REAL = """[station]
id = "lab"
[devices.table]
driver = "modbus-table"
host = "10.0.0.5"
port = 502
[devices.frontend]
driver = "scpi-frontend"
resource = "TCPIP::10.0.0.6::5025::SOCKET"
[devices.fpga]
driver = "fpga-link"
url = "socket://10.0.0.7:7000"
"""


@dataclass
class Case:
    """One bad input: extra CLI arguments, a station file text (None: the built-in sim-hrg) and the
    parts the one message must contain."""

    name: str
    args: list[str]
    station: str | bytes | None
    expect: list[str]
    procedure: str = "table-spin"
    files: dict[str, str] = field(default_factory=dict)


def sim(old: str, new: str) -> str:
    assert old in SIM, old
    return SIM.replace(old, new)


def real(old: str, new: str) -> str:
    assert old in REAL, old
    return REAL.replace(old, new)


def station_cases() -> list[Case]:
    c = [
        ("toml-unclosed-table", sim("[station]", "[station"), ["not valid TOML"]),
        ("toml-no-value", sim('id = "audit"', "id = "), ["not valid TOML"]),
        ("toml-duplicate-key", sim('id = "audit"', 'id = "audit"\nid = "b"'), ["not valid TOML"]),
        ("toml-bad-string", sim('id = "audit"', 'id = "audit'), ["not valid TOML"]),
        ("not-utf8", sim('"audit"', '"caf\xe9"').encode("latin-1"), ["not UTF-8", "0xe9"]),
        ("empty-file", "", ["missing table [station]"]),
        ("no-devices", SIM.split("[devices.table]")[0], ["no [devices.*] table"]),
        ("devices-is-5", "devices = 5\n" + SIM.split("[devices.table]")[0], ["devices=5", "not a table"]),
        ("station-is-text", 'station = "x"\n' + SIM.split("[station]")[1].split("\n", 2)[2], ["station='x'", "table"]),
        ("simulation-is-5", "simulation = 5\n" + SIM.replace('[simulation]\npreset = "hrg"\nseed = 0\n', ""),
         ["simulation=5", "not a table"]),
        ("device-is-5", sim('[devices.fpga]\ndriver = "fpga-link"\n', "[devices]\nfpga = 5\n"),
         ["devices.fpga=5", "not a table"]),
        ("unknown-table", SIM + "[extras]\nx = 1\n", ["unknown table [extras]"]),
        ("unknown-role", sim("[devices.table]", "[devices.turntable]"), ["turntable", "unknown role"]),
        ("unknown-station-key", sim('id = "audit"', 'id = "audit"\nname = "x"'), ["name: unknown key", "allowed"]),
        ("unknown-device-key", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\nhots = 1"),
         ["hots: unknown key", "allowed"]),
        ("unknown-sim-key", sim("seed = 0", "seed = 0\nsped = 1"), ["sped: unknown key"]),
        ("missing-id", sim('id = "audit"', 'description = "x"'), ["id: missing key"]),
        ("id-not-text", sim('id = "audit"', "id = 5"), ["id=5 is not text"]),
        ("missing-table-driver", sim('driver = "modbus-table"\n', ""),
         ["driver: missing key", "ascii-table, modbus-table"]),
        ("missing-frontend-driver", sim('driver = "scpi-frontend"\n', ""), ["driver: missing key", "scpi-frontend"]),
        ("unknown-driver", sim('"modbus-table"', '"telnet-table"'), ["driver='telnet-table'", "not one of"]),
        ("driver-not-text", sim('"modbus-table"', "5"), ["driver=5", "not one of"]),
        ("driver-wrong-role", sim('"modbus-table"', '"fpga-link"'), ["fpga-link' is not one of", "fpga driver"]),
        ("rate-not-a-number", sim("max_rate_dps = 1000.0", 'max_rate_dps = "fast"'),
         ["max_rate_dps='fast' is not a number"]),
        ("rate-above", sim("max_rate_dps = 1000.0", "max_rate_dps = 99999.0"),
         ["max_rate_dps=99999 deg/s is above the limit 20000 deg/s"]),
        ("rate-negative", sim("max_rate_dps = 1000.0", "max_rate_dps = -5.0"),
         ["max_rate_dps=-5 deg/s is below the limit 0.001 deg/s"]),
        ("rate-nan", sim("max_rate_dps = 1000.0", "max_rate_dps = nan"), ["max_rate_dps=nan", "finite"]),
        ("rate-inf", sim("max_rate_dps = 1000.0", "max_rate_dps = inf"), ["max_rate_dps=inf", "finite"]),
        ("rate-bool", sim("max_rate_dps = 1000.0", "max_rate_dps = true"), ["max_rate_dps=True is not a number"]),
        ("accel-zero", sim("max_accel_dps2 = 500.0", "max_accel_dps2 = 0"), ["max_accel_dps2=0", "below the limit"]),
        ("accel-array", sim("max_accel_dps2 = 500.0", "max_accel_dps2 = [1, 2]"),
         ["max_accel_dps2=[1, 2] is not a number"]),
        ("watchdog-zero", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\nwatchdog_s = 0"),
         ["watchdog_s=0", "below the limit 0.1 s"]),
        ("timeout-above", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\ntimeout_s = 100"),
         ["timeout_s=100", "above the limit 30 s"]),
        ("port-above", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\nport = 70000"),
         ["port=70000 is above the limit 65535"]),
        ("port-text", sim("max_rate_dps = 1000.0", 'max_rate_dps = 1000.0\nport = "502"'),
         ["port='502' is not an integer"]),
        ("port-fraction", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\nport = 1.5"),
         ["port=1.5 is not an integer"]),
        ("device-id-above", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\ndevice_id = 300"),
         ["device_id=300 is above the limit 247"]),
        ("host-not-text", sim("max_rate_dps = 1000.0", "max_rate_dps = 1000.0\nhost = 5"), ["host=5 is not text"]),
        ("amplitude-above", sim("max_amplitude_v = 5.0", "max_amplitude_v = 11.0"),
         ["max_amplitude_v=11 V is above the limit 10 V"]),
        ("amplitude-negative", sim("max_amplitude_v = 5.0", "max_amplitude_v = -1.0"),
         ["max_amplitude_v=-1 V is below the limit 0 V"]),
        ("decimation-zero", sim('driver = "fpga-link"', 'driver = "fpga-link"\ndecimation = 0'),
         ["decimation=0 is below the limit 1"]),
        ("fpga-timeout-text", sim('driver = "fpga-link"', 'driver = "fpga-link"\ntimeout_s = "1s"'),
         ["timeout_s='1s' is not a number"]),
        ("seed-negative", sim("seed = 0", "seed = -3"), ["seed=-3 is below the limit 0"]),
        ("seed-fraction", sim("seed = 0", "seed = 1.5"), ["seed=1.5 is not an integer"]),
        ("seed-huge", sim("seed = 0", "seed = 18446744073709551615"), ["seed=18446744073709551615", "above"]),
        ("speed-negative-in-file", sim("seed = 0", "seed = 0\nspeed = -1.0"), ["speed=-1 is below the limit 0"]),
        ("preset-unknown", sim('preset = "hrg"', 'preset = "fog"'),
         ["preset='fog' is not one of hrg, hrg-wa, hrg-selfcal, mems"]),
        ("sample-period-above", sim("seed = 0", "seed = 0\nsample_period_s = 1.0"),
         ["sample_period_s=1 s is above the limit 0.1 s"]),
        ("results-not-text", sim('id = "audit"', 'id = "audit"\nresults = 5'), ["results=5 is not text"]),
        ("runs-dir-not-text", sim('id = "audit"', 'id = "audit"\nruns_dir = []'), ["runs_dir=[] is not text"]),
        ("real-fpga-no-url", real('url = "socket://10.0.0.7:7000"\n', ""),
         ["url: missing key", "real device needs its address"]),
        ("real-frontend-no-resource", real('resource = "TCPIP::10.0.0.6::5025::SOCKET"\n', ""),
         ["resource: missing key", "address"]),
        ("real-port-zero", real("port = 502", "port = 0"), ["port=0 is below the limit 1"]),
        ("real-ascii-baud", real('driver = "modbus-table"\nhost = "10.0.0.5"\nport = 502',
                                 'driver = "ascii-table"\nurl = "/dev/ttyUSB0"\nbaudrate = 10'),
         ["baudrate=10 is below the limit 300"]),
        ("real-host-list", real('host = "10.0.0.5"', "host = ['10.0.0.5']"), ["host=['10.0.0.5'] is not text"]),
    ]
    return [Case(n, [], s, e) for n, s, e in c]


def option_cases(tmp: Path) -> list[Case]:
    ro_store = f"sqlite:///file:{tmp / 'empty.sqlite'}?mode=ro&uri=true"
    c = [
        ("set-not-a-number", ["--set", "rate_dps=abc"], None, ["rate_dps='abc' is not a number"]),
        ("set-above", ["--set", "rate_dps=99999"], None, ["rate_dps=99999 deg/s is above the limit 1000 deg/s"]),
        ("set-below", ["--set", "rate_dps=-99999"], None, ["rate_dps=-99999 deg/s is below the limit -1000 deg/s"]),
        ("set-nan", ["--set", "rate_dps=nan"], None, ["rate_dps=nan", "finite"]),
        ("set-inf", ["--set", "rate_dps=inf"], None, ["rate_dps=inf", "finite"]),
        ("set-empty-value", ["--set", "rate_dps="], None, ["rate_dps='' is not a number"]),
        ("set-hold-negative", ["--set", "hold_s=-1"], None, ["hold_s=-1 s is below the limit 0.1 s"]),
        ("set-unknown", ["--set", "nosuchparam=1"], None,
         ["nosuchparam: not a parameter of table-spin", "hold_s, rate_dps"]),
        ("set-no-equals", ["--set", "novalue"], None, ["--set 'novalue'", "NAME=VALUE"]),
        ("set-no-name", ["--set", "=5"], None, ["--set '=5'", "NAME=VALUE"]),
        ("set-choice", ["--set", "fit_method=newton"], None, ["fit_method='newton' is not one of"], "hrg-damping"),
        ("set-int-fraction", ["--set", "n_points=1.5"], None, ["n_points='1.5' is not an integer"], "mems-sweep"),
        ("set-bool-word", ["--set", "both_directions=maybe"], None, ["both_directions='maybe' is not true or false"],
         "mems-sweep"),
        ("speed-negative", ["--speed", "-1"], None, ["--speed=-1 is below the limit 0", "x real time"]),
        ("speed-huge", ["--speed", "1e9"], None, ["--speed=1000000000 is above the limit 1000000"]),
        ("speed-nan", ["--speed", "nan"], None, ["--speed=nan", "finite"]),
        ("speed-text", ["--speed", "fast"], None, ["--speed", "invalid float value: 'fast'"]),
        ("seed-negative", ["--seed", "-2"], None, ["--seed=-2 is below the limit 0"]),
        ("seed-text", ["--seed", "abc"], None, ["--seed", "invalid int value: 'abc'"]),
        ("fault-no-at", ["--fault", "link-drop"], None, ["--fault 'link-drop'", "KIND@SECONDS"]),
        ("fault-unknown", ["--fault", "meteor@1"], None, ["'meteor' is not one of", "link-drop"]),
        ("fault-time-text", ["--fault", "link-drop@soon"], None, ["'soon' is not a number of seconds"]),
        ("fault-time-negative", ["--fault", "link-drop@-1"], None, ["time=-1 s is below the limit 0 s"]),
        ("fault-time-nan", ["--fault", "link-drop@nan"], None, ["time=nan is not a finite number"]),
        ("fault-on-real", ["--fault", "link-drop@1"], REAL, ["--fault needs a simulated station"]),
        ("seed-on-real", ["--seed", "1"], REAL, ["a real station; --seed applies only to a simulated one"]),
        ("fault-no-such-device", ["--fault", "frontend-hang@1"], sim('[devices.frontend]\ndriver = "scpi-frontend"\n'
                                                                      "max_amplitude_v = 5.0\n", ""),
         ["--fault frontend-hang", "no frontend"]),
        ("proc-needs-missing-role", [], sim('[devices.frontend]\ndriver = "scpi-frontend"\nmax_amplitude_v = 5.0\n',
                                            ""), ["needs device role(s) ['frontend']"], "hrg-damping"),
        ("station-not-found", ["--station", "no-such-station"], None, ["no-such-station: no such station file"]),
        ("station-is-a-directory", ["--station", str(tmp)], None, ["no such station file"]),
        ("procedure-unknown", [], None, ["no procedure 'spin-the-table'", "known:"], "spin-the-table"),
        ("procedure-syntax-error", [], None, ["bad_syntax.py, line 1: invalid syntax"], "bad_syntax.py"),
        ("procedure-import-error", [], None, ["No module named 'gyrobench_no_such_module'"], "./bad_import.py"),
        ("runs-dir-is-a-file", ["--runs-dir", str(tmp / "afile")], None, ["is a file, not a directory"]),
        ("runs-dir-unwritable", ["--runs-dir", "/proc/gyrobench-audit"], None, ["raw data cannot be written"]),
        ("results-readonly", ["--results", ro_store], None, ["results store", "readonly database", "spool"]),
    ]
    return [Case(n, a, s, e, *p) for n, a, s, e, *p in c]


#: cases whose run goes ahead by design: a store that cannot be written takes the record later, through
#: the spool (docs/results_store.md); the exit is still non-zero and the one line names the spool
RUNS_ANYWAY = {"results-readonly"}


def run_case(case: Case, root: Path) -> tuple[bool, str]:
    """(clean, why) for one case, in its own directory."""
    cwd = Path(tempfile.mkdtemp(dir=root, prefix=case.name + "-"))
    (cwd / "bad_syntax.py").write_text("def f(:\n    pass\n")
    (cwd / "bad_import.py").write_text("import gyrobench_no_such_module\n")
    args = ["run", case.procedure, "--set", "hold_s=0.2"] if case.procedure == "table-spin" else ["run", case.procedure]
    if case.name.startswith("set-hold") or case.name == "set-unknown":
        args = ["run", case.procedure]
    if case.station is not None:
        path = cwd / "station.toml"
        path.write_bytes(case.station if isinstance(case.station, bytes) else case.station.encode())
        args += ["--station", str(path)]
    r = subprocess.run(GYROBENCH + args + case.args, cwd=cwd, capture_output=True, text=True, timeout=120)
    err = r.stderr.strip()
    lines = [x for x in err.splitlines() if not x.startswith(("usage:", " "))]  # argparse's usage text
    moved = list(cwd.glob("**/*.h5"))
    why = []
    if r.returncode == 0:
        why.append("exit 0")
    if "Traceback" in err:
        why.append("traceback")
    if "internal error" in err:
        why.append("internal error")
    if len(lines) != 1:
        why.append(f"{len(lines)} message lines")
    missing = [p for p in case.expect if p not in err]
    if missing:
        why.append(f"message lacks {missing}")
    if moved and case.name not in RUNS_ANYWAY:
        why.append("a run started")
    return not why, f"{case.name}: {'; '.join(why) or 'clean'} | {err[-300:]!r}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--verbose", action="store_true")
    opts = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "afile").write_text("")
        (root / "empty.sqlite").write_text("")
        cases = station_cases() + option_cases(root)
        with ThreadPoolExecutor(opts.jobs) as pool:
            results = list(pool.map(lambda c: run_case(c, root), cases))
    for ok, text in results:
        if opts.verbose or not ok:
            print(("clean   " if ok else "UNCLEAN ") + text)
    n_station = len(station_cases())
    clean_station = sum(ok for ok, _ in results[:n_station])
    print(f"station files: tried {n_station}, clean {clean_station}")
    print(f"parameters and options: tried {len(results) - n_station}, clean {sum(ok for ok, _ in results[n_station:])}")
    print(f"bad station files and parameters: tried {len(results)}, clean {sum(ok for ok, _ in results)}")


if __name__ == "__main__":
    main()
