"""The simulated world: one resonator shared by every simulated device, advanced in virtual time.

Devices attach to the World and take part in every block of the advance:
  * `max_block_samples(world)` (optional): the largest block the device tolerates now (a table
    that is accelerating asks for one-sample blocks; loops ask for their control period);
  * `before_block(world, t_s, n, dt_s)`: set the inputs held over the block (case rate and
    ripple, forcing per source, reference frequency);
  * `after_block(world, block)`: consume the samples (the FPGA demodulates and streams them).
All of it runs under `world.lock`, so device servers in other threads read a consistent state.
Time is quantised to the sample grid: `t_s = sample_index * sample_period_s` exactly.
"""

from __future__ import annotations

import math
import threading
from typing import Any, Protocol

import numpy as np

from .physics.averaged import Resonator, use_single_thread_blas
from .physics.errors import REFERENCE_TEMPERATURE_C, ErrorSources
from .physics.noise import Environment, NoiseParams
from .physics.params import ResonatorParams
from .world_block import WorldBlock

#: the force source whose coming on is a turn-on of the gyro (the FPGA firmware's drive)
TURN_ON_SOURCE = "fpga"


_fused: Any = None  # simulators.fused, imported at the first advance that may use it


def _fused_module() -> Any:
    """simulators.fused (imported once, not per block: an import statement in the block loop went
    through the import machinery, and PySide's import hook, every time)."""
    global _fused
    if _fused is None:
        from . import fused

        _fused = fused
    return _fused


class WorldDevice(Protocol):
    """What a simulated device implements to take part in the world's advance."""

    def before_block(self, world: World, t_s: float, n: int, dt_s: float) -> None: ...

    def after_block(self, world: World, block: WorldBlock) -> None: ...


class World:
    """Owns the resonator and the simulated devices; `advance(dt)` moves virtual time."""

    def __init__(
        self,
        params: ResonatorParams | Resonator,
        *,
        seed: int = 0,
        sample_period_s: float = 1e-3,
        max_block_s: float = 0.1,
        noise: NoiseParams | None = None,
        earth_rate_dph: float = 0.0,
        lock: threading.RLock | None = None,
        errors: ErrorSources | None = None,
        temperature_c: float = REFERENCE_TEMPERATURE_C,
    ) -> None:
        if not (math.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s={sample_period_s!r} must be > 0")
        use_single_thread_blas()
        self.resonator = params if isinstance(params, Resonator) else Resonator(params, seed=seed)
        self.params = self.resonator.params
        self.seed = seed
        self.sample_period_s = float(sample_period_s)
        self.max_block_samples = max(1, int(round(max_block_s / sample_period_s)))
        self.lock = threading.RLock() if lock is None else lock  # several slot worlds of a rig share one
        #: the world whose table turns this one (simulators.rig: a slot on a shared table), or None
        self.case_source: World | None = None
        self.sample_index = 0
        self._pending_s = 0.0  # sub-sample remainder of requested advances
        self.devices: list[Any] = []  # change with attach / detach
        self._limiters: list[Any] = []  # their max_block_samples methods
        # inputs held over a block, set by devices in before_block
        self.case_rate_dps = 0.0
        self.case_angle_deg = 0.0
        self.ripple_angle_rad: np.ndarray | None = None
        self.ref_freq_hz = self.params.f0_hz
        self._forces: dict[str, np.ndarray] = {}
        self.last_block: WorldBlock | None = None
        self._listeners: list[Any] = []
        self._run_listeners: list[Any] = []
        # noise and environment (simulators.physics.noise): None for a noise-free world, whose
        # arithmetic and random draws are then those of the world before the noise model
        self.environment: Environment | None = None
        if noise is not None or earth_rate_dph != 0.0:
            self.environment = Environment(
                noise, seed=seed, sample_period_s=self.sample_period_s, earth_rate_dph=earth_rate_dph
            )
        #: the unit's error sources (simulators.physics.errors), None when all are off: the world then
        #: computes what it did before they existed (simulators.fused applies them as the per-block path)
        self.errors = errors if errors is not None and errors.active else None
        #: the unit's temperature (deg C): an input, constant unless a chamber (or a test) sets it
        self.temperature_c = float(temperature_c)
        #: the package's stress state (deg C) behind the temperature's play (thermal hysteresis,
        #: ErrorSources.stress_after); at the temperature to begin with: the unit starts on no branch
        self.stress_c = self.temperature_c
        self._advance_listeners: list[Any] = []
        #: runs of steady blocks take the compiled path (simulators.fused; the same numbers either way)
        self.fused = True
        self.blocks_fused = 0  # blocks advanced that way (diagnostics, tests)
        self._fused_parts: Any = None

    # --- time ------------------------------------------------------------------------------
    @property
    def t_s(self) -> float:
        return self.sample_index * self.sample_period_s

    def attach(self, device: Any) -> None:
        with self.lock:
            self.devices.append(device)
            self._update_limiters()

    def detach(self, device: Any) -> None:
        with self.lock:
            if device in self.devices:
                self.devices.remove(device)
            self._update_limiters()

    def _update_limiters(self) -> None:
        fns = (getattr(dev, "max_block_samples", None) for dev in self.devices)
        self._limiters = [fn for fn in fns if fn is not None]

    def add_listener(self, callback: Any, *, each_block: bool = True) -> None:
        """callback(world) after every block; with each_block=False, after a run of fused blocks
        only (simulators.fused): enough for a clock whose waits need to know the world moved."""
        (self._listeners if each_block else self._run_listeners).append(callback)

    def add_advance_listener(self, callback: Any) -> None:
        """callback(world) at the end of every `advance` (under the world lock): a simulated link
        sends what the blocks of one advance produced in one write, not one per block."""
        self._advance_listeners.append(callback)

    def remove_advance_listener(self, callback: Any) -> None:
        with self.lock:
            if callback in self._advance_listeners:
                self._advance_listeners.remove(callback)

    # --- inputs ----------------------------------------------------------------------------
    def set_force(self, source: str, force: np.ndarray | None) -> None:
        """Forcing u (model units, 1/s x amplitude) applied by one source; None removes it."""
        with self.lock:
            if force is None:
                self._forces.pop(source, None)
            else:
                held = self._forces.get(source)
                if held is not None:  # the world's own copy, refreshed in place (a block's hot path)
                    held[:] = np.asarray(force, dtype=float).reshape(4)
                    return
                if source == TURN_ON_SOURCE and self.environment is not None:
                    self.environment.turn_on()  # the drive comes on: a new turn-on bias
                self._forces[source] = np.array(force, dtype=float).reshape(4)  # a copy: the caller may reuse its array

    @property
    def total_force(self) -> np.ndarray:
        total = np.zeros(4)
        for f in self._forces.values():
            total = total + f
        return total

    # --- advance ---------------------------------------------------------------------------
    def advance(self, dt_s: float) -> int:
        """Advance by dt_s of virtual time (rounded to whole samples, remainder carried over).
        Returns the number of samples produced."""
        if not math.isfinite(dt_s) or dt_s < 0:
            raise ValueError(f"advance dt_s={dt_s!r} must be finite and >= 0")
        with self.lock:
            self._pending_s += dt_s
            n_total = int(math.floor(self._pending_s / self.sample_period_s + 1e-9))
            self._pending_s = max(0.0, self._pending_s - n_total * self.sample_period_s)
            done = 0
            fused = _fused_module() if self.fused else None
            while done < n_total:
                left = n_total - done
                n = min(left, self._block_limit())
                if fused is not None and left >= 2 * n:  # a run of steady blocks: one compiled call
                    k = min(left // n, fused.MAX_FUSED_BLOCKS)
                    if fused.fused_blocks_possible(self, n, k) and fused.run_fused_blocks(self, n, k):
                        done += k * n
                        continue
                self._run_block(n)
                done += n
            for cb in self._advance_listeners:
                cb(self)
            return n_total

    def advance_samples(self, n_samples: int) -> None:
        self.advance(n_samples * self.sample_period_s)

    def _block_limit(self) -> int:
        limit = self.max_block_samples
        for fn in self._limiters:
            m = fn(self)
            if m is not None:
                limit = min(limit, max(1, int(m)))
        return limit

    def _run_block(self, n: int) -> None:
        dt = self.sample_period_s
        i0 = self.sample_index
        t0 = i0 * dt
        self.ripple_angle_rad = None
        for dev in self.devices:
            dev.before_block(self, t0, n, dt)
        src = self.case_source
        if src is not None:  # a slot on a shared table: the table's world has run this block already
            self.case_rate_dps, self.ripple_angle_rad = src.case_rate_dps, src.ripple_angle_rad
        rate = self.case_rate_dps
        forces = self._forces
        if len(forces) == 1:
            force = next(iter(forces.values()))
        else:
            force = self.total_force
        rate_rad_s = math.radians(rate)
        errs = self.errors
        if errs is not None:  # the forcers' gains and angles; f0 and Q at the temperature
            force = errs.force(force)
            if errs.thermal_active:
                c = self.resonator.coeffs
                self.resonator.set_thermal(*errs.thermal(c.gamma, c.c_m, self.params.f0_hz, self.temperature_c))
            rate_rad_s += math.radians(errs.thermal_bias_dps(self.temperature_c, self.stress_c))  # 0 at the reference
        env = self.environment
        gains = None
        if env is not None:
            rate_rad_s += env.block_rate_rad_s(n)  # Earth, turn-on bias and drift noise: an input rate
            if env.has_slow_drifts:
                d, th = env.damping(t0, self.params.delta_inv_tau_per_s, self.params.theta_tau_deg)
                self.resonator.set_damping_anisotropy(d, th)
                gains = env.gains(t0)  # the X pickoff electrodes (cx, sx), the Y ones (cy, sy)
        q_true, q_meas = self.resonator.step_and_measure(
            n,
            dt,
            rate_rad_s=rate_rad_s,
            force=force,
            ref_freq_hz=self.ref_freq_hz,
            ripple_angle_rad=self.ripple_angle_rad,
            gains=gains,
        )
        if errs is not None:  # what the pickoff chains make of the states
            q_meas = errs.measure(q_meas, t0, self.temperature_c, self.stress_c)
        angle0 = self.case_angle_deg
        block = WorldBlock(i0 + 1, q_true, q_meas, rate, angle0, dt, self.ripple_angle_rad)
        self.sample_index = i0 + n
        self.case_angle_deg = angle0 + rate * n * dt
        self.last_block = block
        for dev in self.devices:
            dev.after_block(self, block)
        for cb in self._listeners:
            cb(self)
        for cb in self._run_listeners:
            cb(self)

    # --- truth -----------------------------------------------------------------------------
    def truth(self) -> dict[str, float]:
        """Ground truth for reports and tests; never travels over a device protocol."""
        truth = self.params.truth()
        if self.environment is not None:
            # drive_on: whether the turn-on drive holds its force now (turn_on_bias_dph is then the
            # bias in force; else the next drive-on makes turn_on_bias_next_dph's)
            truth |= self.environment.truth() | {"drive_on": float(TURN_ON_SOURCE in self._forces)}
        if self.errors is not None:
            truth |= self.errors.truth(self.t_s, self.temperature_c, truth, self.stress_c)
        return truth

    def set_temperature(self, temperature_c: float) -> None:
        """The unit's temperature from the next block on (a thermal chamber's input)."""
        if not math.isfinite(temperature_c):
            raise ValueError(f"temperature_c={temperature_c!r} must be finite")
        with self.lock:
            self.temperature_c = float(temperature_c)
            if self.errors is not None and self.errors.hysteretic:
                self.stress_c = self.errors.stress_after(self.stress_c, self.temperature_c)

    def state(self) -> np.ndarray:
        with self.lock:
            return self.resonator.state
