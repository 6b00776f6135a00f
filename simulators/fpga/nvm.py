"""The simulated FPGA's non-volatile memory: the trim block (TRIM_BLOCK registers) with its CRC.

It belongs to the unit, not to the server: kept on the World (so a reconnect and a simulator
restart on the same World find it) and, when a file is named, in that file (so a station
session that spans processes finds it too)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

from drivers.fpga import protocol as p


def encode_block(regs: dict[str, float]) -> bytes:
    """The trim registers as NVM stores them: 8 bytes each (protocol encoding), in address order."""
    return b"".join(p.encode_value(p.BY_NAME[name], regs[name]) for name in p.TRIM_BLOCK)


def decode_block(block: bytes) -> dict[str, float]:
    """The trim registers of a block; an older, shorter layout (p.TRIM_BLOCK_SIZES: registers were only
    ever appended) gives the registers it lacks their defaults (a trim it never had stays off)."""
    n = len(block) // 8
    return {name: p.decode_value(p.BY_NAME[name], block[8 * i : 8 * i + 8]) if i < n else p.BY_NAME[name].default
            for i, name in enumerate(p.TRIM_BLOCK)}


class Nvm:
    """Committed trim block + CRC-16 (CCITT-FALSE, as the link's frames) and a commit counter."""

    SIZE = 8 * len(p.TRIM_BLOCK)  # what a commit writes; blocks of the older p.TRIM_BLOCK_SIZES still load

    def __init__(self, path: str | Path | None = None) -> None:
        self.path = Path(path) if path else None
        self.data: bytes | None = None  # block + 2 CRC bytes (little-endian), None when erased
        self.commits = 0
        if self.path is not None and self.path.exists():
            raw = self.path.read_bytes()
            if len(raw) >= 4:
                self.commits = struct.unpack("<I", raw[:4])[0]
                self.data = raw[4:] or None

    @property
    def valid(self) -> bool:
        d = self.data
        return (d is not None and len(d) - 2 in p.TRIM_BLOCK_SIZES
                and p.crc16(d[:-2]) == struct.unpack("<H", d[-2:])[0])

    @property
    def crc(self) -> int:
        d = self.data
        return struct.unpack("<H", d[-2:])[0] if d is not None and len(d) >= 2 else 0

    def block(self) -> bytes | None:
        return self.data[:-2] if self.valid else None

    def commit(self, block: bytes) -> None:
        self.data = block + struct.pack("<H", p.crc16(block))
        self.commits += 1
        self._save()

    def erase(self) -> None:
        self.data = None
        self._save()

    def _save(self) -> None:
        if self.path is None:
            return
        tmp = self.path.with_suffix(self.path.suffix + ".tmp")
        tmp.write_bytes(struct.pack("<I", self.commits) + (self.data or b""))
        os.replace(tmp, self.path)  # a cut in the middle leaves the old block, never half a block


def world_nvm(world, path: str | Path | None = None) -> Nvm:
    """The unit's NVM: one per World (and per file, when given)."""
    store = world.__dict__.setdefault("_fpga_nvm", {})
    key = str(Path(path).resolve()) if path else ""
    if key not in store:
        store[key] = Nvm(path)
    return store[key]
