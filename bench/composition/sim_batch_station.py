"""The simulated several-gyros station: one Rig (a World per slot, one table), the shared
devices' simulators (the table; a front end behind its switch) and each slot's own (its FPGA, its
front end) on loopback, the real drivers pointed at them; faults aimed at one slot.  Part of the
composition root (bench.composition)."""

from __future__ import annotations

import math
import threading
from typing import Any

from bench.devices import DRIVERS, StationError
from bench.fault_kinds import check_kind
from bench.slots import BATCH_ROLES, BatchStation
from bench.station_config import SIM_KEYS, StationConfig
from simulators.faults import FaultScheduler, stop_simulators
from simulators.faults import inject as inject_fault


def slot_params(preset_name: str, seed: int) -> Any:
    """A slot's resonator: drawn from the preset's production spread (simulators.lot) with the
    slot's own seed; the preset itself when it has no spread."""
    from simulators.lot import SPREADS, draw_units
    from simulators.physics.params import preset

    if preset_name not in SPREADS:
        return preset(preset_name)
    return draw_units(preset_name, 1, seed, "slot")[0].params  # the first unit is never pushed out of spec


class SimBatchStation(BatchStation):
    """A simulated batch station.  Slot n's seed is `seed * 100 + n` (its resonator's draw, its
    noise, its simulators); `resonators` (one per slot) replaces the draws."""

    def __init__(self, config: StationConfig, *, seed: int | None = None, speed: float | None = None,
                 resonators: list[Any] | None = None) -> None:
        sim = dict(config.simulation or {})
        if seed is not None:
            sim["seed"] = SIM_KEYS["seed"].check("", "--seed", seed)
        if speed is not None:
            sim["speed"] = SIM_KEYS["speed"].check("", "--speed", speed)
        config = StationConfig(config.source, config.station, sim, config.devices, config.slots, config.nominal,
                               calibration=config.calibration)
        n = len(config.slots)
        if resonators is not None and len(resonators) != n:
            raise StationError(f"{config.source}: {len(resonators)} resonators given for {n} slots")
        from simulators.physics.noise import NOISE_PRESETS
        from simulators.rig import Rig

        seeds = [self._seed_of(sim["seed"], k) for k in range(1, n + 1)]
        params = resonators or [slot_params(sim["preset"], s) for s in seeds]
        from simulators.physics.errors import ERROR_PRESETS

        self.rig = Rig(params, seeds=seeds, sample_period_s=sim["sample_period_s"],
                       noise=NOISE_PRESETS.get(sim["preset"]), errors=ERROR_PRESETS.get(sim["preset"]))
        self.handles: dict[tuple[int | None, str], Any] = {}
        self.addresses: dict[tuple[int | None, str], dict[str, Any]] = {}
        self.faults = FaultScheduler(self._inject_scheduled)
        self.rig.attach(self.faults)
        self._timers: list[threading.Timer] = []
        super().__init__(config)

    @staticmethod
    def _seed_of(seed: int, slot: int) -> int:
        return int(seed) * 100 + slot

    def slot_seed(self, slot: int) -> int:
        return self._seed_of(self.config.simulation["seed"], slot)

    def _make_clock(self) -> Any:
        from bench.clock import SimClock, SlotClock

        speed = self.config.simulation["speed"]
        return SlotClock(SimClock(self.rig, speed=math.inf if speed == 0 else speed))

    def _serve(self, slot: int | None, role: str, cfg: dict[str, Any]) -> None:
        from simulators.rig import SwitchedWorld

        spec = DRIVERS[cfg["driver"]]
        if spec.serve is None:
            raise StationError(f"{self.config.source}: {role} driver {spec.name!r} has no simulator")
        if slot is not None:
            world = self.rig.worlds[slot - 1]
        elif role in BATCH_ROLES:  # the table turns every slot; the chamber holds every slot's unit
            world = self.rig
        else:  # a shared instrument: behind the switch that connects it to one slot at a time
            world = SwitchedWorld(self.rig)
        self.handles[(slot, role)], self.addresses[(slot, role)] = spec.serve_simulator(world, cfg)

    def open(self) -> SimBatchStation:
        if self.shared:
            return self
        from simulators.warm import warm_kernels

        warm_kernels()  # compiled kernels loaded before anything serves (simulators/warm.py says why)
        try:
            for role, cfg in self.config.devices.items():
                if (None, role) not in self.handles:
                    self._serve(None, role, cfg)
            for n, devices in self.config.slots.items():
                for role, cfg in devices.items():
                    if (n, role) not in self.handles:
                        self._serve(n, role, cfg)
        except Exception:
            self.close()
            raise
        super().open()
        return self

    def _device_cfg(self, slot: int | None, role: str, cfg: dict[str, Any]) -> dict[str, Any]:
        return {**cfg, **self.addresses.get((slot, role), {})}

    def close(self) -> None:
        super().close()
        stop_simulators(self._timers, self.handles)
        self.base_clock.close()

    def truth(self, slot: int) -> dict[str, float]:
        """Slot `slot`'s true parameters (its World's and what its own simulators add)."""
        out = self.rig.truth(slot)
        for (s, _role), handle in self.handles.items():
            extra = getattr(handle, "truth", None)
            if s == slot and callable(extra):
                out.update(extra())
        return out

    # --- faults --------------------------------------------------------------------------------
    def _handles_of(self, slot: int | None) -> dict[str, Any]:
        """The simulators a fault may hit: the shared ones, and slot `slot`'s own."""
        out = {role: h for (s, role), h in self.handles.items() if s is None}
        if slot is not None:
            out.update({role: h for (s, role), h in self.handles.items() if s == slot})
        return out

    def inject(self, kind: str, slot: int | None = None) -> None:
        """Inject a fault now; a slot's own device (its FPGA link) needs `slot`."""
        role = check_kind(kind).role
        if slot is None and not any(s is None and r == role for s, r in self.handles):
            raise StationError(f"fault {kind!r}: the {role} is a slot's own on {self.id!r}: "
                               f"aim it, {kind}@SECONDS:slotN")
        inject_fault(self._handles_of(slot), kind, self._timers)

    def _inject_scheduled(self, text: str) -> None:
        kind, _, where = text.partition(":slot")
        self.inject(kind, int(where) if where else None)

    def schedule_fault(self, kind: str, at_s: float, slot: int | None = None) -> None:
        """Inject `kind` (into slot `slot`'s own device, or a shared one) at `at_s` simulated seconds."""
        role = check_kind(kind).role
        if not (math.isfinite(at_s) and at_s >= 0):
            raise StationError(f"fault {kind!r} at {at_s!r} s: the time must be >= 0")
        if slot is not None and slot not in self.slots:
            raise StationError(f"--fault {kind}@{at_s:g}:slot{slot}: station {self.id!r} has slots "
                               f"{min(self.slots)} to {max(self.slots)}")
        shared = role in self.config.devices
        own = slot is not None and role in self.config.slots[slot]
        if not (shared or own):
            where = f"slot {slot}" if slot is not None else "its shared devices"
            hint = "" if slot is not None else f" (aim it at a slot: {kind}@{at_s:g}:slot1)"
            raise StationError(f"--fault {kind}: station {self.id!r} has no {role} in {where}{hint}")
        with self.rig.lock:
            self.faults.add(kind if slot is None or shared else f"{kind}:slot{slot}", at_s)
