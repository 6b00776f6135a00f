"""Reads from a VISA resource that keep a wall-clock deadline: one reply line, an exact byte count,
or draining whatever the device still sends.

Why: pyvisa-py's socket read waits again after every byte that arrives, so a device that drips
bytes (or streams them without a terminator) holds one read far past the VISA timeout.  Here the
VISA timeout is one short slice and each low-level read asks for a few bytes at a time, so control
comes back at least every PIECE_BYTES x SLICE_S / 2 and the caller's deadline is checked between
reads (docs/frontend_scpi.md, "Deadlines").
"""

from __future__ import annotations

import time
from typing import Any

import pyvisa
from pyvisa.constants import StatusCode

#: VISA timeout of one low-level read: a silence this long hands control back (pyvisa-py waits in
#: select() slices of half of it, and returns what it has after one empty slice)
SLICE_S = 0.01
#: the first read of a reply asks for this many bytes (every reply of the command set fits); the
#: following ones for PIECE_BYTES, so a drip holds one read at most PIECE_BYTES x SLICE_S / 2
FIRST_PIECE_BYTES = 128
PIECE_BYTES = 16
#: a text reply longer than this is not one of the instrument's (a device streaming garbage)
MAX_LINE_BYTES = 1 << 16
#: draining stops after this long without a byte
QUIET_S = 2 * SLICE_S
TERMINATOR = b"\n"


class DeadlineExpired(Exception):
    """The deadline passed before the read completed; `partial` holds what had arrived."""

    def __init__(self, partial: bytes) -> None:
        super().__init__(f"{len(partial)} bytes arrived before the deadline")
        self.partial = partial


class ReplyTooLong(Exception):
    """More than MAX_LINE_BYTES without a terminator."""


def return_partial_reads(res: Any) -> None:
    """Make a low-level read that met a silence return what it has (VI_ATTR_SUPPRESS_END_EN off:
    pyvisa-py's socket default keeps waiting, and a timeout then discards the bytes it held)."""
    try:
        res.set_visa_attribute(pyvisa.constants.VI_ATTR_SUPPRESS_END_EN, pyvisa.constants.VI_FALSE)
    except (pyvisa.errors.VisaIOError, NotImplementedError, AttributeError):
        pass  # a backend without the attribute: its reads end at the terminator or the count


def _piece(res: Any, count: int) -> bytes:
    """One low-level read of at most `count` bytes within one slice; b"" when nothing came."""
    try:
        data, _ = res.visalib.read(res.session, count)
    except pyvisa.errors.VisaIOError as exc:
        if exc.error_code == StatusCode.error_timeout:
            return b""
        raise
    return bytes(data)


def _quiet_reads(res: Any):
    """Context: no VisaIOWarning for a read that stopped at its count or at the terminator."""
    return res.ignore_warning(StatusCode.success_max_count_read, StatusCode.success_termination_character_read)


def read_line(res: Any, deadline: float, *, max_bytes: int = MAX_LINE_BYTES) -> bytes:
    """One reply line (read termination on), without its terminator, complete before `deadline`
    (time.monotonic()); DeadlineExpired or ReplyTooLong otherwise."""
    buf = bytearray()
    count = FIRST_PIECE_BYTES
    with _quiet_reads(res):
        while True:
            if time.monotonic() >= deadline:
                raise DeadlineExpired(bytes(buf))
            chunk = _piece(res, count)
            if not chunk:
                continue
            buf += chunk
            if chunk.endswith(TERMINATOR):
                return bytes(buf[: -len(TERMINATOR)])
            if len(buf) > max_bytes:
                raise ReplyTooLong(f"{len(buf)} bytes without a terminator")
            count = PIECE_BYTES


def read_exact(res: Any, n_bytes: int, deadline: float, *, max_piece: int = 1 << 20) -> bytes:
    """Exactly n_bytes (read termination off) before `deadline`; DeadlineExpired otherwise.

    The first read asks for FIRST_PIECE_BYTES; each next one for what the bytes came at so far
    would bring in half the time left (PIECE_BYTES .. max_piece), so a fast link reads a large
    block in a few reads and a slow drip still hands control back before the deadline."""
    buf = bytearray()
    t0 = time.monotonic()
    piece = FIRST_PIECE_BYTES
    with _quiet_reads(res):
        while len(buf) < n_bytes:
            now = time.monotonic()
            if now >= deadline:
                raise DeadlineExpired(bytes(buf))
            buf += _piece(res, min(n_bytes - len(buf), piece))
            elapsed = time.monotonic() - t0
            if buf and elapsed > 0:
                wanted = len(buf) / elapsed * (deadline - time.monotonic()) / 2
                piece = int(min(max_piece, max(PIECE_BYTES, wanted)))
    return bytes(buf)


def drain(res: Any, deadline: float, *, quiet_s: float = QUIET_S) -> int:
    """Discard input until nothing has come for quiet_s; the number of bytes discarded.
    DeadlineExpired when the device is still sending at the deadline."""
    n = 0
    quiet_since = time.monotonic()
    with _quiet_reads(res):
        while True:
            now = time.monotonic()
            if now - quiet_since >= quiet_s:
                return n
            if now >= deadline:
                raise DeadlineExpired(b"")
            chunk = _piece(res, 4096)
            if chunk:
                n += len(chunk)
                quiet_since = time.monotonic()
