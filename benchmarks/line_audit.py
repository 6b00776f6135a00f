"""The line's record and routing audit against a real database: each case tried from outside
(the `gyrobench line` commands, a forged file, a deleted record, kill -9 mid-unit) and whether the
line held.  Prints one table: case, what was tried, held (yes/no).
Run: .venv/bin/python benchmarks/line_audit.py [--db URL]   (default $GYROBENCH_TEST_PG_URL, else SQLite)
The PostgreSQL URL from `.ci/start-postgres` gives each run its own schema."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PASS_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\nrule="value"\n'
FAIL_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=200\nhigh=300\nrule="value"\n'


def _cli(*argv: str) -> tuple[int, str, str]:
    from bench.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _schema_url(base: str) -> str:
    """A fresh schema on PostgreSQL (the audit leaves the server's other data alone)."""
    if not base.startswith("postgres"):
        return base
    from sqlalchemy import create_engine, text

    schema = f"audit_{uuid.uuid4().hex[:10]}"
    eng = create_engine(base, isolation_level="AUTOCOMMIT")
    with eng.connect() as conn:
        conn.execute(text(f"CREATE SCHEMA {schema}"))
    eng.dispose()
    return f"{base}{'&' if '?' in base else '?'}options=-csearch_path%3D{schema}"


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--db", default=os.environ.get("GYROBENCH_TEST_PG_URL"))
    args = p.parse_args()
    from sqlalchemy import create_engine, delete

    from bench.line.db import LineDB
    from bench.line.integrity import generate_key, record_hash
    from bench.line.schema import line_attempts

    tmp = Path(tempfile.mkdtemp(prefix="line-audit-"))
    url = _schema_url(args.db) if args.db else f"sqlite:///{tmp / 'line.sqlite'}"
    key, pub = generate_key(tmp / "station.key")
    station = tmp / "station.toml"
    station.write_text((ROOT / "bench/stations/sim-hrg.toml").read_text().replace(
        "[station]\n", f'[station]\nline_key = "{key}"\n', 1))
    limits = {"pass": tmp / "pass.toml", "fail": tmp / "fail.toml"}
    limits["pass"].write_text(PASS_LIMITS)
    limits["fail"].write_text(FAIL_LIMITS)
    rows: list[tuple[str, str, bool]] = []

    def run(serial: str, which: str = "pass", *extra: str, st: Path = station) -> tuple[int, str, str]:
        return _cli("line", "run", "ci-spin", "--station", str(st), "--dut", serial, "--operator", "ann", "--yes",
                    "--lot", "A1", "--runs-dir", str(tmp / "runs"), "--db", url, "--limits", str(limits[which]),
                    *extra)

    def verify() -> tuple[int, str, str]:
        return _cli("line", "verify", "A1", "--runs-dir", str(tmp / "runs"), "--db", url, "--key", str(pub))

    folder = tmp / "runs" / "line" / "A1"
    run("U1")
    run("U2", "fail")
    run("U3")
    failed = json.loads((folder / "U2-a1.json").read_text())
    forged = json.loads(json.dumps(failed))
    forged.update(serial="U9", outcome="PASS")
    forged["measurements"][0]["outcome"] = "PASS"
    forged["integrity"]["sha256"] = record_hash(forged)
    (tmp / "U9-a1.json").write_text(json.dumps(forged))
    code, _, err = _cli("line", "import", str(tmp / "U9-a1.json"), "--db", url, "--runs-dir", str(tmp / "runs"),
                        "--key", str(pub))
    rows.append(("tampering", "FAIL record edited to PASS under a new serial, re-hashed, `line import`",
                 code == 1 and "refused" in err))
    code, out, _ = verify()
    rows.append(("tampering", "`line verify` of the untouched lot", code == 0 and "hold" in out))
    raw = Path(json.loads((folder / "U1-a1.json").read_text())["runs"][0]["raw_file"])
    raw.write_bytes(raw.read_bytes() + b"\0")
    code, out, _ = verify()
    rows.append(("tampering", "a raw file changed by one byte: verify names it first",
                 code == 1 and "first break: U1-a1" in out))
    (folder / "U2-a1.json").unlink()
    eng = create_engine(url)
    with eng.begin() as conn:
        conn.execute(delete(line_attempts).where(line_attempts.c.serial == "U2"))
    eng.dispose()
    code, out, _ = verify()
    rows.append(("tampering", "a record deleted from disk and database: the chain names the gap",
                 code == 1 and "#2, the one before it (#3), is missing" in out))
    code, out, _ = run("U1", "pass", "--retest-reason", "audit")
    rows.append(("no replace", "U1 tested again: a new file, the first untouched",
                 (folder / "U1-a2.json").is_file() and code in (0, 6)))
    # routing
    code, _, err = run("U3")
    rows.append(("routing", "a PASS unit retested with no reason", code == 2 and "--retest-reason" in err))
    run("U4", "fail")
    code, _, err = run("U4")
    rows.append(("routing", "a FAIL unit retested with no rework code", code == 2 and "--rework" in err))
    other = tmp / "other.toml"
    other.write_text(station.read_text().replace('id = "sim-hrg"', 'id = "other"'))
    code, _, err = run("U6", "pass", "--fault", "table-estop@0.2")
    code2, _, err2 = run("U6", "pass", st=other)
    rows.append(("routing", "an ERROR unit (max_attempts 1) tried again on another station",
                 code == 4 and code2 == 2 and "has had 1 attempt(s)" in err2))
    code, out, _ = run("U4", "pass", "--rework", "RW-1", st=other)
    rows.append(("routing", "the FAIL unit after rework, on another station: attempt 2",
                 code == 0 and "U4 attempt 2: PASS" in out))
    code, _, err = _cli("line", "run", "ci-spin", "--dut", "U5", "--operator", "ann", "--yes", "--runs-dir",
                        str(tmp / "runs"), "--db", url, "--lot", "../../x")
    rows.append(("input", "--lot ../../x", code == 2 and not (tmp / "x").exists()))
    code, _, err = _cli("line", "run", "ci-spin", "--dut", "A\nB\x1b[31mRED", "--operator", "ann", "--yes",
                        "--runs-dir", str(tmp / "runs"), "--db", url)
    rows.append(("input", "a serial with a newline and an escape", code == 2 and "\x1b" not in err))
    # crash
    slow = tmp / "slow.toml"
    slow.write_text(station.read_text().replace("speed = 0.0", "speed = 1.0"))
    seq = tmp / "long.toml"
    seq.write_text('[sequence]\nname="long"\n[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=60\n')
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "line", "run", str(seq), "--station", str(slow),
                             "--dut", "K1", "--operator", "ann", "--yes", "--lot", "A1", "--runs-dir",
                             str(tmp / "runs"), "--db", url, "--limits", str(limits["pass"])],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    db = LineDB(url)
    t0 = time.monotonic()
    while not db.attempts(serial="K1") and time.monotonic() - t0 < 120 and proc.poll() is None:
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    rows.append(("crash", "kill -9 mid-unit: its attempt row", [a["outcome"] for a in db.attempts(serial="K1")]
                 == ["INTERRUPTED"]))
    db.close()
    width = max(len(t) for _, t, _ in rows)
    print(f"line audit on {url.split('?')[0]} ({tmp})")
    print(f"{'case':<11} {'tried':<{width}} held")
    for case, tried, held in rows:
        print(f"{case:<11} {tried:<{width}} {'yes' if held else 'NO'}")
    print(f"{sum(h for *_, h in rows)}/{len(rows)} held")
    return 0 if all(h for *_, h in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
