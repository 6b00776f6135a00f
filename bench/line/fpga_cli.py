"""`gyrobench fpga load FILE --station ...` and `gyrobench fpga show --station ...`: a unit's
compensation file into the FPGA's trim registers, committed to NVM and read back (one message
naming the register, the value and the limit on any mismatch); the trims and NVM state read back.

`load` is gated as the line's own trims step is (bench/line/trims.py): the unit's last attempt
must be a PASS and the FPGA's NVM must hold no other unit's trims; `--override-reason TEXT` loads
anyway and the override is appended to RUNS_DIR/line/fpga_overrides.jsonl."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .trims import TrimMismatch, load_trims

__all__ = ["TrimMismatch", "add_fpga_subcommand", "load_trims"]


def __getattr__(name: str) -> Any:
    """The trims' names re-exported here, imported on first use: every `gyrobench` process builds
    this subcommand's parser, and the compensation file's modules cost ~0.02 s (issue 36)."""
    if name in ("TrimMismatch", "load_trims"):
        from . import trims

        return getattr(trims, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

EXIT_OK, EXIT_BAD, EXIT_USAGE = 0, 1, 2


def add_fpga_subcommand(sub) -> argparse.ArgumentParser:
    """Register `fpga load|show` on the CLI's subparsers."""
    p = sub.add_parser("fpga", help="the FPGA's trims in NVM: load a compensation file, show the trims")
    fsub = p.add_subparsers(dest="fpga_command", required=True)
    ld = fsub.add_parser("load", help="write a compensation file's trims, commit them to NVM, read back and compare")
    ld.add_argument("file", help="compensation file (TOML, docs/compensation_file.md)")
    ld.add_argument("--station", required=True, help="station name or station TOML file")
    ld.add_argument("--json", action="store_true")
    ld.add_argument("--override-reason", default=None, metavar="TEXT",
                    help="load a unit that did not pass, or over another unit's NVM; the reason is recorded")
    ld.add_argument("--operator", default="", help="who loads (kept with an override)")
    ld.add_argument("--runs-dir", default=None, help="where the unit records lie (default: the station's runs dir)")
    ld.add_argument("--db", default=None, help="line database URL (default: the station's results store)")
    ld.set_defaults(func=cmd_load)
    sh = fsub.add_parser("show", help="read the trims and the NVM state back")
    sh.add_argument("--station", required=True, help="station name or station TOML file")
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=cmd_show)
    return p


def _err(msg: str) -> None:
    print(f"gyrobench: error: {msg}", file=sys.stderr)


def _load_station(station_name: str):
    from bench.composition import load_station

    from .compensation import CompensationError

    station = load_station(station_name)
    if "fpga" not in station.config.devices:
        roles = ", ".join(sorted(station.config.devices))
        raise CompensationError(f"station {station.id!r} has no FPGA ([devices.fpga]) to hold trims; it has: {roles}")
    return station


def _open(station_name: str):
    station = _load_station(station_name)
    station.open()
    return station


def _history(args: argparse.Namespace, station: Any, serial: str) -> list[dict[str, Any]]:
    """The serial's attempts on disk and in the line database (bench/line/routing.history)."""
    from . import LineError
    from .db import LineDB
    from .routing import history

    runs_dir = args.runs_dir or station.runs_dir
    url = args.db or (station.results_url if runs_dir == station.runs_dir else None) or f"{runs_dir}/results.sqlite"
    try:
        db = LineDB(url)
    except LineError as exc:  # the database is down: the records on disk still speak
        _err(f"line database not read ({exc}); judging from the records in {runs_dir}")
        return history(None, runs_dir, serial)
    try:
        return history(db, runs_dir, serial)
    finally:
        db.close()


def cmd_load(args: argparse.Namespace) -> int:
    from .compensation import CompensationError, load
    from .trims import TrimMismatch, check_nvm_unit, load_trims, log_override, pass_gate, sha256_file

    try:
        comp = load(args.file)
        trims = comp.trims()
        station = _load_station(args.station)
    except CompensationError as exc:
        _err(str(exc))
        return EXIT_USAGE
    reason = (args.override_reason or "").strip()
    overridden = []
    gate = pass_gate(_history(args, station, comp.serial), comp.serial, comp.sequence)
    if gate is not None:
        if not reason:
            _err(f"{gate} (--override-reason TEXT loads anyway, recorded)")
            return EXIT_USAGE
        overridden.append(gate)
    station.open()
    try:
        link = station.devices["fpga"]
        try:
            check_nvm_unit(link, comp.serial)
        except TrimMismatch as exc:
            if not reason:
                _err(f"{exc} (--override-reason TEXT loads anyway, recorded)")
                return EXIT_USAGE
            overridden.append(str(exc))
        out = load_trims(link, trims)
    except TrimMismatch as exc:
        _err(f"FPGA trims not loaded as written: {exc}")
        return EXIT_BAD
    finally:
        station.close()
    if overridden:
        from .record import now_iso

        log = log_override(args.runs_dir or station.runs_dir, {
            "at": now_iso(), "serial": comp.serial, "station": station.id, "operator": args.operator,
            "file": str(args.file), "sha256": sha256_file(args.file), "reason": reason, "overridden": overridden,
            "crc": out["crc"]})
        out["override"] = {"reason": reason, "overridden": overridden, "log": str(log)}
    if args.json:
        print(json.dumps({"serial": comp.serial, **out}))
    else:
        print(f"loaded {args.file} (unit {comp.serial}) into the FPGA of station {station.id}; "
              f"NVM committed, CRC {out['crc']:#06x}, read back equal")
        for why in overridden:
            print(f"  OVERRIDE ({reason}): {why}; recorded in {out['override']['log']}")
        _print_trims(out["trims"])
        if _sim_without_nvm_file(station):
            print("  note: a simulated station's NVM lives with this command's World; set nvm_file in its "
                  "[devices.fpga] to keep it for the next command")
    return EXIT_OK


def _sim_without_nvm_file(station: Any) -> bool:
    return station.config.simulation is not None and not station.config.devices["fpga"].get("nvm_file")


def cmd_show(args: argparse.Namespace) -> int:
    from .compensation import CompensationError

    try:
        station = _open(args.station)
    except CompensationError as exc:
        _err(str(exc))
        return EXIT_USAGE
    try:
        link = station.devices["fpga"]
        trims, nvm = link.read_trims(), link.nvm_status()
    finally:
        station.close()
    if args.json:
        print(json.dumps({"trims": trims, "nvm": nvm}))
        return EXIT_OK
    state = "valid" if nvm["valid"] else ("CRC BAD" if nvm["crc_bad"] else "empty")
    match = ", trims equal NVM" if nvm["match"] else (", trims differ from NVM" if nvm["valid"] else "")
    print(f"NVM {state} (CRC {nvm['crc']:#06x}, {nvm['commits']} commits){match}")
    _print_trims(trims)
    return EXIT_OK


def _print_trims(trims: dict[str, Any]) -> None:
    from drivers.fpga import protocol as p

    for name, value in trims.items():
        reg = p.BY_NAME[name]
        if name == "TRIM_EN":
            words = [w for bit, w in ((p.TRIM_DRIFT, "drift"), (p.TRIM_SPLIT, "split"), (p.TRIM_GAIN, "gain"))
                     if int(value) & bit]
            text = f"{int(value):#04x} ({', '.join(words) or 'none'})"
        elif name in ("TRIM_FILE_ID", "TRIM_UNIT_ID"):
            text = f"{int(value):012x}"
        else:
            text = f"{value:.9g} {reg.unit}".rstrip()
        print(f"  {name:<26} {text}")
