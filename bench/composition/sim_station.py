"""The simulated station: one World + SimClock, each device's simulator served on loopback (the
`serve` its driver's spec names, next to the simulator) and the real drivers pointed at them;
`--fault` kinds injected through simulators.faults.  Part of the composition root
(bench.composition): the one place the engine's station meets the simulators."""

from __future__ import annotations

import math
import threading
from pathlib import Path
from typing import Any

from bench.devices import DRIVERS, StationError
from bench.fault_kinds import check_kind
from bench.station import Station
from bench.station_config import SIM_KEYS, StationConfig, load_config
from simulators.faults import FaultScheduler, stop_simulators
from simulators.faults import inject as inject_fault


class SimStation(Station):
    """A simulated station: one World + SimClock, the simulators on loopback, the real drivers.

    `truth()` gives the true parameters (same names as the measurements); `inject(kind)` and
    `schedule_fault(kind, at_s)` give the `--fault` kinds of FAULTS."""

    def __init__(
        self,
        config: StationConfig | str | Path = "sim-hrg",
        *,
        seed: int | None = None,
        speed: float | None = None,
        preset: str | None = None,
        resonator: Any = None,
    ) -> None:
        if not isinstance(config, StationConfig):
            config = load_config(config)
        if config.simulation is None:
            raise StationError(f"{config.source}: not a simulated station (no [simulation] table)")
        sim = dict(config.simulation)
        # overrides come from the command line or the window, not the file: name the option
        if seed is not None:
            sim["seed"] = SIM_KEYS["seed"].check("", "--seed", seed)
        if speed is not None:
            try:
                sim["speed"] = SIM_KEYS["speed"].check("", "--speed", speed)
            except StationError as exc:
                raise StationError(f"{exc} (allowed: 0 = lockstep, or 0 to 1e6 x real time)") from None
        if preset is not None:
            sim["preset"] = SIM_KEYS["preset"].check("", "preset", preset)
        config = StationConfig(config.source, config.station, sim, config.devices, nominal=config.nominal,
                               calibration=config.calibration)
        from simulators.physics.noise import NOISE_PRESETS, earth_rate_dph
        from simulators.physics.params import preset as make_preset
        from simulators.world import World

        st = config.station
        earth = 0.0
        if sim.get("earth_rate"):
            earth = earth_rate_dph(st.get("latitude_deg", 0.0), st.get("axis_elevation_deg", 90.0),
                                   st.get("axis_azimuth_deg", 0.0))
        # resonator: a drawn unit's ResonatorParams (a simulated production lot) instead of the preset
        params = make_preset(sim["preset"]) if resonator is None else resonator
        from simulators.physics.errors import ERROR_PRESETS

        self.world = World(params, seed=sim["seed"], sample_period_s=sim["sample_period_s"],
                           noise=NOISE_PRESETS.get(sim["preset"]), earth_rate_dph=earth,
                           errors=ERROR_PRESETS.get(sim["preset"]))
        self.handles: dict[str, Any] = {}
        self.addresses: dict[str, dict[str, Any]] = {}
        self.faults = FaultScheduler(self.inject)
        self.world.attach(self.faults)
        self._timers: list[threading.Timer] = []
        super().__init__(config)

    def _make_clock(self) -> Any:
        from bench.clock import SimClock

        speed = self.config.simulation["speed"]
        return SimClock(self.world, speed=math.inf if speed == 0 else speed)

    @property
    def seed(self) -> int:
        return int(self.config.simulation["seed"])

    def start_simulators(self) -> dict[str, dict[str, Any]]:
        """Start each device's simulator on loopback; their addresses by role."""
        from simulators.warm import warm_kernels

        warm_kernels()  # compiled kernels loaded before anything serves (simulators/warm.py says why)
        for role, cfg in self.config.devices.items():
            spec = DRIVERS[cfg["driver"]]
            if spec.serve is None:
                raise StationError(f"{self.config.source}: [devices.{role}] driver {spec.name!r} has no simulator")
            if role not in self.handles:
                self.handles[role], self.addresses[role] = spec.serve_simulator(self.world, cfg)
        return self.addresses

    def open(self) -> SimStation:
        if self.devices:  # already open: the same simulators and drivers
            return self
        try:
            self.start_simulators()
        except Exception:
            self.close()
            raise
        super().open()
        return self

    def _device_cfg(self, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return {**cfg, **self.addresses.get(role, {})}

    def close(self) -> None:
        super().close()
        stop_simulators(self._timers, self.handles)
        self.clock.close()

    def truth(self) -> dict[str, float]:
        """The world's truth and what a simulator adds (the FPGA's output modes' scale factor and bias)."""
        out = self.world.truth()
        for handle in self.handles.values():
            extra = getattr(handle, "truth", None)
            if callable(extra):
                out.update(extra())
        return out

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d["addresses"] = self.addresses
        return d

    # --- faults ----------------------------------------------------------------------------
    def inject(self, kind: str) -> None:
        """Inject a station fault now (one of FAULTS)."""
        inject_fault(self.handles, kind, self._timers)

    def schedule_fault(self, kind: str, at_s: float) -> None:
        """Inject `kind` when the world reaches `at_s` simulated seconds."""
        role = check_kind(kind).role
        if not (math.isfinite(at_s) and at_s >= 0):
            raise StationError(f"fault {kind!r} at {at_s!r} s: the time must be >= 0")
        if role not in self.config.devices:
            raise StationError(f"--fault {kind}: station {self.id!r} has no {role} to fault")
        with self.world.lock:
            self.faults.add(kind, at_s)
