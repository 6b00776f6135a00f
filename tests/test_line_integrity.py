"""Records that cannot be edited unseen: each record hashed, chained per station and signed with
the station's key; `line verify` names the first break, `line import` re-checks and refuses what
does not verify; no record file is ever replaced; a unit killed mid-run leaves an INTERRUPTED
attempt row.  On SQLite and on PostgreSQL."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from sqlalchemy import create_engine, delete

from bench.cli import main
from bench.line.db import LineDB
from bench.line.integrity import generate_key, record_hash
from bench.line.schema import line_attempts

ROOT = Path(__file__).resolve().parents[1]
PASS_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=99.5\nhigh=100.5\nrule="value"\n'
FAIL_LIMITS = '[product]\nname="p"\n[limits.table_rate_dps]\nlow=200\nhigh=300\nrule="value"\n'


def keyed_station(tmp_path, speed=None):
    """sim-hrg with a line key named by its station file (the key made here, in tmp)."""
    key, pub = generate_key(tmp_path / "station.key")
    text = (ROOT / "bench" / "stations" / "sim-hrg.toml").read_text()
    text = text.replace("[station]\n", f'[station]\nline_key = "{key}"\n', 1)
    if speed is not None:
        text = text.replace("speed = 0.0", f"speed = {speed}")
    path = tmp_path / "keyed.toml"
    path.write_text(text)
    return path, pub


def _run(tmp_path, url, station, serial, limits_text, *extra):
    tmp_path.mkdir(parents=True, exist_ok=True)
    limits = tmp_path / f"limits-{hashlib.sha256(limits_text.encode()).hexdigest()[:6]}.toml"
    limits.write_text(limits_text)
    return main(["line", "run", "ci-spin", "--station", str(station), "--dut", serial, "--operator", "ann",
                 "--yes", "--lot", "L1", "--runs-dir", str(tmp_path), "--db", url, "--limits", str(limits), *extra])


def _verify(capsys, tmp_path, url, pub):
    code = main(["line", "verify", "L1", "--runs-dir", str(tmp_path), "--db", url, "--key", str(pub)])
    return code, capsys.readouterr().out


def test_a_forged_record_is_refused_and_verify_names_the_first_break(tmp_path, store_url, capsys):
    station, pub = keyed_station(tmp_path)
    assert _run(tmp_path, store_url, station, "SN-1", PASS_LIMITS) == 0
    assert _run(tmp_path, store_url, station, "SN-2", FAIL_LIMITS) == 1  # FAIL exits 1
    folder = tmp_path / "line" / "L1"
    good, failed = (json.loads((folder / f"{s}-a1.json").read_text()) for s in ("SN-1", "SN-2"))
    assert (good["chain"]["index"], failed["chain"]["index"]) == (1, 2)
    assert failed["chain"]["prev_sha256"] == good["integrity"]["sha256"] == record_hash(good)
    lim = Path(failed["limits_file"])
    assert lim.is_absolute() and failed["limits_sha256"] == hashlib.sha256(lim.read_bytes()).hexdigest()
    assert failed["sequence_sha256"] and failed["checkout_modified"] in (True, False, None)
    capsys.readouterr()
    code, out = _verify(capsys, tmp_path, store_url, pub)
    assert code == 0 and "2 record(s) from 1 station(s): chain, signatures and raw files hold" in out

    # the FAIL record edited by hand to PASS under a new serial: refused by import, whether its
    # hash is left alone or recomputed (the signature is then wrong)
    forged = json.loads(json.dumps(failed))
    forged.update(serial="SN-NEW", outcome="PASS", summary="PASS: 1 limit(s) met")
    forged["measurements"][0]["outcome"] = "PASS"
    elsewhere = tmp_path / "forged"
    elsewhere.mkdir()
    (elsewhere / "SN-NEW-a1.json").write_text(json.dumps(forged))
    assert main(["line", "import", str(elsewhere / "SN-NEW-a1.json"), "--db", store_url, "--key", str(pub)]) == 1
    out, err = capsys.readouterr()
    assert "imported 0 record(s)" in out and "refused: its content does not match its hash" in err
    forged["integrity"]["sha256"] = record_hash(forged)
    (elsewhere / "SN-NEW-a1.json").write_text(json.dumps(forged))
    assert main(["line", "import", str(elsewhere / "SN-NEW-a1.json"), "--db", store_url, "--key", str(pub)]) == 1
    assert "refused: its signature does not match its hash" in capsys.readouterr().err
    db = LineDB(store_url)
    assert {a["serial"] for a in db.attempts()} == {"SN-1", "SN-2"}  # nothing forged got in
    db.close()

    # the forgery dropped into the lot folder, and a raw file changed: verify names them, first first
    (folder / "SN-NEW-a1.json").write_text(json.dumps(forged))
    raw = Path(good["runs"][0]["raw_file"])
    raw.write_bytes(raw.read_bytes() + b"\0")
    code, out = _verify(capsys, tmp_path, store_url, pub)
    assert code == 1 and "BROKEN; first break: SN-1-a1" in out and "does not match its SHA-256" in out
    assert "SN-NEW-a1" in out and "signature does not match" in out


def test_a_removed_record_breaks_its_station_chain(tmp_path, capsys):
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    station, pub = keyed_station(tmp_path)
    for s in ("SN-1", "SN-2", "SN-3"):
        assert _run(tmp_path, url, station, s, PASS_LIMITS) == 0
    assert _verify(capsys, tmp_path, url, pub)[0] == 0
    (tmp_path / "line" / "L1" / "SN-2-a1.json").unlink()  # the record, on disk and in the database
    eng = create_engine(url)
    with eng.begin() as conn:
        conn.execute(delete(line_attempts).where(line_attempts.c.serial == "SN-2"))
    eng.dispose()
    code, out = _verify(capsys, tmp_path, url, pub)
    assert code == 1 and "first break: SN-3-a1" in out and "record #2, the one before it (#3), is missing" in out
    # another station's key is not this station's: --key of another key refuses every record
    _, other = generate_key(tmp_path / "other.key")
    code, out = _verify(capsys, tmp_path, url, other)
    assert code == 1 and "not a trusted key" in out


def test_no_record_file_is_replaced_when_the_database_went_down(tmp_path, capsys, monkeypatch):
    """The database gone mid-unit (after the attempt's row began): the JSON record is kept; a retest
    after writes attempt 2 in a new file (numbers from disk and database), the first file untouched;
    `line import` then gives the open attempt row its record."""
    from bench.line import LineError

    def down(self, row_id, record):
        raise LineError(f"line database {self.url}: connection refused")

    station, pub = keyed_station(tmp_path)
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    monkeypatch.setattr(LineDB, "finish_attempt", down)
    code = _run(tmp_path, url, station, "LN6", PASS_LIMITS)
    monkeypatch.undo()
    assert code == 6  # PASS, but its record is not in the database: distinct exit code
    first = tmp_path / "line" / "L1" / "LN6-a1.json"
    kept = first.read_bytes()
    assert "import" in capsys.readouterr().err
    assert _run(tmp_path, url, station, "LN6", PASS_LIMITS, "--retest-reason", "after the outage") == 0
    assert first.read_bytes() == kept and (tmp_path / "line" / "L1" / "LN6-a2.json").is_file()
    assert main(["line", "import", str(first), "--db", url, "--key", str(pub)]) == 0
    db = LineDB(url)
    assert [(a["attempt"], a["outcome"]) for a in db.attempts(serial="LN6")] == [(1, "PASS"), (2, "PASS")]
    db.close()


def test_kill_9_mid_unit_leaves_an_interrupted_attempt(tmp_path, store_url):
    # lockstep (virtual time: no wall-clock watchdog a loaded machine could trip, so it runs beside
    # other tests; it ran alone at 1x real time): 40 holds of 600 simulated s take a minute or more
    # of wall time, and the kill comes within 0.2 s of the attempt row
    station, _ = keyed_station(tmp_path)
    seq = tmp_path / "long.toml"
    step = '[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=600\n'
    seq.write_text('[sequence]\nname="long"\n' + step * 40)
    limits = tmp_path / "limits.toml"
    limits.write_text(PASS_LIMITS)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "line", "run", str(seq), "--station", str(station),
                             "--dut", "K9", "--operator", "ann", "--yes", "--lot", "L1", "--runs-dir", str(tmp_path),
                             "--db", store_url, "--limits", str(limits)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    db = LineDB(store_url)
    try:
        deadline = time.monotonic() + 120
        while not [a for a in db.attempts(serial="K9") if a["outcome"] == "RUNNING"]:
            assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "no RUNNING attempt row"
            time.sleep(0.2)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        (row,) = db.attempts(serial="K9")
        assert row["outcome"] == "INTERRUPTED" and row["attempt"] == 1
        (stub,) = db.records(serial="K9", open_too=True)
        assert "interrupted" in stub["end_reason"]
        assert db.records(serial="K9") == []  # no record: the report's records leave it out
    finally:
        db.close()
        proc.stderr.close()
    # the unit tested again (by another sequence): attempt 2, the interrupted attempt counts
    assert _run(tmp_path, store_url, station, "K9", PASS_LIMITS) == 0
    assert json.loads((tmp_path / "line" / "L1" / "K9-a2.json").read_text())["attempt"] == 2


def test_a_station_chain_continues_from_the_database_in_another_runs_dir(tmp_path):
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    station, _ = keyed_station(tmp_path)
    assert _run(tmp_path / "a", url, station, "C1", PASS_LIMITS) == 0
    assert _run(tmp_path / "b", url, station, "C2", PASS_LIMITS) == 0  # a new runs dir: no chain head there
    first, second = (json.loads((tmp_path / d / "line" / "L1" / f"{s}-a1.json").read_text())
                     for d, s in (("a", "C1"), ("b", "C2")))
    assert second["chain"] == {"station": "sim-hrg", "index": 2, "prev_sha256": first["integrity"]["sha256"]}
