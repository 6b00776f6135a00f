"""What creating a fresh results store costs, built at once (fresh.py) against migrated step by
step by alembic (what every fresh store paid before), interleaved: in this process (warm, as a
test in a worker) and in a new process (as a `gyrobench run` in a new runs directory), on SQLite
and, with $GYROBENCH_TEST_PG_URL, on PostgreSQL (a new schema each time).

    PYTHONPATH=. python benchmarks/fresh_store.py [repeats]
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

from sqlalchemy import create_engine, text

ROOT = Path(__file__).resolve().parents[1]
_ONE = """
import sys, time
t0 = time.perf_counter()
from bench.results import ResultsStore
from bench.results.store import head_revision
if sys.argv[2] == "built":
    ResultsStore(sys.argv[1]).close()
else:
    s = ResultsStore(sys.argv[1], upgrade=False)
    s.upgrade(head_revision())
    s.close()
print(time.perf_counter() - t0)
"""


def _open(url: str, how: str) -> float:
    from bench.results import ResultsStore
    from bench.results.store import head_revision

    t0 = time.perf_counter()
    if how == "built":
        ResultsStore(url).close()
    else:
        s = ResultsStore(url, upgrade=False)
        s.upgrade(head_revision())
        s.close()
    return time.perf_counter() - t0


def _fresh_process(url: str, how: str) -> float:
    out = subprocess.run([sys.executable, "-c", _ONE, url, how], cwd=ROOT, capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return float(out.stdout.split()[-1])


def main(repeats: int = 10) -> None:
    tmp = Path(tempfile.mkdtemp())
    pg = os.environ.get("GYROBENCH_TEST_PG_URL")
    admin = create_engine(pg, isolation_level="AUTOCOMMIT") if pg else None

    def new_url(engine: str) -> str:
        if engine == "sqlite":
            return f"sqlite:///{tmp / uuid.uuid4().hex}.sqlite"
        schema = f"b_{uuid.uuid4().hex[:12]}"
        with admin.connect() as conn:
            conn.execute(text(f"CREATE SCHEMA {schema}"))
        return f"{pg}{'&' if '?' in pg else '?'}options=-csearch_path%3D{schema}"

    _open(new_url("sqlite"), "migrated")  # imports and alembic's scripts loaded once
    for engine in ["sqlite"] + (["postgresql"] if pg else []):
        for where, fn in (("in process", _open), ("new process", _fresh_process)):
            times: dict[str, list[float]] = {"migrated": [], "built": []}
            for _ in range(repeats):
                for how in ("migrated", "built"):
                    times[how].append(fn(new_url(engine), how))
            med = {k: statistics.median(v) * 1000 for k, v in times.items()}
            print(f"{engine:10s} {where:11s}  migrated {med['migrated']:7.1f} ms   built {med['built']:7.1f} ms   "
                  f"saved {med['migrated'] - med['built']:7.1f} ms")
    if admin is not None:
        with admin.connect() as conn:
            for (name,) in conn.execute(text("SELECT nspname FROM pg_namespace WHERE nspname LIKE 'b\\_%'")):
                conn.execute(text(f"DROP SCHEMA {name} CASCADE"))
        admin.dispose()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
