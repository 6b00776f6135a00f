"""The thermal hysteresis trim (TRIM_HYST_HZ, TRIM_BIAS_HYST_DPH, TRIM_SF_HYST_PPM, HYST_STATE;
docs/fpga_link.md "Thermal hysteresis trim"): a play on the PLL frequency whose state, +1 after
heating and -1 after cooling, takes half the heating-minus-cooling bias off the rate output; off
by default; NVM blocks of the older layouts load with it off."""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import struct

import pytest

from drivers.fpga import protocol as p
from simulators.fpga import kernels as k
from simulators.fpga.firmware import FpgaFirmware
from simulators.fpga.nvm import Nvm, decode_block, encode_block
from simulators.physics.params import preset
from simulators.world import World

HALF_WIDTH_HZ = -0.2  # a resonator that slows when heated: the play's half-width times a negative df/dT
#: REF_FREQ_HZ's steps (Hz) and the play's state after each: the PLL frequency's offset from it, f, falls
#: by the step.  +0.5: f falls 0.5 Hz (heating through the band: s = +1); -1.0: f rises past the band
#: (cooling: s = -1); +0.1: back into the band by half its width (s = -0.5)
STEPS = ((0.5, 1.0), (-1.0, -1.0), (0.1, -0.5))


def _run(trims: dict[str, float]) -> list[tuple[float, float]]:
    """(rate output deg/s, HYST_STATE) 2 s after each of STEPS, force-to-rebalance at 10 deg/s on an ideal
    HRG (seeded: the same run with and without the trims)."""
    params = preset("hrg-ideal")
    world = World(params, seed=5)
    fw = FpgaFirmware(world)
    world.attach(fw)
    ref_hz = params.f0_hz - 1.0
    regs = [("REF_FREQ_HZ", ref_hz), ("AGC_SETPOINT", 1.0), ("LOOP_PERIOD_S", 0.05),
            ("OUTPUT_MODE", p.MODE_FORCE_TO_REBALANCE), ("FTR_GAIN", 3.6), *trims.items()]
    for name, value in regs:
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN)
    world.case_rate_dps = 10.0
    world.advance(2.0)
    out = []
    for step_hz, _ in STEPS:
        ref_hz += step_hz
        fw.write(p.BY_NAME["REF_FREQ_HZ"], ref_hz)
        world.advance(2.0)
        out.append((float(fw._st[k.S_RATE_OUT]), float(fw.read(p.BY_NAME["HYST_STATE"]))))
    return out


def test_the_play_takes_half_the_hysteresis_off_by_branch():
    raw = _run({})
    assert [s for _, s in raw] == [0.0, 0.0, 0.0]  # no play without a half-width
    hyst = {"TRIM_HYST_HZ": HALF_WIDTH_HZ, "TRIM_BIAS_HYST_DPH": -216.0, "TRIM_SF_HYST_PPM": -200.0}
    off = _run(hyst)  # TRIM_EN clear: the play tracks, nothing is applied
    assert [r for r, _ in off] == [r for r, _ in raw]
    assert [s for _, s in off] == pytest.approx([s for _, s in STEPS], abs=1e-3)  # the PLL's jitter: ~uHz
    on = _run({**hyst, "TRIM_EN": p.TRIM_THERMAL})
    for (r_raw, _), (r_on, s), (_, s_want) in zip(raw, on, STEPS, strict=True):
        assert s == pytest.approx(s_want, abs=1e-3)
        # heating (s = +1): the bias is half the (negative) hysteresis low of the mean: the trim adds 108 deg/h
        want = (r_raw - 0.5 * -216.0 * s / 3600.0) / (1.0 + 1e-6 * 0.5 * -200.0 * s)
        assert r_on == pytest.approx(want, rel=1e-12)
    assert on[0][0] - raw[0][0] == pytest.approx(108.0 / 3600.0 + 100e-6 * raw[0][0], rel=1e-3)


def test_writing_the_half_width_restarts_the_play():
    world = World(preset("hrg-ideal"), seed=1)
    fw = FpgaFirmware(world)
    fw._st[k.S_HYST], fw._st[k.S_PLAY_OK] = 1.0, 1.0
    fw.write(p.BY_NAME["TRIM_HYST_HZ"], 0.3)
    assert fw.read(p.BY_NAME["HYST_STATE"]) == 0.0 and fw._st[k.S_PLAY_OK] == 0.0


def test_hysteresis_trim_round_trips_through_nvm_and_older_blocks_load_it_off(tmp_path):
    world = World(preset("hrg-ideal"), seed=1)
    path = tmp_path / "nvm.bin"
    fw = FpgaFirmware(world, nvm=Nvm(path))
    values = {"TRIM_EN": p.TRIM_THERMAL, "TRIM_BIAS_DPH": 12.5, "TRIM_SF_PPM": 30.0, "TRIM_HYST_HZ": -0.0125,
              "TRIM_BIAS_HYST_DPH": -216.0, "TRIM_SF_HYST_PPM": -200.0}
    for name, value in values.items():
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["NVM_CMD"], p.NVM_COMMIT)
    assert len(Nvm(path).block()) == p.TRIM_BLOCK_SIZES[-1] == 152
    again = FpgaFirmware(World(preset("hrg-ideal"), seed=2), nvm=Nvm(path))  # a power cycle
    assert {n: again.regs[n] for n in values} == values
    assert again._nvm_status() == p.NVM_VALID | p.NVM_MATCH
    regs = {name: p.BY_NAME[name].default for name in p.TRIM_BLOCK} | values
    full = encode_block(regs)
    for size in p.TRIM_BLOCK_SIZES[:-1]:  # as firmware before the hysteresis trim committed it
        nvm = Nvm()
        nvm.data = full[:size] + struct.pack("<H", p.crc16(full[:size]))
        assert nvm.valid
        back = decode_block(nvm.block())
        assert back["TRIM_HYST_HZ"] == back["TRIM_BIAS_HYST_DPH"] == back["TRIM_SF_HYST_PPM"] == 0.0
        assert back["TRIM_BIAS_DPH"] == 12.5
