"""FPGA register link protocol: frame codec, register map and stream layout, shared by the
driver and the simulator so the two cannot drift apart (docs/fpga_link.md describes it).

Every frame, little-endian:
    sync  u16  0x5AA5 (bytes A5 5A on the wire)
    type  u8   READ=1, WRITE=2, ACK=3, NACK=4, STREAM=5
    len   u8   payload length in bytes
    seq   u32  command sequence number (echoed by ACK/NACK) or stream frame counter
    addr  u16  register address (stream frames: the loops' saturation bits SAT_*)
    payload    len bytes
    crc   u16  CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor)
               over type..payload (everything after the sync word)
Register values travel as 8 bytes: uint64 for integer registers, float64 for real ones.
A stream frame's payload (60 bytes, protocol version 2) is the sample index (u64), its time (f64),
eight float32: cx, sx, cy, sy, amp_ctrl, freq_ctrl, quad_ctrl, prec_ctrl, then the gyro's outputs:
the wave angle angle_out_deg (f64, unwrapped: the whole-angle output) and the force-to-rebalance
rate output rate_out_dps (f32).
"""

from __future__ import annotations

import struct
from binascii import crc_hqx
from dataclasses import dataclass

import numpy as np

from bench.kernel_cache import njit  # NUMBA_CACHE_DIR keyed on the kernels' sources

from .stream import (  # noqa: F401 - the stream's layout, saturation bits and output modes, without numba
    MODE_FORCE_TO_REBALANCE,
    MODE_WHOLE_ANGLE,
    OUTPUT_MODES,
    SAT_AMP,
    SAT_FTR,
    SAT_NAMES,
    SAT_PREC,
    SAT_QUAD,
    STREAM_COLUMNS,
    STREAM_SCHEMA,
    saturation_text,
)

SYNC = b"\xa5\x5a"
SYNC_U16 = 0x5AA5
CRC_INIT = 0xFFFF
HEADER = struct.Struct("<HBBIH")  # sync, type, len, seq, addr
HEADER_SIZE = HEADER.size  # 10
CRC_SIZE = 2
MAX_PAYLOAD = 255
SEQ_MOD = 1 << 32

READ, WRITE, ACK, NACK, STREAM = 1, 2, 3, 4, 5
FRAME_TYPES = {READ: "read", WRITE: "write", ACK: "ack", NACK: "nack", STREAM: "stream"}

# NACK error codes (payload of a NACK, u64)
ERR_UNKNOWN_ADDRESS = 1
ERR_READ_ONLY = 2
ERR_OUT_OF_RANGE = 3
ERR_BAD_LENGTH = 4
ERR_WRITE_ONLY = 5
NACK_REASONS = {
    ERR_UNKNOWN_ADDRESS: "unknown register address",
    ERR_READ_ONLY: "register is read-only",
    ERR_OUT_OF_RANGE: "value out of range",
    ERR_BAD_LENGTH: "bad payload length",
    ERR_WRITE_ONLY: "register is write-only",
}

# --- control bits (register CTRL; CTRL_SET / CTRL_CLR set or clear bits idempotently) ---------
DRIVE_EN = 0x01  # clearing it is "cut drive": every force goes to zero
AGC_EN = 0x02
PLL_EN = 0x04
QUAD_EN = 0x08
WHOLE_ANGLE = 0x10
STREAM_EN = 0x20
DRIFT_COMP_EN = 0x40
CTRL_MASK = 0x7F
LOOP_BITS = AGC_EN | PLL_EN | QUAD_EN | WHOLE_ANGLE | DRIFT_COMP_EN

# --- status bits (register STATUS) ------------------------------------------------------------
ST_DRIVE_ON = 0x01
ST_AGC_SETTLED = 0x02  # amplitude within 1 % of the setpoint
ST_PLL_LOCKED = 0x04  # phase error under 0.05 rad
ST_STREAMING = 0x08

FPGA_ID = 0x46504741  # "FPGA"
#: 2: the stream frame gained the gyro's outputs (angle_out_deg, rate_out_dps); 72 bytes (was 60)
#: 3: a stream frame's address field carries the loops' saturation bits (SAT_*)
PROTOCOL_VERSION = 3


@dataclass(frozen=True)
class Register:
    """One register: address, value kind ('u' uint64 or 'f' float64), access, limits, unit."""

    name: str
    addr: int
    kind: str
    access: str  # "ro", "rw", "wo"
    lo: float = 0.0
    hi: float = 0.0
    unit: str = ""
    default: float = 0.0
    doc: str = ""


_U64_MAX = float(2**64 - 1)

REGISTERS: tuple[Register, ...] = (
    Register("ID", 0x00, "u", "ro", doc="constant 0x46504741 ('FPGA')"),
    Register("VERSION", 0x01, "u", "ro", doc="protocol version"),
    Register("STATUS", 0x02, "u", "ro", doc="status bits ST_*"),
    Register("CTRL", 0x03, "u", "rw", 0, CTRL_MASK, doc="control bits (DRIVE_EN, AGC_EN, ...)"),
    Register("CTRL_SET", 0x04, "u", "wo", 0, CTRL_MASK, doc="write bits to set in CTRL"),
    Register("CTRL_CLR", 0x05, "u", "wo", 0, CTRL_MASK, doc="write bits to clear in CTRL"),
    Register("SAMPLE_PERIOD_S", 0x06, "f", "ro", unit="s", doc="demodulated sample period"),
    Register("SAMPLE_INDEX", 0x07, "u", "ro", doc="index of the last sample processed"),
    Register("STREAM_DECIMATION", 0x08, "u", "rw", 1, 100000, default=1,
             doc="stream every Nth sample (sample index divisible by N)"),
    Register("STREAM_START_INDEX", 0x09, "u", "ro", doc="SAMPLE_INDEX when the stream was enabled"),
    Register("LOOP_PERIOD_S", 0x0A, "f", "rw", 1e-4, 1.0, "s", 0.05, "loop update period (max block)"),
    Register("FORCE_LIMIT", 0x0B, "f", "rw", 0.0, 100.0, "1/s", 1.0, "clamp on each loop force"),
    Register("DRIVE_FORCE", 0x0C, "f", "rw", -100.0, 100.0, "1/s", 0.0, "open-loop amplitude force, AGC off"),
    Register("AGC_SETPOINT", 0x10, "f", "rw", 0.0, 100.0, "", 1.0, "amplitude setpoint a"),
    Register("AGC_KP", 0x11, "f", "rw", 0.0, 1e4, "1/s", 2.0, "AGC proportional gain"),
    Register("AGC_KI", 0x12, "f", "rw", 0.0, 1e4, "1/s^2", 1.0, "AGC integral gain"),
    Register("REF_FREQ_HZ", 0x13, "f", "rw", 1.0, 1e6, "Hz", 0.0, "reference (centre) frequency"),
    Register("PLL_KP", 0x14, "f", "rw", 0.0, 1e4, "Hz/rad", 1.0, "PLL proportional gain"),
    Register("PLL_KI", 0x15, "f", "rw", 0.0, 1e4, "Hz/rad/s", 2.0, "PLL integral gain"),
    Register("QUAD_KP", 0x16, "f", "rw", 0.0, 1e4, "1/s", 2.0, "quadrature loop proportional gain"),
    Register("QUAD_KI", 0x17, "f", "rw", 0.0, 1e4, "1/s^2", 1.0, "quadrature loop integral gain"),
    Register("PRECESSION_RATE_DPS", 0x18, "f", "rw", -1e4, 1e4, "deg/s", 0.0,
             "whole-angle precession command: wave angle rate"),
    Register("FM_AMPLITUDE_HZ", 0x19, "f", "rw", 0.0, 1e3, "Hz", 0.0, "reference frequency modulation amplitude"),
    Register("FM_RATE_HZ", 0x1A, "f", "rw", 0.0, 1e3, "Hz", 0.0, "reference frequency modulation rate"),
    Register("DRIFT_D_PER_S", 0x1B, "f", "rw", 0.0, 1e3, "1/s", 0.0, "drift compensation: damping anisotropy D"),
    Register("DRIFT_THETA_TAU_DEG", 0x1C, "f", "rw", -360.0, 360.0, "deg", 0.0,
             "drift compensation: damping axis theta_tau"),
    Register("PLL_FREQ_HZ", 0x1D, "f", "ro", unit="Hz", doc="reference frequency now (PLL output, FM excluded)"),
    Register("FM_FORCE_HZ", 0x1E, "f", "rw", 0.0, 1e3, "Hz", 0.0,
             "frequency-control force: a square wave at FM_RATE_HZ of a force in phase with the wave's "
             "displacement, sized to move its frequency +-this much on an ideal chain (CETC's f_omega)"),
    Register("ERR_CRC", 0x20, "u", "ro", doc="command frames the FPGA rejected (CRC or malformed)"),
    Register("ERR_CMD", 0x21, "u", "ro", doc="NACKs sent"),
    Register("FRAMES_SENT", 0x22, "u", "ro", doc="stream frames produced since the stream was enabled"),
    # output modes (0x30-0x3F)
    Register("OUTPUT_MODE", 0x30, "u", "rw", 0, 1, default=MODE_WHOLE_ANGLE,
             doc="0 whole-angle (rate-integrating), 1 force-to-rebalance (rate)"),
    Register("FTR_ANGLE_DEG", 0x31, "f", "rw", -45.0, 45.0, "deg", 0.0,
             "force-to-rebalance: the wave angle the rebalance loop holds"),
    Register("FTR_KP", 0x32, "f", "rw", 0.0, 1e3, "1/s", 4.0, "rebalance loop proportional gain"),
    Register("FTR_KI", 0x33, "f", "rw", 0.0, 1e4, "1/s^2", 4.0, "rebalance loop integral gain"),
    Register("FTR_GAIN", 0x34, "f", "rw", -1e6, 1e6, "", 1.0,
             "rate output gain G: rate_out_dps = G degrees(F_p / (4 AGC_SETPOINT))"),
)

# --- trims held in non-volatile memory (0x40-0x4F, 0x50-0x56; docs/fpga_link.md "Trims in NVM") -
NVM_COMMIT, NVM_RELOAD, NVM_ERASE = 1, 2, 3  # NVM_CMD values
NVM_VALID, NVM_MATCH, NVM_CRC_BAD = 0x01, 0x02, 0x04  # NVM_STATUS bits
TRIM_DRIFT, TRIM_SPLIT, TRIM_GAIN, TRIM_THERMAL = 0x01, 0x02, 0x04, 0x08  # TRIM_EN bits: the trims applied
TRIM_PHASE = 0x10  # the readout phase trim (TRIM_PHASE_X_DEG, TRIM_PHASE_Y_DEG)
TRIM_EN_MASK = 0x1F
TRIM_REGISTERS: tuple[Register, ...] = (
    Register("NVM_CMD", 0x40, "u", "wo", 0, 3, doc="1 commit the trim block to NVM, 2 reload it, 3 erase NVM (0 none)"),
    Register("NVM_STATUS", 0x41, "u", "ro", doc="0x01 NVM valid (CRC checks), 0x02 trims equal NVM, 0x04 CRC bad"),
    Register("NVM_CRC", 0x42, "u", "ro", doc="CRC-16 of the trim block stored in NVM (0: empty)"),
    Register("NVM_COMMITS", 0x43, "u", "ro", doc="commits since manufacture (NVM wear)"),
    Register("TRIM_EN", 0x44, "u", "rw", 0, TRIM_EN_MASK,
             doc="trims applied: 0x01 drift, 0x02 split, 0x04 gains, 0x08 thermal (bias and scale factor), "
                 "0x10 readout phase"),
    Register("TRIM_DRIFT_D_PER_S", 0x45, "f", "rw", 0.0, 1e3, "1/s", 0.0, "drift trim: damping anisotropy D"),
    Register("TRIM_DRIFT_THETA_TAU_DEG", 0x46, "f", "rw", -360.0, 360.0, "deg", 0.0, "drift trim: damping axis"),
    Register("TRIM_SPLIT_HZ", 0x47, "f", "rw", 0.0, 10.0, "Hz", 0.0, "split trim: frequency split"),
    Register("TRIM_SPLIT_THETA_DEG", 0x48, "f", "rw", -360.0, 360.0, "deg", 0.0, "split trim: frequency axis"),
    Register("TRIM_GAIN_X", 0x49, "f", "rw", 0.5, 2.0, "", 1.0, "pickoff x gain trim (multiplies cx, sx)"),
    Register("TRIM_GAIN_Y", 0x4A, "f", "rw", 0.5, 2.0, "", 1.0, "pickoff y gain trim (multiplies cy, sy)"),
    Register("TRIM_BRYAN_FACTOR", 0x4B, "f", "rw", 0.0, 1.0, "", 0.0, "scale factor trim: Bryan factor K (0 none)"),
    Register("TRIM_BIAS_DPH", 0x4C, "f", "rw", -1e6, 1e6, "deg/h", 0.0,
             "thermal trim: the bias at REF_FREQ_HZ, removed from the force-to-rebalance rate output"),
    Register("TRIM_BIAS_DPH_PER_HZ", 0x4D, "f", "rw", -1e6, 1e6, "deg/h/Hz", 0.0,
             "thermal trim: the bias's slope against the PLL frequency's offset from REF_FREQ_HZ (the "
             "resonator frequency as the thermometer)"),
    Register("TRIM_UNIT_ID", 0x4E, "u", "rw", 0, float(2**48 - 1),
             doc="the unit's serial as 48 bits of its SHA-256 (0: none), so NVM names the unit it trims"),
    Register("TRIM_FILE_ID", 0x4F, "u", "rw", 0, float(2**48 - 1), doc="compensation file id (SHA-256, 6 bytes)"),
    Register("TRIM_PHASE_X_DEG", 0x50, "f", "rw", -45.0, 45.0, "deg", 0.0,
             "readout phase trim of the x chain: its demodulation reference turned this much later (cancels "
             "a chain delay of this phase at the carrier: cx, sx rotated back by it)"),
    Register("TRIM_PHASE_Y_DEG", 0x51, "f", "rw", -45.0, 45.0, "deg", 0.0,
             "readout phase trim of the y chain (cy, sy), as TRIM_PHASE_X_DEG"),
    Register("TRIM_SF_PPM", 0x52, "f", "rw", -1e5, 1e5, "ppm", 0.0,
             "thermal trim: the scale factor's error at REF_FREQ_HZ, the force-to-rebalance rate output (less "
             "the bias trim) divided by 1 + it"),
    Register("TRIM_SF_PPM_PER_HZ", 0x53, "f", "rw", -1e5, 1e5, "ppm/Hz", 0.0,
             "thermal trim: the scale factor error's slope against the PLL frequency's offset from REF_FREQ_HZ"),
    # the branch-aware (hysteresis) trim: docs/fpga_link.md "Thermal hysteresis trim"
    Register("TRIM_HYST_HZ", 0x54, "f", "rw", -1e3, 1e3, "Hz", 0.0,
             "thermal hysteresis trim: the half-width of a play (backlash) on the PLL frequency, signed as the "
             "frequency's temperature coefficient (the play's half-width in K times df/dT, negative for a "
             "resonator that slows when heated), so its state HYST_STATE is +1 after heating, -1 after cooling "
             "(0: no play, HYST_STATE 0)"),
    Register("TRIM_BIAS_HYST_DPH", 0x55, "f", "rw", -1e6, 1e6, "deg/h", 0.0,
             "thermal hysteresis trim: the bias on heating minus that on cooling; the rate output less "
             "HYST_STATE times half of it (with TRIM_THERMAL)"),
    Register("TRIM_SF_HYST_PPM", 0x56, "f", "rw", -1e5, 1e5, "ppm", 0.0,
             "thermal hysteresis trim: the scale factor error on heating minus that on cooling; HYST_STATE "
             "times half of it joins the scale factor trim's error (with TRIM_THERMAL)"),
    Register("HYST_STATE", 0x57, "f", "ro", unit="",
             doc="the hysteresis play's normalised state in [-1, +1]: (PLL frequency - play output) / "
                 "TRIM_HYST_HZ; +1 after heating, -1 after cooling by more than the play's width"),
)
TRIM_BLOCK_SIZES = (96, 112, 128, 152)  # the block's bytes as the layouts grew (phase, scale factor, hysteresis)
TRIM_BLOCK = tuple(r.name for r in TRIM_REGISTERS if r.access == "rw")  # what NVM holds, in address order
REGISTERS = REGISTERS + TRIM_REGISTERS

BY_NAME: dict[str, Register] = {r.name: r for r in REGISTERS}
BY_ADDR: dict[int, Register] = {r.addr: r for r in REGISTERS}
for _r in REGISTERS:
    if _r.kind == "u" and _r.access == "ro":
        object.__setattr__(_r, "hi", _U64_MAX)


def register(name_or_addr: str | int) -> Register:
    """Look a register up by name or address; KeyError names the unknown key."""
    if isinstance(name_or_addr, str):
        try:
            return BY_NAME[name_or_addr.upper()]
        except KeyError:
            raise KeyError(f"unknown FPGA register {name_or_addr!r}") from None
    try:
        return BY_ADDR[int(name_or_addr)]
    except KeyError:
        raise KeyError(f"unknown FPGA register address {name_or_addr!r}") from None


def encode_value(reg: Register, value: float) -> bytes:
    """8-byte payload for a register value."""
    if reg.kind == "u":
        return struct.pack("<Q", int(value))
    return struct.pack("<d", float(value))


def decode_value(reg: Register, payload: bytes) -> float | int:
    if len(payload) != 8:
        raise ValueError(f"register payload of {len(payload)} bytes (expected 8)")
    if reg.kind == "u":
        return struct.unpack("<Q", payload)[0]
    return struct.unpack("<d", payload)[0]


def in_range(reg: Register, value: float) -> bool:
    """Whether value is a valid write for reg (finite, within [lo, hi], integral for 'u')."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return False
    if v != v or v in (float("inf"), float("-inf")):
        return False
    if reg.kind == "u" and v != int(v):
        return False
    return reg.lo <= v <= reg.hi


# --- frames -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Frame:
    """A decoded command-path frame (read, write, ack, nack)."""

    type: int
    seq: int
    addr: int
    payload: bytes


def crc16(data: bytes | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF)."""
    return crc_hqx(data, CRC_INIT)


def _crc_position_table(length: int) -> tuple[np.ndarray, int]:
    """The CRC is affine over GF(2): crc(m) = crc(zeros) ^ XOR_j T[j, m[j]] with T[j, v] the CRC
    (from 0) of v at position j and zeros elsewhere.  The lookups are independent (no chain from
    byte to byte as in the classic table loop), so a compiled loop over them is ~4x faster."""
    table = np.empty((length, 256), np.uint16)
    for j in range(length):
        msg = bytearray(length)
        for v in range(256):
            msg[j] = v
            table[j, v] = crc_hqx(bytes(msg), 0)
    return table, crc_hqx(bytes(length), CRC_INIT)


_CRC_BODY = 68  # a stream frame's CRC covers type..payload (STREAM_FRAME_SIZE - sync - crc)
STREAM_CRC_TABLE, STREAM_CRC_ZEROS = _crc_position_table(_CRC_BODY)


@njit(cache=True)
def _frame_crc(frame: np.ndarray, table: np.ndarray, crc_zeros: int) -> int:
    """CRC-16/CCITT-FALSE of a stream frame's bytes 2..69 (the position table of its length)."""
    crc = np.uint16(crc_zeros)
    for j in range(table.shape[0]):
        crc ^= table[j, frame[2 + j]]
    return int(crc)


@njit(cache=True)
def _crc16_frames(frames: np.ndarray, table: np.ndarray, crc_zeros: int, out: np.ndarray) -> None:
    """out[i] = CRC of frames[i, 2:-2] (type..payload of stream frame i)."""
    for i in range(frames.shape[0]):
        out[i] = _frame_crc(frames[i], table, crc_zeros)


_SYNC_LO, _SYNC_HI = SYNC[0], SYNC[1]


@njit(cache=True)
def _valid_stream_run(frames: np.ndarray, table: np.ndarray, crc_zeros: int) -> int:
    """How many of frames (k, 72 uint8) from the first are whole stream frames: sync word, type,
    length and CRC each as the protocol has them (the first frame that fails ends the run)."""
    for i in range(frames.shape[0]):
        f = frames[i]
        if f[0] != _SYNC_LO or f[1] != _SYNC_HI or f[2] != STREAM or f[3] != STREAM_PAYLOAD:
            return i
        if _frame_crc(f, table, crc_zeros) != (f[70] | (f[71] << 8)):
            return i
    return frames.shape[0]


def crc16_frames(frames: np.ndarray) -> np.ndarray:
    """CRC of every frame of a (n, L) uint8 array of whole frames (sync .. crc), compiled: the
    stream's CRCs in ~0.1 us a frame (crc_hqx per frame cost ~0.5 us, the table gather more)."""
    if frames.shape[1] != STREAM_FRAME_SIZE:
        raise ValueError(f"stream frames are {STREAM_FRAME_SIZE} bytes, not {frames.shape[1]}")
    out = np.empty(frames.shape[0], np.uint16)
    _crc16_frames(frames, STREAM_CRC_TABLE, STREAM_CRC_ZEROS, out)
    return out


def encode_frame(ftype: int, seq: int, addr: int, payload: bytes = b"") -> bytes:
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    body = HEADER.pack(SYNC_U16, ftype, len(payload), seq % SEQ_MOD, addr) + payload
    return body + struct.pack("<H", crc16(body[2:]))


# --- stream -----------------------------------------------------------------------------------
STREAM_PAYLOAD = 60
N_CHANNELS = 11  # 8 float32 channels, the angle (f64), the rate output (f32) and the saturation bits (u16)
STREAM_DTYPE = np.dtype(
    [
        ("sync", "<u2"),
        ("type", "u1"),
        ("len", "u1"),
        ("seq", "<u4"),
        ("addr", "<u2"),
        ("index", "<u8"),
        ("t_s", "<f8"),
        ("ch", "<f4", (8,)),
        ("angle_out_deg", "<f8"),
        ("rate_out_dps", "<f4"),
        ("crc", "<u2"),
    ]
)
STREAM_FRAME_SIZE = STREAM_DTYPE.itemsize  # 72
assert STREAM_FRAME_SIZE == HEADER_SIZE + STREAM_PAYLOAD + CRC_SIZE == _CRC_BODY + 4


_STREAM_TEMPLATE = np.zeros(0, STREAM_DTYPE)


def _stream_template(n: int) -> np.ndarray:
    """n frames with the constant fields (sync, type, length) filled in; copy before use."""
    global _STREAM_TEMPLATE
    if len(_STREAM_TEMPLATE) < n:
        tpl = np.zeros(max(n, 2 * len(_STREAM_TEMPLATE), 64), STREAM_DTYPE)
        tpl["sync"] = SYNC_U16
        tpl["type"] = STREAM
        tpl["len"] = STREAM_PAYLOAD
        _STREAM_TEMPLATE = tpl
    return _STREAM_TEMPLATE[:n]


@njit(cache=True)
def put_stream_frame(
    frame: np.ndarray, seq: int, index: int, t_s: float, ch: np.ndarray, table: np.ndarray, crc_zeros: int
) -> None:
    """Write one stream frame's seq, index, t_s, channels (10: eight as float32, the angle as
    float64, the rate output as float32) and CRC into `frame` (72 uint8) whose sync, type, length
    and address are set (STREAM_DTYPE's layout, little-endian).
    Compiled, so the simulated FPGA's block kernel writes its frames without a Python step."""
    seq &= 0xFFFFFFFF
    for j in range(4):
        frame[4 + j] = (seq >> (8 * j)) & 0xFF
    idx = np.uint64(index)
    t_bits = np.float64(t_s).view(np.uint64)
    for j in range(8):
        frame[10 + j] = (idx >> np.uint64(8 * j)) & np.uint64(0xFF)
        frame[18 + j] = (t_bits >> np.uint64(8 * j)) & np.uint64(0xFF)
    for c in range(8):
        bits = np.float32(ch[c]).view(np.uint32)
        for j in range(4):
            frame[26 + 4 * c + j] = (bits >> np.uint32(8 * j)) & np.uint32(0xFF)
    a_bits = np.float64(ch[8]).view(np.uint64)
    for j in range(8):
        frame[58 + j] = (a_bits >> np.uint64(8 * j)) & np.uint64(0xFF)
    r_bits = np.float32(ch[9]).view(np.uint32)
    for j in range(4):
        frame[66 + j] = (r_bits >> np.uint32(8 * j)) & np.uint32(0xFF)
    if ch.shape[0] > 10:  # the saturation bits, in the address field
        flags = int(ch[10])
        frame[8] = flags & 0xFF
        frame[9] = (flags >> 8) & 0xFF
    crc = _frame_crc(frame, table, crc_zeros)
    frame[70] = crc & 0xFF
    frame[71] = crc >> 8


@njit(cache=True)
def _encode_frames(
    frames: np.ndarray, seq0: int, index: np.ndarray, t_s: np.ndarray, ch: np.ndarray, table: np.ndarray, crc0: int
) -> None:
    row = np.zeros(N_CHANNELS)
    for i in range(frames.shape[0]):
        for c in range(ch.shape[1]):
            row[c] = ch[i, c]
        put_stream_frame(frames[i], seq0 + i, index[i], t_s[i], row, table, crc0)


def stream_frame_buffer(n: int) -> np.ndarray:
    """(n, 60) uint8 with every frame's constant fields (sync, type, length, address) set."""
    return _stream_template(n).copy().view(np.uint8).reshape(n, STREAM_FRAME_SIZE)


def encode_stream(seq0: int, index: np.ndarray, t_s: np.ndarray, channels: np.ndarray) -> bytes:
    """Encode n stream frames at once (one compiled pass, CRC per frame): channels is (n, 11) in
    stream order after t_s, or (n, 10) with no saturation bits, or (n, 8) with the outputs zero too."""
    frames = stream_frame_buffer(len(index))
    _encode_frames(frames, int(seq0) % SEQ_MOD, np.asarray(index, np.int64), np.asarray(t_s, float),
                   np.asarray(channels, float), STREAM_CRC_TABLE, STREAM_CRC_ZEROS)  # fmt: skip
    return frames.tobytes()


def stream_rows(arr: np.ndarray) -> np.ndarray:
    """Decoded stream frames -> (n, 13) float64 block in STREAM_COLUMNS order."""
    out = np.empty((len(arr), len(STREAM_COLUMNS)))
    out[:, 0] = arr["index"]
    out[:, 1] = arr["t_s"]
    out[:, 2:10] = arr["ch"]
    out[:, 10] = arr["angle_out_deg"]
    out[:, 11] = arr["rate_out_dps"]
    out[:, 12] = arr["addr"]
    return out


class FrameParser:
    """Incremental parser: feed bytes, get stream frames (a structured array) and command frames.

    Resynchronises after garbage by searching the next sync word; a frame whose CRC fails is
    counted corrupt and the search resumes one byte later, so a corrupted byte can never become
    a sample.  Runs of stream frames are checked and decoded vectorised.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.corrupt = 0  # frames rejected (CRC, bad type or length)
        self.resyncs = 0  # times bytes were skipped to find a sync word
        self.bytes_skipped = 0

    def feed(self, data: bytes) -> tuple[list[np.ndarray], list[Frame]]:
        if not self._buf and isinstance(data, bytes) and len(data) and len(data) % STREAM_FRAME_SIZE == 0:
            # the usual read: whole stream frames and nothing else, checked in one compiled pass
            rows = np.frombuffer(data, np.uint8).reshape(-1, STREAM_FRAME_SIZE)
            if _valid_stream_run(rows, STREAM_CRC_TABLE, STREAM_CRC_ZEROS) == len(rows):
                return [np.frombuffer(data, STREAM_DTYPE)], []  # bytes: read-only, nothing pinned
        buf = self._buf
        buf += data
        streams: list[np.ndarray] = []
        frames: list[Frame] = []
        pos = 0
        n = len(buf)
        size = STREAM_FRAME_SIZE
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                keep = 1 if n > pos and buf[-1] == SYNC[0] else 0  # maybe the first half of a sync
                if n - keep > pos:
                    self._skip(n - keep - pos)
                    pos = n - keep
                break
            if i > pos:
                self._skip(i - pos)
            pos = i
            if n - i < HEADER_SIZE:
                break
            ftype, length = buf[i + 2], buf[i + 3]
            if ftype not in FRAME_TYPES or (ftype == STREAM and length != STREAM_PAYLOAD):
                self.corrupt += 1
                pos = i + 1
                continue
            flen = HEADER_SIZE + length + CRC_SIZE
            if n - i < flen:
                break
            if ftype == STREAM:
                run = self._stream_run(buf, i, (n - i) // size)
                if run is None:
                    self.corrupt += 1
                    pos = i + 1
                    continue
                streams.append(run)
                pos = i + len(run) * size
                continue
            body = bytes(buf[i + 2 : i + flen - 2])
            if crc16(body) != buf[i + flen - 2] | (buf[i + flen - 1] << 8):
                self.corrupt += 1
                pos = i + 1
                continue
            _, _, _, seq, addr = HEADER.unpack_from(buf, i)
            frames.append(Frame(ftype, seq, addr, body[HEADER_SIZE - 2 :]))
            pos = i + flen
        del buf[:pos]
        return streams, frames

    def _skip(self, n: int) -> None:
        self.resyncs += 1
        self.bytes_skipped += n

    @staticmethod
    def _stream_run(buf: bytearray, i: int, k: int) -> np.ndarray | None:
        """The longest run of valid stream frames starting at i (None if the first is bad)."""
        size = STREAM_FRAME_SIZE
        chunk = bytes(buf[i : i + k * size])  # a copy: frombuffer would pin the bytearray
        m = _valid_stream_run(np.frombuffer(chunk, np.uint8).reshape(k, size), STREAM_CRC_TABLE, STREAM_CRC_ZEROS)
        if m == 0:
            return None
        return np.frombuffer(chunk, STREAM_DTYPE, count=m)
