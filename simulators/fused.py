"""The world's fused blocks: a run of steady loop periods advanced in one compiled call.

A long lockstep record (a static whole-angle record, a free decay, a table at constant rate)
spends most of its time in blocks where nothing but the loops changes: the table is settled, the
front end's drive outputs are off, no fault is due and the FPGA's registers are not written (the
world lock is held).  For such a run `World.advance` hands K blocks to `run_fused_blocks`: the
table's and the environment's inputs for all K at once (they do not depend on the resonator), then
`fused_kernel.closed_loop_blocks` (the firmware's before/after_block around the resonator's exact
step, block by block), then per block in Python what stays there (the stream frames to the link,
the front end's lock-in, the world's listeners).  Every value and every random draw is the one the
per-block path makes, in the same order, so seeded runs are bit-identical either way
(tests/test_world_fused.py, benchmarks/sim_identical.py).  A unit's error sources (World.errors)
ride along: each block's temperature (a thermal chamber stepped block by block, as its before_block
does), its bias, gamma and c_m, and the pickoff chains' gains are worked out in Python first; the
forcers' and pickoff chains' errors are applied in the compiled loop.  Anything else (a rig's
shared chamber, the readout phase trim, FM, a fault due) takes the per-block path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from drivers.fpga import protocol as p

from .chamber.thermal import ChamberThermal
from .faults import FaultScheduler
from .fpga.firmware import FpgaFirmware
from .frontend.model import FrontEndModel
from .fused_kernel import closed_loop_blocks
from .physics.averaged import damping_terms
from .rate_table.mechanics import TableMechanics
from .world_block import WorldBlock

#: the World (simulators.world) a fused run advances: typed Any here, as the world imports this
#: module and this module never imports the world
World = Any

#: at most this many blocks in one fused call (a lockstep grid step is 8 loop periods)
MAX_FUSED_BLOCKS = 64
_NONE = np.empty(0)  # an absent per-block input or gain trim


class _Parts:
    """The devices of a world the fused path knows, found once per device list."""

    __slots__ = ("devices", "table", "frontend", "firmware", "chamber", "faults", "ok")

    def __init__(self, devices: list[Any]) -> None:
        self.devices = list(devices)
        self.table: TableMechanics | None = None
        self.frontend: FrontEndModel | None = None
        self.firmware: FpgaFirmware | None = None
        self.chamber: ChamberThermal | None = None
        self.faults: list[FaultScheduler] = []
        kinds = {TableMechanics: "table", FrontEndModel: "frontend", FpgaFirmware: "firmware",
                 ChamberThermal: "chamber"}  # fmt: skip
        self.ok = True
        for dev in devices:
            if type(dev) is FaultScheduler:
                self.faults.append(dev)
                continue
            slot = kinds.get(type(dev))
            if slot is None or getattr(self, slot) is not None:  # an unknown device, or two of a kind
                self.ok = False
                return
            setattr(self, slot, dev)
        self.ok = self.firmware is not None and self.table is not None


def _parts(world: World) -> _Parts:
    parts = world._fused_parts
    if parts is None or parts.devices != world.devices:
        parts = world._fused_parts = _Parts(world.devices)
    return parts


def fused_blocks_possible(world: World, n: int, k: int) -> bool:
    """True when the next k blocks of n samples may take the fused path (module docstring)."""
    parts = _parts(world)
    if not parts.ok or world.case_source is not None:
        return False
    ch = parts.chamber
    if ch is not None and any(unit is not world for unit in ch.units):  # a rig's chamber: per block
        return False
    if ch is not None and world.errors is None:  # the chamber is stepped with the error sources' inputs only
        return False
    res = world.resonator
    if not res._linear:
        return False
    t_end = (world.sample_index + k * n) * world.sample_period_s
    for sched in parts.faults:
        if sched.pending and sched.pending[0][0] <= t_end + 1e-9:
            return False
    fe = parts.frontend
    if fe is not None and (fe.capture is not None or fe.reference_hz() is not None):
        return False
    with parts.firmware.lock:
        return _firmware_steady(world, parts.firmware)


def _firmware_steady(world: World, fw: FpgaFirmware) -> bool:
    """The firmware's part of the check (under its lock: the FPGA server writes registers from its
    own thread, holding only that lock)."""
    ctrl, _, _, fm_on, _ = fw._hot_now()
    if fm_on or fw._phase_rot is not None:  # the readout phase trim runs in the per-block path only
        return False
    forces = world._forces
    if ctrl & p.DRIVE_EN:  # the drive on and already applied: its force is refreshed in place
        return fw._u_on and len(forces) == 1 and "fpga" in forces
    return not fw._u_on and not forces  # the drive off and cut: no force at all


def _error_inputs(
    world: World, chamber: ChamberThermal | None, errs: Any, n: int, k: int, rate_rad_s: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Each block's input rate with the temperature's bias, gamma and c_m at the temperature (or
    (0,) when f0 and Q do not move) and the pickoff chains' gains: World._run_block's values, the
    chamber stepped (and the unit's temperature set) before each block as its before_block does."""
    dt = world.sample_period_s
    i0 = world.sample_index
    thermal = errs.thermal_active
    c = world.resonator.coeffs
    f0_hz = world.params.f0_hz
    bias = np.empty(k)
    zg0, zg4 = (np.empty(k), np.empty(k)) if thermal else (_NONE, _NONE)
    pick_gx, pick_gy = np.empty(k), np.empty(k)
    for j in range(k):
        if chamber is not None:
            chamber.step(n * dt)
            world.set_temperature(chamber.resonator_c)
        temp_c, stress_c = world.temperature_c, world.stress_c
        if thermal:
            zg0[j], zg4[j] = errs.thermal(c.gamma, c.c_m, f0_hz, temp_c)
        bias[j] = math.radians(errs.thermal_bias_dps(temp_c, stress_c))
        pick_gx[j], pick_gy[j] = errs.pickoff_gains((i0 + j * n) * dt, temp_c, stress_c)
    return rate_rad_s + bias, zg0, zg4, pick_gx, pick_gy


def run_fused_blocks(world: World, n: int, k: int) -> bool:
    """Advance the world by k blocks of n samples (`fused_blocks_possible` said so); False (and
    nothing done) if the table turned out not settled or a register was written since the check."""
    parts = world._fused_parts
    assert parts is not None
    table, fe, fw = parts.table, parts.frontend, parts.firmware
    assert table is not None and fw is not None
    dt = world.sample_period_s
    i0 = world.sample_index
    with fw.lock:
        if not _firmware_steady(world, fw):  # a register written since the check (real-time mode)
            return False
        inputs = table.fused_before_blocks(i0, k, n, dt)
        if inputs is None:
            return False
        mean_rates, ripple = inputs
        rate_rad_s = np.array([math.radians(r) for r in mean_rates])
        res = world.resonator
        errs = world.errors
        zg0 = zg4 = pick_gx = pick_gy = forcer = pickoff = _NONE
        if errs is not None:  # World._run_block's error sources at each block's temperature
            rate_rad_s, zg0, zg4, pick_gx, pick_gy = _error_inputs(world, parts.chamber, errs, n, k, rate_rad_s)
            forcer = np.array(errs._forcer_constants, dtype=float)
            pickoff = np.array(errs._pickoff_constants, dtype=float)
        env = world.environment
        slow = env is not None and env.has_slow_drifts
        zg2 = zg3 = gain_x = gain_y = _NONE
        if env is not None:
            rate_rad_s = rate_rad_s + env.block_rates_rad_s(n, k)
            if slow:  # World._run_block's damping and gains at each block's start
                zg2, zg3, gain_x, gain_y = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
                d0, th0 = world.params.delta_inv_tau_per_s, world.params.theta_tau_deg
                for j in range(k):
                    t0 = (i0 + j * n) * dt
                    zg2[j], zg3[j] = damping_terms(*env.damping(t0, d0, th0))
                    gain_x[j], gain_y[j] = env.gains(t0)
        sigma = res._sigma
        q_meas = res._normals.take(4 * n * k).reshape(n * k, 4) if sigma != 0.0 else np.empty((n * k, 4))
        q_true = np.empty((n * k, 4))
        regs = fw.regs
        prm = fw._params()
        ctrl, gains, _, _, dec = fw._hot
        drive = bool(ctrl & p.DRIVE_EN)
        active = bool(ctrl & (p.DRIVE_EN | p.PLL_EN))
        stream = bool(ctrl & p.STREAM_EN)
        frames = fw._fused_frames(k * (n if dec <= 1 else n // dec + 2))
        frame_counts = np.zeros(k, np.int64)
        ref_hz = np.empty(k)
        force = np.zeros(4)
        pll, fw._dec_n, seq_end = closed_loop_blocks(
            n, i0, dt, rate_rad_s, ripple, res._zg, res._four_k, res._nu_offset, res._w0, res._q,
            res._psi_per_rad, sigma, slow, zg2, zg3, gain_x, gain_y,
            errs is not None, zg0, zg4, forcer, pickoff, pick_gx, pick_gy, q_true, q_meas,
            drive, active or fw._owns_ref, float(world.ref_freq_hz), float(regs["PLL_FREQ_HZ"]),
            float(regs["REF_FREQ_HZ"]), active, stream, ctrl, prm, fw._st,
            _NONE if gains is None else gains, dec, fw._dec_sum, fw._dec_n, fw._stream_seq, frames,
            p.STREAM_CRC_TABLE, p.STREAM_CRC_ZEROS, frame_counts, ref_hz, force,
        )  # fmt: skip
        res._psi = float(res._psi_per_rad * ripple[-1, -1])
        if zg0.shape[0]:
            res.set_thermal(float(zg0[-1]), float(zg4[-1]))  # the last block's, as set_thermal left it
        if active:
            regs["PLL_FREQ_HZ"] = float(pll)
        fw._owns_ref = active
        if drive:
            world._forces["fpga"][:] = force  # the last block's, held as set_force holds it
        regs["SAMPLE_INDEX"] = i0 + k * n
        # what stays in Python: the front end's lock-in, the frames to the link, the listeners
        if fe is not None:
            fe.fused_after_blocks(q_meas, n, dt)
        total = int(frame_counts.sum())
        if total:
            fw._sent_frames(frames[:total], total)  # one write of every block's frames, in order
        angle = world.case_angle_deg
        each_block = world._listeners
        for j in range(k):
            a, rate, angle0 = j * n, mean_rates[j], angle
            angle = angle0 + rate * n * dt
            if each_block or j == k - 1:  # the world as after block j (devices as after the run)
                world.sample_index = i0 + a + n
                world.case_angle_deg = angle
                world.case_rate_dps = float(rate)
                world.ripple_angle_rad = ripple[j]
                world.ref_freq_hz = float(ref_hz[j])
                world.last_block = WorldBlock(i0 + a + 1, q_true[a : a + n], q_meas[a : a + n], rate, angle0, dt,
                                              ripple[j])  # fmt: skip
                for cb in each_block:
                    cb(world)
        for cb in world._run_listeners:
            cb(world)
        assert fw._stream_seq == seq_end
        world.blocks_fused += k
    return True

