"""FPGA link protocol: frame codec, CRC, parser resynchronisation, register map (no transport)."""

from __future__ import annotations

import struct
from binascii import crc_hqx

import numpy as np
import pytest

from drivers.fpga import protocol as p


def _stream(n: int, seed: int = 0, seq0: int = 0) -> tuple[bytes, np.ndarray]:
    rng = np.random.default_rng(seed)
    index = np.arange(1, n + 1, dtype=np.int64)
    ch = rng.normal(size=(n, 11)).astype(np.float32).astype(float)
    ch[:, 8] = rng.normal(size=n) * 1e3  # the angle output travels as float64
    ch[:, 10] = rng.integers(0, 16, size=n)  # the loops' saturation bits (the address field)
    return p.encode_stream(seq0, index, index * 1e-3, ch), ch


def test_crc_is_ccitt_false():
    # the standard check value of CRC-16/CCITT-FALSE over "123456789" is 0x29B1
    assert p.crc16(b"123456789") == 0x29B1


def test_command_frame_layout_and_round_trip():
    reg = p.BY_NAME["AGC_SETPOINT"]
    frame = p.encode_frame(p.WRITE, 7, reg.addr, p.encode_value(reg, 0.75))
    assert frame[:2] == b"\xa5\x5a" and len(frame) == p.HEADER_SIZE + 8 + p.CRC_SIZE
    assert struct.unpack("<H", frame[-2:])[0] == crc_hqx(frame[2:-2], 0xFFFF)
    streams, frames = p.FrameParser().feed(frame)
    assert streams == [] and frames == [p.Frame(p.WRITE, 7, reg.addr, struct.pack("<d", 0.75))]
    assert p.decode_value(reg, frames[0].payload) == 0.75


def test_stream_round_trip_in_random_chunks():
    data, ch = _stream(500)
    data += p.encode_frame(p.ACK, 3, 0x10, bytes(8))
    parser = p.FrameParser()
    rng = np.random.default_rng(1)
    blocks, cmds, pos = [], [], 0
    while pos < len(data):
        k = int(rng.integers(1, 300))
        s, f = parser.feed(data[pos : pos + k])
        blocks += [p.stream_rows(a) for a in s]
        cmds += f
        pos += k
    rows = np.vstack(blocks)
    assert rows.shape == (500, 13) and len(p.STREAM_COLUMNS) == 13
    np.testing.assert_array_equal(rows[:, 0], np.arange(1, 501))
    np.testing.assert_array_equal(rows[:, 2:], ch)  # float32 values survive exactly
    assert len(cmds) == 1 and parser.corrupt == 0 and parser.resyncs == 0


def test_corrupted_bytes_never_yield_a_wrong_sample():
    """Every frame gets one byte altered somewhere (header, payload or CRC) in half the frames:
    each surviving sample must equal what was sent (CRC-16 catches every single-byte error)."""
    n = 2000
    data, ch = _stream(n, seed=2)
    rng = np.random.default_rng(3)
    buf = bytearray(data)
    hit = np.flatnonzero(rng.random(n) < 0.5)
    for j in hit:
        buf[j * p.STREAM_FRAME_SIZE + int(rng.integers(0, p.STREAM_FRAME_SIZE))] ^= int(rng.integers(1, 256))
    parser = p.FrameParser()
    rows = np.vstack([p.stream_rows(a) for a in parser.feed(bytes(buf))[0]])
    idx = rows[:, 0].astype(int)
    np.testing.assert_array_equal(rows[:, 2:], ch[idx - 1])
    # a corrupted frame is never delivered; every clean frame is (a corrupted neighbour cannot hide it)
    assert set(idx) == set(np.setdiff1d(np.arange(n), hit) + 1)
    assert parser.corrupt > 0.5 * len(hit) and parser.resyncs > 0  # sync hits are skipped, not counted


def test_garbage_between_frames_resyncs():
    data, ch = _stream(10)
    garbage = bytes([0xA5, 0x00, 0x5A, 0xA5, 0x5A, 0x05, 0xFF]) * 3
    parser = p.FrameParser()
    cut = 5 * p.STREAM_FRAME_SIZE  # between two frames
    s, _ = parser.feed(garbage + data[:cut] + garbage + data[cut:])
    rows = np.vstack([p.stream_rows(a) for a in s])
    np.testing.assert_array_equal(rows[:, 0], np.arange(1, 11))
    assert parser.resyncs >= 2


def test_register_map_is_consistent():
    assert len(p.BY_NAME) == len(p.REGISTERS) and len(p.BY_ADDR) == len(p.REGISTERS)
    for reg in p.REGISTERS:
        assert reg.kind in ("u", "f") and reg.access in ("ro", "rw", "wo")
        if reg.access != "ro":
            assert reg.lo <= reg.default <= reg.hi or reg.name in ("REF_FREQ_HZ", "CTRL_SET", "CTRL_CLR"), reg.name
    assert p.register("agc_setpoint") is p.BY_NAME["AGC_SETPOINT"]
    assert p.register(0x13).name == "REF_FREQ_HZ"
    with pytest.raises(KeyError, match="NOPE"):
        p.register("NOPE")
    assert not p.in_range(p.BY_NAME["STREAM_DECIMATION"], 0)
    assert not p.in_range(p.BY_NAME["STREAM_DECIMATION"], 2.5)
    assert not p.in_range(p.BY_NAME["AGC_SETPOINT"], float("nan"))


def test_compiled_stream_encoder_matches_the_layout_byte_for_byte():
    """encode_stream (compiled, position-table CRC) against struct packing and crc_hqx, across the
    32-bit sequence wrap, with float64 channels rounded to float32 as the frame carries them (the
    angle output stays float64): protocol version 3's 72-byte frame, the saturation bits in addr."""
    rng = np.random.default_rng(5)
    n, seq0 = 7, p.SEQ_MOD - 3
    index = np.array([0, 1, 2**40, 5, 6, 2**63 - 1, 9], dtype=np.int64)
    t_s = rng.normal(size=n) * 1e3
    ch = rng.normal(size=(n, 11))
    ch[:, 10] = [0, p.SAT_PREC, 15, 1, 2, 8, 0]
    want = b""
    for i in range(n):
        body = struct.pack("<BBIHQd8fdf", p.STREAM, p.STREAM_PAYLOAD, (seq0 + i) % p.SEQ_MOD, int(ch[i, 10]),
                           int(index[i]),
                           float(t_s[i]), *ch[i, :8].astype(np.float32), float(ch[i, 8]),
                           np.float32(ch[i, 9]))  # fmt: skip
        want += b"\xa5\x5a" + body + struct.pack("<H", crc_hqx(body, 0xFFFF))
    assert p.encode_stream(seq0, index, t_s, ch) == want
    assert p.STREAM_FRAME_SIZE == 72 and p.PROTOCOL_VERSION == 3
    rows = np.frombuffer(want, np.uint8).reshape(n, p.STREAM_FRAME_SIZE)
    assert p.crc16_frames(rows).tolist() == [crc_hqx(r[2:-2].tobytes(), 0xFFFF) for r in rows]
