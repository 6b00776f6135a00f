"""What the lot benchmarks share: a fresh PostgreSQL schema per run, and copies of a built-in
simulated station under their own ids and Ed25519 keys (their own chains, locks and signatures)."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from pathlib import Path

#: the built-in simulated station each line sequence runs on
STATION_OF = {"ci-mems": "sim-mems", "eol-mems": "sim-mems", "eol-hrg": "sim-hrg", "ci-spin": "sim-hrg"}


def fresh_pg_schema(base: str, prefix: str = "line") -> tuple[str, Callable[[], None]]:
    """A new schema on the server at `base`: the URL that searches it first, and a function that drops it."""
    from sqlalchemy import create_engine, text

    schema = f"{prefix}_{uuid.uuid4().hex[:10]}"
    admin = create_engine(base, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f"CREATE SCHEMA {schema}"))

    def drop() -> None:
        with admin.connect() as conn:
            conn.execute(text(f"DROP SCHEMA {schema} CASCADE"))
        admin.dispose()

    sep = "&" if "?" in base else "?"
    return f"{base}{sep}options=-csearch_path%3D{schema}", drop


def keyed_station_copy(folder: Path, base: str, station_id: str) -> tuple[Path, str]:
    """A copy of the built-in station `base` named `station_id` with its own signing key, written in
    `folder`: the station file and the key's public half."""
    from bench.line.integrity import generate_key, load_public_key
    from bench.station_config import find_station_file

    (folder / "keys").mkdir(parents=True, exist_ok=True)
    key, pub = generate_key(folder / "keys" / f"{station_id}.key")
    text = find_station_file(base).read_text().replace(f'id = "{base}"', f'id = "{station_id}"\nline_key = "{key}"', 1)
    path = folder / f"{station_id}.toml"
    path.write_text(text)
    return path, load_public_key(pub)
