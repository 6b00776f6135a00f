"""Load (on a fresh checkout: compile) the simulators' compiled kernels before a station serves.

numba loads a cached kernel at its first call in a process (about 0.05 s each, 0.4-0.5 s for all)
and compiles it when no cache exists yet (a fresh checkout: 10-30 s).  Called from inside a run,
that happens in the thread that advances the world, with the world lock held: in real-time mode
the link checks' replies then miss their wall-clock timeouts and a first run after a checkout can
end with a lost link.  So a simulated station calls `warm_kernels()` before it serves: a throwaway
world with every simulated device, driven through the per-block and the fused paths for a few
simulated seconds, and a few stream frames parsed, which calls every kernel with the argument
types a run uses.  Its random generators are its own: no run's draws change.

On a cache that does not hold this source's kernels yet (bench.kernel_cache keys it on their
sources), a line on stderr says so at once and one more names each kernel as numba starts it, so a
first run is never a minute of nothing on screen; `make install` fills the cache ahead
(`python -m simulators.warm`).  The damping fit's model kernel and the kernels only some units call
(warm_unit_kernels) are compiled here too, on a cold cache only: a run loads them (~0.05 s) where it uses them."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

_lock = threading.Lock()
_done = False
#: the modules whose kernels are named as they compile
_KERNEL_MODULES = ("simulators.", "drivers.fpga.protocol", "bench.analysis.free_decay_rk")


def warm_kernels(*, verbose: bool | None = None, on_compile: Callable[[str], None] | None = None) -> None:
    """Once per process: call every compiled kernel of the simulated devices and the stream parser.
    verbose: lines on stderr while compiling (default: only when the cache is not filled yet);
    on_compile: called with each kernel's name as it starts compiling (the window's splash)."""
    global _done
    with _lock:
        if _done:
            return
        from bench import kernel_cache

        cold = not kernel_cache.is_filled()
        if verbose if verbose is not None else cold:
            print(f"gyrobench: compiling the simulated devices' kernels (once per change of their source; "
                  f"cached in {kernel_cache.cache_dir()}) ...", file=sys.stderr, flush=True)
        with _named_compiles(verbose if verbose is not None else cold, on_compile):
            _warm_devices()
            if cold:  # compiled once, for the run's analysis process to load from the same cache; a filled
                warm_analysis()  # cache holds it already, and this process never calls it (~0.03 s, issue 36)
                warm_unit_kernels()  # likewise the kernels only some units call (MEMS, realistic, thermal)
        if cold:
            kernel_cache.mark_filled()
        _done = True


def _warm_devices() -> None:
    from drivers.fpga import protocol as p

    from .physics.noise import NOISE_PRESETS
    from .physics.params import preset
    from .world import World

    for world in (World(preset("hrg-wa"), seed=0, noise=NOISE_PRESETS["hrg-wa"], earth_rate_dph=10.0),
                  World(preset("hrg"), seed=0)):  # with and without the noise model's inputs
        frames = _drive(world)
    p.FrameParser().feed(b"".join(frames[-4:]))


@contextmanager
def _named_compiles(on: bool, on_compile: Callable[[str], None] | None = None) -> Iterator[None]:
    """While on: a line on stderr as each of our kernels starts compiling (not the ones it inlines);
    `on_compile(name)` too, when given (also when not on)."""
    if not on and on_compile is None:
        yield
        return
    from numba.core import event

    t0, depth = time.perf_counter(), [0]

    class _Named(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            depth[0] += 1
            fn = ev.data["dispatcher"].py_func
            if depth[0] == 1 and fn.__module__.startswith(_KERNEL_MODULES):
                if on:
                    print(f"  {time.perf_counter() - t0:5.1f} s  compiling {fn.__module__}.{fn.__qualname__}",
                          file=sys.stderr, flush=True)
                if on_compile is not None:
                    on_compile(f"{fn.__module__}.{fn.__qualname__}")

        def on_end(self, ev: event.Event) -> None:
            depth[0] -= 1

    with event.install_listener("numba:compile", _Named()):
        yield
    if on:
        print(f"  {time.perf_counter() - t0:5.1f} s  kernels ready", file=sys.stderr, flush=True)


def warm_analysis() -> None:
    """Compile (or load) the damping fit's model kernel with the argument types the fit uses."""
    import numpy as np

    from bench.analysis.free_decay_rk import rk4_sensitivities

    rk4_sensitivities(np.zeros((4, 4)), np.zeros((8, 4, 4)), 0.0, 0.0, False, np.ones(4), 3, 0.01, 1, True)


def warm_unit_kernels() -> None:
    """Compile (or load) the kernels only some units call, with a run's types: the nonlinear
    resonator's DOP853 (a MEMS ring's blocks), the pickoff chains' errors (realistic and thermal
    units) and the FPGA's readout phase trim.  A run of such a unit loads them at its first block
    (~0.05 s each from the cache); every other station's process is spared the loads."""
    import numpy as np

    from .fpga.firmware import _turn_back
    from .physics.dop853 import integrate_block
    from .physics.errors import ERROR_PRESETS

    integrate_block(-np.eye(4), np.ones(4), 1.0, 0.1, np.ones(4), 1e-3, 2)
    ERROR_PRESETS["hrg-realistic"].measure(np.zeros((2, 4)), 0.0)
    _turn_back(np.zeros((2, 4)), (1.0, 0.0, 1.0, 0.0))


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


if __name__ == "__main__":  # `make install`: fill the kernel cache so a first `make run` finds it
    warm_kernels(verbose=True)
