"""The trims as a gated last step: a unit's compensation written into its FPGA's NVM, read back and
compared, for PASS units only, and only when the NVM names no other unit (docs/line.md "Trims").

`load_trims` is the write-commit-reload-compare cycle `gyrobench fpga load` uses too;
`write_unit_trims` is the line's step: its result goes into the unit record's `trims`."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

from .compensation import Compensation, CompensationError, from_record, unit_id
from .verdict import PASS


class TrimMismatch(RuntimeError):
    """A trim read back differs from what was written, or the NVM names another unit."""


def _same(a: float, b: float) -> bool:
    return a == b or math.isclose(float(a), float(b), rel_tol=1e-12, abs_tol=1e-15)


def load_trims(link: Any, trims: dict[str, float]) -> dict[str, Any]:
    """Write the trims, commit them to NVM, reload them from NVM (as at power-up) and compare each
    register read back with what was written.  TrimMismatch names the register and both values."""
    link.write_trims(trims)
    crc = link.commit_trims()
    link.reload_trims()
    back = link.read_trims()
    for name, want in trims.items():
        got = back[name]
        if not _same(got, want):
            raise TrimMismatch(f"{name} read back {got!r} after the NVM commit, written {want!r}")
    return {"trims": back, "nvm": link.nvm_status(), "crc": crc}


def nvm_unit_id(link: Any) -> int:
    """The unit id the NVM holds (0: NVM empty or never given one); reloads the registers from a
    valid NVM first, as at power-up."""
    if not link.nvm_status()["valid"]:
        return 0
    link.reload_trims()
    return int(link.read_register("TRIM_UNIT_ID"))


def check_nvm_unit(link: Any, serial: str) -> int:
    """The NVM's unit id when it is this serial's or none; TrimMismatch when it names another unit."""
    held, want = nvm_unit_id(link), unit_id(serial)
    if held not in (0, want):
        raise TrimMismatch(f"the FPGA's NVM holds the trims of another unit (unit id {held:012x}, serial {serial} "
                           f"is {want:012x}): is the unit in the fixture the one scanned?")
    return held


def sha256_file(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_unit_trims(link: Any, record: dict[str, Any], path: str | Path) -> dict[str, Any]:
    """The line's last step on an open station: for a PASS record, its compensation written to
    `path` and loaded into the FPGA (NVM unit id checked before, read-back and unit id after).
    Returns the record's `trims` entry; `written` False with the reason when not written,
    `error` set when the write was tried and failed (the unit is then not PASS)."""
    if record.get("outcome") != PASS:
        return {"written": False, "reason": f"unit {record.get('outcome')}: trims are written for PASS units only"}
    try:
        comp: Compensation = from_record(record)
        trims = comp.trims()
    except CompensationError as exc:
        return {"written": False, "error": f"no trims: {exc}"}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    comp.write(path)
    out: dict[str, Any] = {"written": False, "file": str(path), "sha256": sha256_file(path),
                           "file_id": f"{comp.file_id():012x}", "unit_id": f"{unit_id(comp.serial):012x}",
                           "chosen": {n: {"procedure": c.procedure, "run_id": c.run_id, "basis": c.basis}
                                      for n, c in comp.coefficients.items()}}
    try:
        out["nvm_unit_before"] = f"{check_nvm_unit(link, comp.serial):012x}"
        loaded = load_trims(link, trims)
        held = int(loaded["trims"]["TRIM_UNIT_ID"])
        if held != unit_id(record["serial"]):
            raise TrimMismatch(f"NVM unit id {held:012x} read back is not serial {record['serial']}'s")
    except (TrimMismatch, CompensationError) as exc:
        out["error"] = f"trims not written: {exc}"
        return out
    except Exception as exc:  # noqa: BLE001 - a link that fails: the unit is not trimmed, the record says why
        out["error"] = f"trims not written: {type(exc).__name__}: {exc}"
        return out
    out.update(written=True, read_back=loaded["trims"], nvm=loaded["nvm"], crc=f"{loaded['crc']:#06x}")
    return out


def pass_gate(attempts: list[dict[str, Any]], serial: str, sequence: str = "") -> str | None:
    """Why a unit's trims may not be loaded by hand (None: its last attempt, by the compensation's
    sequence when named, is a PASS).  `attempts` is the serial's history, oldest first
    (bench/line/routing.history)."""
    mine = [a for a in attempts if not sequence or a.get("sequence") == sequence]
    if not mine:
        by = f" by sequence {sequence}" if sequence else ""
        return f"unit {serial} has no attempt{by} on this line (its records on disk and in the line database)"
    last = mine[-1]
    if last.get("outcome") != PASS:
        return (f"unit {serial}'s last attempt (a{last.get('attempt')}, sequence {last.get('sequence')}, station "
                f"{last.get('station')}) is {last.get('outcome')}; trims are loaded for PASS units only")
    return None


def log_override(runs_dir: str | Path, entry: dict[str, Any]) -> Path:
    """An override of the trims' gate, appended as one JSON line to RUNS_DIR/line/fpga_overrides.jsonl."""
    import json

    path = Path(runs_dir) / "line" / "fpga_overrides.jsonl"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps(entry, sort_keys=True) + "\n")
    return path
