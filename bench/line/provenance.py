"""Where a unit record's verdict came from: the software version, whether its checkout was modified,
and the SHA-256 of the limits and sequence files it was judged by (not a path as typed)."""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path
from typing import Any

from .record import sha256_of

REPO = Path(__file__).resolve().parents[2]


@functools.lru_cache(maxsize=1)
def checkout_modified() -> bool | None:
    """Whether the git checkout the code runs from has changes to tracked files (None: not a checkout)."""
    try:
        out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return bool(out.stdout.strip())


def provenance(sequence_file: str, limits_file: str) -> dict[str, Any]:
    """The record's provenance fields."""
    from bench.engine.runner import software_version

    return {"software_version": software_version(), "checkout_modified": checkout_modified(),
            "sequence_file": str(sequence_file), "sequence_sha256": sha256_of(sequence_file),
            "limits_file": str(limits_file), "limits_sha256": sha256_of(limits_file)}
