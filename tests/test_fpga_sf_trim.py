"""The thermal trim's scale factor part (TRIM_SF_PPM, TRIM_SF_PPM_PER_HZ; docs/fpga_link.md "Trims
in NVM"): the force-to-rebalance rate output, less the bias trim, over 1 + the scale factor error at
the PLL frequency; off by default; NVM blocks of the older layouts still load."""

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


def _ftr_rate(trims: dict[str, float]) -> tuple[float, float]:
    """The rate output (deg/s) and the PLL frequency's offset (Hz) after 3 s of force-to-rebalance at
    10 deg/s on an ideal HRG (seeded: the same run with and without the trims)."""
    params = preset("hrg-ideal")
    world = World(params, seed=5)
    fw = FpgaFirmware(world)
    world.attach(fw)
    regs = [("REF_FREQ_HZ", params.f0_hz - 1.0), ("AGC_SETPOINT", 1.0), ("LOOP_PERIOD_S", 0.05),
            ("OUTPUT_MODE", p.MODE_FORCE_TO_REBALANCE), ("FTR_GAIN", 3.6), *trims.items()]
    for name, value in regs:
        fw.write(p.BY_NAME[name], value)
    fw.write(p.BY_NAME["CTRL"], p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN)
    world.case_rate_dps = 10.0
    world.advance(3.0)
    return float(fw._st[k.S_RATE_OUT]), float(fw._st[k.S_OUT + 1])


def test_the_scale_factor_trim_divides_the_rate_output_by_one_plus_its_error():
    raw, df_hz = _ftr_rate({})
    assert raw == pytest.approx(3.6 * preset("hrg-ideal").bryan_factor * 10.0, rel=0.1)  # G K Omega, still settling
    assert df_hz == pytest.approx(1.0, abs=0.01)  # the PLL on f0, REF_FREQ_HZ 1 Hz below
    sf = {"TRIM_BIAS_DPH": 360.0, "TRIM_SF_PPM": 2000.0, "TRIM_SF_PPM_PER_HZ": 150.0}
    off, _ = _ftr_rate(sf)  # TRIM_EN clear: nothing applied
    assert off == raw
    on, _ = _ftr_rate({**sf, "TRIM_EN": p.TRIM_THERMAL})
    assert on == pytest.approx((raw - 0.1) / (1.0 + 1e-6 * (2000.0 + 150.0 * df_hz)), rel=1e-12)


def test_older_nvm_blocks_load_with_the_scale_factor_trim_off():
    regs = {name: p.BY_NAME[name].default for name in p.TRIM_BLOCK}
    regs.update(TRIM_EN=p.TRIM_THERMAL | p.TRIM_PHASE, TRIM_BIAS_DPH=12.5, TRIM_PHASE_Y_DEG=1.5)
    full = encode_block(regs)
    assert len(full) == 8 * len(p.TRIM_BLOCK) == p.TRIM_BLOCK_SIZES[-1]
    for size in p.TRIM_BLOCK_SIZES:
        nvm = Nvm()
        nvm.data = full[:size] + struct.pack("<H", p.crc16(full[:size]))  # as an older firmware committed it
        assert nvm.valid
        back = decode_block(nvm.block())
        assert back["TRIM_BIAS_DPH"] == 12.5 and back["TRIM_SF_PPM"] == back["TRIM_SF_PPM_PER_HZ"] == 0.0
        assert back["TRIM_PHASE_Y_DEG"] == (1.5 if size > 96 else 0.0)
    nvm = Nvm()
    nvm.data = full[:104] + struct.pack("<H", p.crc16(full[:104]))  # no layout this long: not valid
    assert not nvm.valid


def test_a_unit_with_an_older_block_powers_up_with_its_trims(tmp_path):
    """The firmware loads a 112-byte block (before the scale factor trim) and says it matches NVM."""
    regs = {name: p.BY_NAME[name].default for name in p.TRIM_BLOCK}
    regs.update(TRIM_EN=p.TRIM_THERMAL, TRIM_BIAS_DPH=-7.0, TRIM_BIAS_DPH_PER_HZ=0.25)
    old = encode_block(regs)[:112]
    path = tmp_path / "nvm.bin"
    path.write_bytes(struct.pack("<I", 3) + old + struct.pack("<H", p.crc16(old)))
    world = World(preset("hrg-ideal"), seed=1)
    fw = FpgaFirmware(world, nvm=Nvm(path))
    assert fw.regs["TRIM_EN"] == p.TRIM_THERMAL and fw.regs["TRIM_BIAS_DPH_PER_HZ"] == 0.25
    assert fw.regs["TRIM_SF_PPM"] == 0.0
    assert fw._nvm_status() == p.NVM_VALID | p.NVM_MATCH
