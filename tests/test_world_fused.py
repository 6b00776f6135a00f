"""The world's fused blocks (simulators.fused) give the numbers of the per-block path bit for bit:
two worlds of the same seed, one with `fused` off, go through the same script (whole-angle drive,
a table spun up and held at rate, a free decay, gain trims, an undecimated stream, the front end's
drive on and off, the slow drifts and noise of sim-hrg-wa, a noise-free resonator, a scheduled fault) and must agree in
every state, register, stream byte and listener call, while the fused one took most blocks fused."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.fpga import protocol as p
from drivers.rate_table import modbus_protocol as mp
from simulators.chamber.thermal import ChamberThermal
from simulators.faults import FaultScheduler
from simulators.fpga.firmware import FpgaFirmware
from simulators.frontend.model import FrontEndModel
from simulators.physics.errors import ERROR_PRESETS, ErrorSources
from simulators.physics.noise import NOISE_PRESETS, earth_rate_dph
from simulators.physics.params import preset
from simulators.rate_table.mechanics import TableMechanics
from simulators.world import World

WA = p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE | p.STREAM_EN


class Rig:
    """A world with the four simulated devices and what they hand out, recorded."""

    def __init__(self, name: str, fused: bool, seed: int = 7, errors: ErrorSources | None = None) -> None:
        params = preset(name)
        self.world = World(params, seed=seed, noise=NOISE_PRESETS.get(name), earth_rate_dph=earth_rate_dph(48.0),
                           errors=errors)  # fmt: skip
        self.world.fused = fused
        self.stream: list[bytes] = []
        self.fired: list[tuple[float, str]] = []
        self.faults = FaultScheduler(lambda kind: self.fired.append((self.world.t_s, kind)))
        self.table = TableMechanics(seed=seed, watchdog_s=0.0)
        self.fe = FrontEndModel(seed=seed)
        self.fw = FpgaFirmware(self.world)
        self.fw.sink = lambda data, n: self.stream.append(data)
        for dev in (self.faults, self.table, self.fe, self.fw):
            self.world.attach(dev)
        self.blocks_seen: list[tuple[int, float]] = []  # (first index, sum of q_meas) per block
        self.world.add_listener(
            lambda w: self.blocks_seen.append((w.last_block.first_index, float(w.last_block.q_meas.sum())))
        )
        self.moved = [0]
        self.world.add_listener(lambda w: self.moved.__setitem__(0, self.moved[0] + 1), each_block=False)

    def reg(self, name: str, value: float) -> None:
        with self.world.lock:
            self.fw.write(p.register(name), value)

    def scpi(self, message: str) -> None:
        with self.world.lock:
            self.fe.execute(message, self.world)

    def script(self) -> None:
        w = self.world
        self.faults.add("probe", 7.3)
        self.reg("REF_FREQ_HZ", w.params.f0_hz)
        self.reg("AGC_SETPOINT", 1.0)
        self.reg("STREAM_DECIMATION", 10)
        self.reg("CTRL", WA)
        for dt in (0.4, 0.4, 0.37, 1.0, 0.05, 2.0, 0.4, 3.3):
            w.advance(dt)
        with w.lock:  # the table to 100 deg/s: its ramp goes block by block, then held at rate
            self.table.set_enabled(True)
            self.table.command(mp.MODE_RATE, 100.0, 0.0, 500.0)
        for _ in range(10):
            w.advance(0.4)
        self.scpi("OUTP1 ON")  # the front end drives: no fused blocks while it does
        w.advance(0.8)
        self.scpi("OUTP1 OFF;SENS:LOCK:TC 0.01")
        w.advance(1.2)
        self.reg("TRIM_GAIN_X", 1.01)
        self.reg("TRIM_EN", p.TRIM_GAIN)
        self.reg("STREAM_DECIMATION", 1)
        w.advance(1.6)
        self.reg("CTRL", p.PLL_EN | p.STREAM_EN)  # the drive cut: a free decay, the PLL tracking
        for _ in range(6):
            w.advance(0.4)
        self.reg("CTRL", 0)  # everything off
        w.advance(2.0)

    def state(self) -> dict[str, object]:
        w, fw = self.world, self.fw
        env = w.environment
        return {
            "q": w.resonator._q.copy(), "psi": w.resonator._psi, "zg": w.resonator._zg.copy(),
            "index": w.sample_index, "case_angle": w.case_angle_deg, "case_rate": w.case_rate_dps,
            "ref": w.ref_freq_hz, "forces": {k: v.copy() for k, v in w._forces.items()},
            "st": fw._st.copy(), "regs": dict(fw.regs), "dec": (fw._dec_sum.copy(), fw._dec_n, fw._stream_seq),
            "stream": b"".join(self.stream), "lockin": self.fe.lockin.copy(),
            "table": (self.table.angle_deg, self.table.ref_angle_deg, self.table._noise_state, self.table.t_s),
            "env": None if env is None else (env._pos, env._wander_phi, env.turn_on_count),
            "fired": list(self.fired), "blocks_seen": list(self.blocks_seen),
            "normals": w.resonator._normals.take(3).copy(),
            "thermal": (w.temperature_c, w.stress_c, w.resonator._thermal),
        }


def _same(a: object, b: object, path: str = "") -> None:
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for key in a:
            _same(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, (tuple, list)):
        assert isinstance(b, (tuple, list)) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b), f"{path} differs"
    else:
        assert a == b or (a != a and b != b), f"{path}: {a!r} != {b!r}"


@pytest.mark.parametrize("name", ["hrg-wa", "hrg", "hrg-ideal"])
def test_fused_blocks_give_the_per_block_numbers_bit_for_bit(name):
    plain, fused = Rig(name, fused=False), Rig(name, fused=True)
    plain.script()
    fused.script()
    _same(plain.state(), fused.state())
    assert [kind for _, kind in fused.fired] == ["probe"]
    n_blocks = len(fused.blocks_seen)
    assert plain.moved[0] == n_blocks  # the per-block path calls every listener after every block
    assert fused.moved[0] < n_blocks  # the fused one calls the run listeners once a fused run
    assert fused.world.blocks_fused > 0.5 * n_blocks, (fused.world.blocks_fused, n_blocks)


def test_the_fused_path_stands_aside_for_what_it_does_not_model():
    """A nonlinear resonator, FM on or an unknown device: every block goes the per-block way."""
    mems = Rig("mems", fused=True)
    mems.script()
    assert mems.world.blocks_fused == 0
    rig = Rig("hrg-wa", fused=True)
    rig.reg("REF_FREQ_HZ", rig.world.params.f0_hz)
    rig.reg("CTRL", WA)
    rig.reg("FM_AMPLITUDE_HZ", 0.1)
    rig.reg("FM_RATE_HZ", 1.0)
    rig.world.advance(2.0)
    assert rig.world.blocks_fused == 0
    rig.reg("FM_AMPLITUDE_HZ", 0.0)
    rig.world.advance(2.0)
    assert rig.world.blocks_fused > 0

    class Other:
        def before_block(self, world, t_s, n, dt_s): ...

        def after_block(self, world, block): ...

    done = rig.world.blocks_fused
    rig.world.attach(Other())
    rig.world.advance(2.0)
    assert rig.world.blocks_fused == done


#: the realistic HRG's error sources with a temperature bias and thermal hysteresis as well
THERMAL_ERRORS = ERROR_PRESETS["hrg-realistic"].with_(
    bias_tc_dps_k=0.002, bias_tc2_dps_k2=1e-4, hyst_halfwidth_k=0.5, bias_hyst_dps=-0.01, sf_hyst_ppm=-200.0
)


@pytest.mark.parametrize("name", ["hrg-wa", "hrg"])
def test_fused_blocks_with_error_sources_in_a_moving_chamber_give_the_per_block_numbers(name):
    """A unit with every error source in a chamber whose temperature changes every block (heating,
    then cooling through the hysteresis's play): the fused path's samples are the per-block ones."""
    rigs = []
    for fused in (False, True):
        rig = Rig(name, fused=fused, errors=THERMAL_ERRORS)
        chamber = ChamberThermal(setpoint_c=35.0, ramp_c_per_min=300.0, case_tau_s=2.0, resonator_tau_s=1.0)
        rig.world.attach(chamber)
        rig.script()
        with rig.world.lock:
            chamber.setpoint_c = 20.0
        peak_c = rig.world.temperature_c
        rig.world.advance(6.0)
        rigs.append(rig)
    plain, fused = rigs
    _same(plain.state(), fused.state())
    assert plain.world.blocks_fused == 0
    n_blocks = len(fused.blocks_seen)
    assert fused.world.blocks_fused > 0.5 * n_blocks, (fused.world.blocks_fused, n_blocks)
    assert peak_c > 30.0 and fused.world.temperature_c < peak_c - 2.0  # heated, then cooled on its branch
    assert fused.world.stress_c == fused.world.temperature_c + 0.5


def test_a_chamber_on_a_unit_without_error_sources_keeps_the_per_block_path():
    """The fused path steps a chamber with the error sources' inputs only: without error sources
    the chamber still moves the unit's temperature, block by block."""
    rig = Rig("hrg-wa", fused=True)
    chamber = ChamberThermal(setpoint_c=35.0, ramp_c_per_min=300.0, case_tau_s=2.0, resonator_tau_s=1.0)
    rig.world.attach(chamber)
    t0_c = rig.world.temperature_c
    rig.script()
    assert rig.world.blocks_fused == 0
    assert rig.world.temperature_c > t0_c + 5.0
