"""A local spool of run records that the results store could not take (full disk, read-only
file, server down): one JSON file per run beside the raw data, submitted again by
`gyrobench runs --sync` and at the start of the next run.

A record the store refuses (not a store that is down: a value it will never take) is moved to
`<spool>/quarantine/` with a `.reason` file beside it, so the records after it still go in.
Each submission holds a lock on its record (`claim`), so syncs running at once submit it once."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any


class Spool:
    """`<dir>/<run_id>.json` files, each a store document (see `ResultsStore.record_doc`)."""

    def __init__(self, directory: str | Path) -> None:
        self.dir = Path(directory)

    @property
    def quarantine_dir(self) -> Path:
        return self.dir / "quarantine"

    def path(self, run_id: str) -> Path:
        return self.dir / f"{run_id}.json"

    def put(self, doc: dict[str, Any]) -> Path:
        """Write a document atomically (a reader never sees half a file); its path."""
        self.dir.mkdir(parents=True, exist_ok=True)
        path = self.path(doc["run"]["run_id"])
        _write_atomic(path, json.dumps(doc, default=str))
        return path

    def pending(self) -> list[Path]:
        """The spooled records, oldest run first (not the quarantined ones)."""
        if not self.dir.is_dir():
            return []
        return sorted(self.dir.glob("*.json"))

    def quarantined(self) -> list[Path]:
        """The records the store refused, each with its `.reason` beside it."""
        if not self.quarantine_dir.is_dir():
            return []
        return sorted(self.quarantine_dir.glob("*.json"))

    def load(self, path: Path) -> dict[str, Any]:
        return json.loads(path.read_text())

    def remove(self, run_id: str) -> None:
        self.path(run_id).unlink(missing_ok=True)

    def quarantine(self, path: Path, reason: str) -> Path:
        """Move a refused record to quarantine/ with `<name>.reason` (what the store said); its new path."""
        self.quarantine_dir.mkdir(parents=True, exist_ok=True)
        dest = self.quarantine_dir / path.name
        _write_atomic(dest.with_suffix(".reason"), reason.rstrip("\n") + "\n")
        os.replace(path, dest)
        return dest

    @contextlib.contextmanager
    def claim(self, path: Path) -> Iterator[bool]:
        """Hold the record's lock (`.<name>.lock`) while it is submitted; yields False when another
        process holds it or the record is gone already (submitted by that process)."""
        lock = path.with_name(f".{path.name}.lock")
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:
            yield path.exists()
            return
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                yield False
                return
            yield path.exists()
        finally:
            with contextlib.suppress(OSError):
                if not path.exists():
                    lock.unlink()
            os.close(fd)


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
