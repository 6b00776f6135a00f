"""`gyrobench fpga load FILE --station ...` and `gyrobench fpga show --station ...`: a unit's
compensation file into the FPGA's trim registers, committed to NVM and read back (one message
naming the register, the value and the limit on any mismatch); the trims and NVM state read back."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

from .compensation import CompensationError, load

EXIT_OK, EXIT_BAD, EXIT_USAGE = 0, 1, 2


class TrimMismatch(RuntimeError):
    """A trim read back differs from what was written."""


def add_fpga_subcommand(sub) -> argparse.ArgumentParser:
    """Register `fpga load|show` on the CLI's subparsers."""
    p = sub.add_parser("fpga", help="the FPGA's trims in NVM: load a compensation file, show the trims")
    fsub = p.add_subparsers(dest="fpga_command", required=True)
    ld = fsub.add_parser("load", help="write a compensation file's trims, commit them to NVM, read back and compare")
    ld.add_argument("file", help="compensation file (TOML, docs/compensation_file.md)")
    ld.add_argument("--station", required=True, help="station name or station TOML file")
    ld.add_argument("--json", action="store_true")
    ld.set_defaults(func=cmd_load)
    sh = fsub.add_parser("show", help="read the trims and the NVM state back")
    sh.add_argument("--station", required=True, help="station name or station TOML file")
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=cmd_show)
    return p


def _err(msg: str) -> None:
    print(f"gyrobench: error: {msg}", file=sys.stderr)


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


def _open(station_name: str):
    from bench.composition import load_station

    station = load_station(station_name)
    if "fpga" not in station.config.devices:
        roles = ", ".join(sorted(station.config.devices))
        raise CompensationError(f"station {station.id!r} has no FPGA ([devices.fpga]) to hold trims; it has: {roles}")
    station.open()
    return station


def cmd_load(args: argparse.Namespace) -> int:
    try:
        comp = load(args.file)
        trims = comp.trims()
        station = _open(args.station)
    except CompensationError as exc:
        _err(str(exc))
        return EXIT_USAGE
    try:
        out = load_trims(station.devices["fpga"], trims)
    except TrimMismatch as exc:
        _err(f"FPGA trims not loaded as written: {exc}")
        return EXIT_BAD
    finally:
        station.close()
    if args.json:
        print(json.dumps({"serial": comp.serial, **out}))
    else:
        print(f"loaded {args.file} (unit {comp.serial}) into the FPGA of station {station.id}; "
              f"NVM committed, CRC {out['crc']:#06x}, read back equal")
        _print_trims(out["trims"])
        if _sim_without_nvm_file(station):
            print("  note: a simulated station's NVM lives with this command's World; set nvm_file in its "
                  "[devices.fpga] to keep it for the next command")
    return EXIT_OK


def _sim_without_nvm_file(station: Any) -> bool:
    return station.config.simulation is not None and not station.config.devices["fpga"].get("nvm_file")


def cmd_show(args: argparse.Namespace) -> int:
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
        elif name == "TRIM_FILE_ID":
            text = f"{int(value):012x}"
        else:
            text = f"{value:.9g} {reg.unit}".rstrip()
        print(f"  {name:<26} {text}")
