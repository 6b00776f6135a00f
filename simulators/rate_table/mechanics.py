"""Rate-table mechanics as a World device: the controller's profile generator, a first-order
rate loop, angle integration, ripple and noise, and the safety behaviour (e-stop, drive fault,
interlock, wall-clock watchdog).  Both table servers (Modbus, ASCII) drive one of these.

Motion model, per sample of dt: the profile velocity `ref` moves toward its goal by at most
accel*dt (goal = commanded rate; in position mode a sqrt(2 a |error|) approach law; 0 when
stopping); the actual rate follows `ref` through a first-order lag of tau_s; the angle integrates
the actual rate (trapezoid).  Trips brake at `brake_decel_dps2`; a watchdog expiry ramps down at
the commanded acceleration, then disables.  The watchdog trips when the host has been silent for
watchdog_s both on the wall clock (its writes: commands and heartbeats, as a real controller
counts them) and in the table's simulated time (any request, reads too): in real time the wall
clause decides, so a bench that stops feeding it stops the table whatever the speed; in lockstep
the world moves only while the bench drives it and reads the table at every grid point, so a
loaded machine that starves the heartbeat thread of wall time cannot trip it
(docs/rate_table_modbus.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from drivers.rate_table import modbus_protocol as mp

from ..physics.normals import NormalBuffer
from .kernels import deviation_rad, deviation_rad_blocks, profile_step

_NO_ANGLES = np.empty(0)


class CommandRejected(Exception):
    """A command the controller refuses; `bad_value` tells a range error from a state refusal."""

    def __init__(self, message: str, *, bad_value: bool) -> None:
        super().__init__(message)
        self.bad_value = bad_value


def wrap180(angle_deg: float) -> float:
    """Angle difference folded into (-180, 180]."""
    a = math.fmod(angle_deg, 360.0)
    if a > 180.0:
        a -= 360.0
    elif a <= -180.0:
        a += 360.0
    return a


class TableMechanics:
    """Single-axis table: attach to a World (`world.attach(mech)`), command it from a server."""

    def __init__(
        self,
        *,
        max_rate_dps: float = 1000.0,
        max_accel_dps2: float = 1000.0,
        brake_decel_dps2: float | None = None,
        tau_s: float = 0.02,
        ripple_deg: tuple[float, float] = (1e-3, 5e-4),
        noise_deg: float = 1e-4,
        noise_tau_s: float = 0.01,
        rate_noise_dps: float = 0.002,
        at_rate_tol_dps: float = 0.05,
        in_position_tol_deg: float = 0.005,
        watchdog_s: float = 2.0,
        accel_block_samples: int = 10,
        seed: int = 0,
        wall_clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.max_rate_dps = float(max_rate_dps)
        self.max_accel_dps2 = float(max_accel_dps2)
        self.brake_decel_dps2 = float(brake_decel_dps2 or max_accel_dps2)
        self.tau_s = float(tau_s)
        self.ripple_deg = (float(ripple_deg[0]), float(ripple_deg[1]))
        self.noise_deg = float(noise_deg)
        self.noise_tau_s = float(noise_tau_s)
        self.rate_noise_dps = float(rate_noise_dps)
        self.at_rate_tol_dps = float(at_rate_tol_dps)
        self.in_position_tol_deg = float(in_position_tol_deg)
        self.watchdog_s = float(watchdog_s)
        self.accel_block_samples = int(accel_block_samples)
        self.wall_clock = wall_clock
        self._rng_noise = np.random.default_rng([seed, 1])
        self._noise_normals = NormalBuffer(self._rng_noise)  # the jitter's draws, in its order
        self._rng_meas = np.random.default_rng([seed, 2])
        # motion state
        self.ref_dps = 0.0  # profile velocity
        self.rate_dps = 0.0  # actual (lagged) rate, without ripple
        self.angle_deg = 0.0  # actual multi-turn angle, without ripple and noise
        self.ref_angle_deg = 0.0  # profile angle (position mode)
        self._noise_state = 0.0  # OU angle jitter, deg
        self._steps_cache: dict[int, np.ndarray] = {}
        self._ou_key: tuple[float, float, float] | None = None
        self._ou = (0.0, 0.0)
        self.t_s = 0.0
        # commands
        self.mode = mp.MODE_STOP
        self.target_rate_dps = 0.0
        self.target_angle_deg = 0.0  # as commanded, [0, 360)
        self._target_unwrapped_deg = 0.0
        self.traverse_dps = 0.0
        self.accel_dps2 = min(100.0, self.max_accel_dps2)
        self.enabled = False
        # safety
        self.estop_pressed = False
        self.estop_latched = False
        self.fault_latched = False
        self.interlock_open = False
        self.watchdog_expired = False
        self.fault_code = mp.FAULT_NONE
        self._last_feed_wall = wall_clock()
        self._last_contact_t_s = 0.0  # simulated time of the host's last request
        self._position_done = False

    # --- commands (servers call these under world.lock) ---------------------------------------
    def feed(self) -> None:
        """Feed the watchdog: a write came (lock-free: float stores)."""
        self._last_feed_wall = self.wall_clock()
        self._last_contact_t_s = self.t_s

    def note_contact(self) -> None:
        """The host asked something: it is alive in simulated time (lock-free: a float store)."""
        self._last_contact_t_s = self.t_s

    @property
    def tripped(self) -> bool:
        return (
            self.estop_pressed
            or self.estop_latched
            or self.fault_latched
            or self.interlock_open
            or (self.watchdog_expired)
        )

    def command(self, mode: int, rate_dps: float, angle_deg: float, accel_dps2: float) -> None:
        """Mode and setpoints in one go (the Modbus command block, the ASCII MODE command)."""
        if mode not in mp.MODES:
            raise CommandRejected(f"mode {mode} is not one of {mp.MODES}", bad_value=True)
        for name, v in (("rate", rate_dps), ("angle", angle_deg), ("accel", accel_dps2)):
            if not math.isfinite(v):
                raise CommandRejected(f"{name}={v!r} is not finite", bad_value=True)
        if abs(rate_dps) > self.max_rate_dps:
            raise CommandRejected(f"rate {rate_dps} deg/s beyond +/-{self.max_rate_dps}", bad_value=True)
        if not 0.0 < accel_dps2 <= self.max_accel_dps2:
            raise CommandRejected(f"accel {accel_dps2} deg/s^2 outside (0, {self.max_accel_dps2}]", bad_value=True)
        if mode == mp.MODE_POSITION and not (0.0 <= angle_deg < 360.0 and rate_dps != 0.0):
            raise CommandRejected(f"position target {angle_deg} outside [0, 360) or zero speed", bad_value=True)
        if mode != mp.MODE_STOP and (not self.enabled or self.tripped):
            raise CommandRejected("motion refused: drive not enabled or tripped", bad_value=False)
        self.feed()
        self.accel_dps2 = float(accel_dps2)
        self.mode = mode
        if mode == mp.MODE_RATE:
            self.target_rate_dps = float(rate_dps)
        elif mode == mp.MODE_POSITION:
            self.target_angle_deg = float(angle_deg)
            self.traverse_dps = abs(float(rate_dps))
            self.ref_angle_deg = self.angle_deg
            self._target_unwrapped_deg = self.ref_angle_deg + wrap180(angle_deg - self.ref_angle_deg)
            self._position_done = False
        else:
            self.target_rate_dps = 0.0

    def set_enabled(self, on: bool) -> None:
        if on:
            if self.tripped:
                raise CommandRejected("enable refused: e-stop, fault, interlock or watchdog active", bad_value=False)
            if not self.enabled:
                self.mode = mp.MODE_STOP
                self.target_rate_dps = 0.0
            self.enabled = True
            self.feed()
        else:
            self.enabled = False
            self.mode = mp.MODE_STOP

    def fault_reset(self) -> None:
        """Clear latches whose cause is gone (a pressed e-stop stays latched)."""
        if not self.estop_pressed:
            self.estop_latched = False
        self.fault_latched = False
        self.watchdog_expired = False
        if not self.tripped:
            self.fault_code = mp.FAULT_NONE
        self.feed()

    def set_watchdog_s(self, watchdog_s: float) -> None:
        if not (math.isfinite(watchdog_s) and watchdog_s >= 0):
            raise CommandRejected(f"watchdog {watchdog_s} s must be >= 0", bad_value=True)
        self.watchdog_s = float(watchdog_s)
        self.feed()

    # --- fault injection ---------------------------------------------------------------------
    def inject(self, kind: str, code: int | None = None) -> None:
        """kind: "estop" (button pressed), "fault" (drive fault latched), "interlock" (door open)."""
        if kind == "estop":
            self.estop_pressed = self.estop_latched = True
            self._trip(mp.FAULT_ESTOP)
        elif kind == "fault":
            self.fault_latched = True
            self._trip(mp.FAULT_DRIVE if code is None else int(code))
        elif kind == "interlock":
            self.interlock_open = True
            self._trip(mp.FAULT_INTERLOCK)
        else:
            raise ValueError(f"inject kind={kind!r}: expected 'estop', 'fault' or 'interlock'")

    def clear(self, kind: str) -> None:
        """Release the e-stop button or close the interlock (latches stay until fault_reset)."""
        if kind == "estop":
            self.estop_pressed = False
        elif kind == "interlock":
            self.interlock_open = False
        elif kind != "fault":
            raise ValueError(f"clear kind={kind!r}: expected 'estop', 'fault' or 'interlock'")

    def _trip(self, code: int) -> None:
        if self.fault_code == mp.FAULT_NONE:
            self.fault_code = code
        self.enabled = False
        self.mode = mp.MODE_STOP

    def check_watchdog(self) -> None:
        """Latch a watchdog expiry while the drive is enabled: the host silent for watchdog_s on
        the wall clock (no write) and in simulated time (no request)."""
        if (
            self.enabled
            and self.watchdog_s > 0
            and not self.watchdog_expired
            and self.t_s - self._last_contact_t_s > self.watchdog_s
            and self.wall_clock() - self._last_feed_wall > self.watchdog_s
        ):
            self.watchdog_expired = True
            if self.fault_code == mp.FAULT_NONE:
                self.fault_code = mp.FAULT_WATCHDOG
            self.mode = mp.MODE_STOP  # controlled ramp-down; disabled once at rest

    # --- status ---------------------------------------------------------------------------------
    def ripple_angle_deg(self, angle_deg: np.ndarray | float) -> np.ndarray | float:
        """Periodic angle error of the drive: once and twice per revolution."""
        th = np.radians(angle_deg)
        return self.ripple_deg[0] * np.sin(th) + self.ripple_deg[1] * np.sin(2.0 * th)

    def status(self) -> tuple[float, float, int, int]:
        """(rate_dps, angle_deg in [0, 360), status bits, fault code) as the controller reports
        them; the request is a sign of life in simulated time (check_watchdog)."""
        self.check_watchdog()
        self.note_contact()
        th = math.radians(self.angle_deg)
        ripple_rate = (self.ripple_deg[0] * math.cos(th) + 2.0 * self.ripple_deg[1] * math.cos(2.0 * th)) * (
            math.radians(self.rate_dps)
        )
        rate = self.rate_dps + ripple_rate + self.rate_noise_dps * float(self._rng_meas.standard_normal())
        angle = (self.angle_deg + float(self.ripple_angle_deg(self.angle_deg)) + self._noise_state) % 360.0
        bits = 0
        if self.enabled:
            bits |= mp.ST_ENABLED
        if self.at_rate:
            bits |= mp.ST_AT_RATE
        if self.in_position:
            bits |= mp.ST_IN_POSITION
        if self.fault_latched:
            bits |= mp.ST_FAULT
        if self.estop_pressed or self.estop_latched:
            bits |= mp.ST_ESTOP
        if self.interlock_open:
            bits |= mp.ST_INTERLOCK_OPEN
        if self.watchdog_expired:
            bits |= mp.ST_WATCHDOG_EXPIRED
        if abs(self.rate_dps) > 1e-6 or self.ref_dps != 0.0:
            bits |= mp.ST_MOVING
        return rate, angle, bits, self.fault_code

    @property
    def at_rate(self) -> bool:
        return (
            self.enabled
            and self.mode == mp.MODE_RATE
            and self.ref_dps == self.target_rate_dps
            and abs(self.rate_dps - self.target_rate_dps) <= self.at_rate_tol_dps
        )

    @property
    def in_position(self) -> bool:
        return (
            self.enabled
            and self.mode == mp.MODE_POSITION
            and self._position_done
            and abs(wrap180(self.target_angle_deg - self.angle_deg)) <= self.in_position_tol_deg
            and abs(self.rate_dps) <= self.at_rate_tol_dps
        )

    # --- motion -------------------------------------------------------------------------------
    def _goal(self, dt_s: float) -> tuple[float, float]:
        """(goal velocity, acceleration used) of the profile for the next sample."""
        if self.estop_pressed or self.estop_latched or self.fault_latched or self.interlock_open or not self.enabled:
            return 0.0, self.brake_decel_dps2
        if self.mode == mp.MODE_RATE:
            return self.target_rate_dps, self.accel_dps2
        if self.mode == mp.MODE_POSITION and not self._position_done:
            a = self.accel_dps2
            err = self._target_unwrapped_deg - self.ref_angle_deg
            v = min(self.traverse_dps, math.sqrt(2.0 * a * abs(err)), abs(err) / dt_s)
            return math.copysign(v, err), a
        return 0.0, self.accel_dps2

    def settled(self) -> bool:
        """True when the profile and the lag are at rest on their goal (big blocks are exact)."""
        if self.mode == mp.MODE_POSITION and self.enabled and not self._position_done:
            return False
        goal, _ = self._goal(1.0)
        return self.ref_dps == goal and self.rate_dps == goal

    def _step(self, n: int, dt_s: float) -> np.ndarray:
        """Advance n samples; return the smooth angle at each sample end (n,)."""
        if self.settled():
            angles = self.angle_deg + self.rate_dps * dt_s * self._steps(n)
            self.angle_deg = float(angles[-1])
            self.ref_angle_deg += self.ref_dps * dt_s * n
            return angles
        alpha = 1.0 - math.exp(-dt_s / self.tau_s)
        angles = np.empty(n)
        state = np.array([self.ref_dps, self.ref_angle_deg, self.rate_dps, self.angle_deg,
                          float(self._position_done), float(self.enabled)])  # fmt: skip
        halted = self.estop_pressed or self.estop_latched or self.fault_latched or self.interlock_open
        profile_step(state, n, dt_s, alpha, halted, int(self.mode), float(self.target_rate_dps),
                     float(self.accel_dps2), float(self.brake_decel_dps2), float(self.traverse_dps),
                     float(self._target_unwrapped_deg), self.watchdog_expired, angles)  # fmt: skip
        self.ref_dps, self.ref_angle_deg, self.rate_dps, self.angle_deg = (float(v) for v in state[:4])
        self._position_done, self.enabled = bool(state[4]), bool(state[5])
        return angles

    # --- World device ---------------------------------------------------------------------------
    def max_block_samples(self, world) -> int | None:
        self.check_watchdog()
        return None if self.settled() else self.accel_block_samples

    def _steps(self, n: int) -> np.ndarray:
        """1.0 .. n, cached per block size (never written to)."""
        steps = self._steps_cache.get(n)
        if steps is None:
            steps = np.arange(1, n + 1, dtype=float)
            self._steps_cache = {n: steps} if len(self._steps_cache) > 16 else {**self._steps_cache, n: steps}
        return steps

    def _ou_step(self, dt_s: float) -> tuple[float, float]:
        """The jitter's OU step over dt_s: (decay, innovation scale), worked out once per dt."""
        key = (dt_s, self.noise_tau_s, self.noise_deg)
        if self._ou_key != key:
            e = math.exp(-dt_s / self.noise_tau_s)
            self._ou_key, self._ou = key, (e, self.noise_deg * math.sqrt(1.0 - e * e))
        return self._ou

    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        """Move the table over the block; hand the world its mean rate and the in-block angle
        deviation (profile curvature, ripple, jitter) as `ripple_angle_rad` (compiled kernel)."""
        self.check_watchdog()
        a0 = self.angle_deg
        settled = self.settled()
        if settled:  # constant rate: the angles are a0 + rate dt k, made in the kernel
            rate_step = self.rate_dps * dt_s
            a_end = a0 + rate_step * float(n)
            angles = _NO_ANGLES
            self.angle_deg = a_end
            self.ref_angle_deg += self.ref_dps * dt_s * n
        else:
            rate_step = 0.0
            angles = self._step(n, dt_s)
            a_end = float(angles[-1])
        # rounded to 1 ndeg/s so a table at rate gives the resonator the same rate every block
        # (its exact step is cached on the inputs); the rounding goes into the deviation below
        mean_rate = round((a_end - a0) / (n * dt_s), 9)
        if self.noise_deg > 0:
            e, scale = self._ou_step(dt_s)
            w = self._noise_normals.take(n)  # standard normals: the kernel scales them
            y_prev = e * self._noise_state
        else:
            e, scale, w, y_prev = 0.0, 1.0, _NO_ANGLES, 0.0
        dev = np.empty(n)
        r1, r2 = self.ripple_deg
        y = deviation_rad(angles, settled, a0, rate_step, mean_rate, dt_s, r1, r2, w, e, y_prev, dev, scale)
        if self.noise_deg > 0:
            self._noise_state = y
        world.case_rate_dps = float(mean_rate)
        world.ripple_angle_rad = dev
        self.t_s = t_s + n * dt_s

    def fused_before_blocks(self, i0: int, k: int, n: int, dt_s: float) -> tuple[list[float], np.ndarray] | None:
        """`before_block` for k blocks of n samples from sample i0 at once, for the world's fused
        path (simulators.fused): each block's mean rate (deg/s) and in-block deviation (k, n) rad,
        the same values and draws as k calls; None (nothing changed) unless the table is settled."""
        self.check_watchdog()
        if not self.settled():
            return None
        rate_step = self.rate_dps * dt_s
        if self.rate_dps == 0.0 and self.ref_dps == 0.0:  # at rest: the angle stays, every mean rate is 0
            a0s, rates = np.full(k, self.angle_deg), [0.0] * k
        else:
            a0s, rates = np.empty(k), []
            for j in range(k):
                a0 = self.angle_deg
                a_end = a0 + rate_step * float(n)
                self.angle_deg = a_end
                self.ref_angle_deg += self.ref_dps * dt_s * n
                a0s[j] = a0
                rates.append(round((a_end - a0) / (n * dt_s), 9))
        if self.noise_deg > 0:
            e, scale = self._ou_step(dt_s)
            w = self._noise_normals.take(n * k)
        else:
            e, scale, w = 0.0, 1.0, _NO_ANGLES
        dev = np.empty((k, n))
        r1, r2 = self.ripple_deg
        y = deviation_rad_blocks(a0s, rate_step, np.array(rates), dt_s, r1, r2, w, e, self._noise_state, dev, scale)
        if self.noise_deg > 0:
            self._noise_state = y
        self.t_s = (i0 + (k - 1) * n) * dt_s + n * dt_s
        return rates, dev

    def after_block(self, world, block) -> None:
        pass

    def advance_alone(self, n: int, dt_s: float) -> None:
        """Move n samples without a World: an axis of a multi-axis controller that carries no
        gyro, caught up by its server when asked (nothing reads its in-block angles)."""
        while n > 0:
            if self.settled():
                self.angle_deg += self.rate_dps * dt_s * n
                self.ref_angle_deg += self.ref_dps * dt_s * n
                break
            k = min(n, 4096)
            self._step(k, dt_s)
            n -= k
