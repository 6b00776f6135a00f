"""A local spool of run records that the results store could not take (full disk, read-only
file, server down): one JSON file per run beside the raw data, submitted again by
`gyrobench runs --sync` and at the start of the next run."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any


class Spool:
    """`<dir>/<run_id>.json` files, each a store document (see `ResultsStore.record_doc`)."""

    def __init__(self, directory: str | Path) -> None:
        self.dir = Path(directory)

    def path(self, run_id: str) -> Path:
        return self.dir / f"{run_id}.json"

    def put(self, doc: dict[str, Any]) -> Path:
        """Write a document atomically (a reader never sees half a file); its path."""
        self.dir.mkdir(parents=True, exist_ok=True)
        path = self.path(doc["run"]["run_id"])
        fd, tmp = tempfile.mkstemp(dir=self.dir, prefix=".", suffix=".tmp")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(doc, f, default=str)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    def pending(self) -> list[Path]:
        """The spooled records, oldest run first."""
        if not self.dir.is_dir():
            return []
        return sorted(self.dir.glob("*.json"))

    def load(self, path: Path) -> dict[str, Any]:
        return json.loads(path.read_text())

    def remove(self, run_id: str) -> None:
        self.path(run_id).unlink(missing_ok=True)
