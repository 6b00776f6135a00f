"""Load (on a fresh checkout: compile) the simulators' compiled kernels before a station serves.

numba loads a cached kernel at its first call in a process (about 0.05 s each, 0.4-0.5 s for all)
and compiles it when no cache exists yet (a fresh checkout: 10-30 s).  Called from inside a run,
that happens in the thread that advances the world, with the world lock held: in real-time mode
the link checks' replies then miss their wall-clock timeouts and a first run after a checkout can
end with a lost link.  So a simulated station calls `warm_kernels()` before it serves: a throwaway
world with every simulated device, driven through the per-block and the fused paths for a few
simulated seconds, and a few stream frames parsed, which calls every kernel with the argument
types a run uses.  Its random generators are its own: no run's draws change."""

from __future__ import annotations

import threading
from typing import Any

_lock = threading.Lock()
_done = False


def warm_kernels() -> None:
    """Once per process: call every compiled kernel of the simulated devices and the stream parser."""
    global _done
    with _lock:
        if _done:
            return
        from drivers.fpga import protocol as p

        from .physics.noise import NOISE_PRESETS
        from .physics.params import preset
        from .world import World

        for world in (World(preset("hrg-wa"), seed=0, noise=NOISE_PRESETS["hrg-wa"], earth_rate_dph=10.0),
                      World(preset("hrg"), seed=0)):  # with and without the noise model's inputs
            frames = _drive(world)
        p.FrameParser().feed(b"".join(frames[-4:]))
        _done = True


def _drive(world: Any) -> list[bytes]:
    """Every simulated device on `world`, driven through both paths; the stream frames it sent."""
    from drivers.fpga import protocol as p
    from drivers.rate_table import modbus_protocol as mp

    from .faults import FaultScheduler
    from .fpga.firmware import FpgaFirmware
    from .frontend.model import FrontEndModel
    from .rate_table.mechanics import TableMechanics

    frames: list[bytes] = []
    fw = FpgaFirmware(world)
    fw.sink = lambda data, n: frames.append(data)
    table = TableMechanics(seed=0, watchdog_s=0.0)
    fe = FrontEndModel(seed=0)
    for dev in (FaultScheduler(lambda kind: None), table, fe, fw):
        world.attach(dev)
    with world.lock:
        for name, value in (("REF_FREQ_HZ", world.params.f0_hz), ("AGC_SETPOINT", 1.0), ("STREAM_DECIMATION", 10)):
            fw.write(p.register(name), value)
        fw.write(p.register("CTRL"), p.DRIVE_EN | p.AGC_EN | p.PLL_EN | p.QUAD_EN | p.WHOLE_ANGLE | p.STREAM_EN)
    world.advance(1.0)  # per-block first blocks, then fused runs
    with world.lock:
        table.set_enabled(True)
        table.command(mp.MODE_RATE, 10.0, 0.0, 1000.0)  # a ramp (per block), then at rate (fused)
    world.advance(1.0)
    with world.lock:
        fw.write(p.register("TRIM_EN"), p.TRIM_GAIN)
        fw.write(p.register("TRIM_GAIN_X"), 1.01)
        fw.write(p.register("STREAM_DECIMATION"), 1)
    world.advance(0.4)
    return frames
