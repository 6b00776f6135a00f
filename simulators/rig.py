"""Several gyros on one rate table: a World per slot (its own resonator, seed and noise, its own
simulated FPGA), one table turning them all, advanced block by block together under one lock.

The table's simulator attaches to the rig (it lands on slot 1's world, the "table world"); every
other slot world takes the case rate and ripple of each block from it (`World.case_source`), so
all resonators see the same motion.  A block's length is the smallest any slot's devices allow.
A front end shared by the slots through a switch (`SwitchedWorld`) drives and reads the slot its
`ROUT:SLOT` selects; the others see no front-end force.
"""

from __future__ import annotations

import math
import threading
from typing import Any

from .world import World


class Rig:
    """N slot worlds on one table, with the World interface the clock and the table use."""

    def __init__(self, slot_params: list[Any], *, seeds: list[int], sample_period_s: float = 1e-3,
                 noise: Any = None, earth_rate_dph: float = 0.0, errors: Any = None) -> None:
        if not slot_params or len(slot_params) != len(seeds):
            raise ValueError(f"a rig needs one seed per slot ({len(slot_params)} slots, {len(seeds)} seeds)")
        self.lock = threading.RLock()
        self.worlds = [World(p, seed=s, sample_period_s=sample_period_s, noise=noise,
                             earth_rate_dph=earth_rate_dph, lock=self.lock, errors=errors)
                       for p, s in zip(slot_params, seeds, strict=True)]
        for w in self.worlds[1:]:
            w.case_source = self.worlds[0]
        self.table_world = self.worlds[0]
        self.seed = seeds[0]
        self.sample_period_s = self.table_world.sample_period_s
        self._pending_s = 0.0
        self._listeners: list[Any] = []

    @property
    def t_s(self) -> float:
        return self.table_world.t_s

    @property
    def sample_index(self) -> int:
        return self.table_world.sample_index

    @property
    def params(self) -> Any:
        return self.table_world.params

    # --- the table's devices ----------------------------------------------------------------
    def attach(self, device: Any) -> None:
        self.table_world.attach(device)

    def detach(self, device: Any) -> None:
        self.table_world.detach(device)

    def add_listener(self, callback: Any, *, each_block: bool = True) -> None:
        """callback(rig) after every block of all slots (the real-time clock's waits)."""
        self._listeners.append(callback)

    def add_advance_listener(self, callback: Any) -> None:
        self.table_world.add_advance_listener(callback)

    def remove_advance_listener(self, callback: Any) -> None:
        self.table_world.remove_advance_listener(callback)

    def state(self) -> Any:
        return self.table_world.state()

    # --- advance ------------------------------------------------------------------------------
    def advance(self, dt_s: float) -> int:
        """Advance every slot by dt_s (whole samples, remainder carried), block by block together."""
        if not math.isfinite(dt_s) or dt_s < 0:
            raise ValueError(f"advance dt_s={dt_s!r} must be finite and >= 0")
        with self.lock:
            self._pending_s += dt_s
            n_total = int(math.floor(self._pending_s / self.sample_period_s + 1e-9))
            self._pending_s = max(0.0, self._pending_s - n_total * self.sample_period_s)
            self.advance_samples(n_total)
            return n_total

    def advance_samples(self, n_total: int) -> None:
        with self.lock:
            done = 0
            while done < n_total:
                n = min(n_total - done, min(w._block_limit() for w in self.worlds))
                for w in self.worlds:  # the table world first: the others take its case rate
                    w._run_block(n)
                for cb in self._listeners:
                    cb(self)
                done += n
            for w in self.worlds:  # each slot's link sends what this advance produced, in one write
                for cb in w._advance_listeners:
                    cb(w)

    # --- truth --------------------------------------------------------------------------------
    def truth(self, slot: int) -> dict[str, float]:
        """Slot `slot`'s (1-based) true parameters."""
        return self.worlds[slot - 1].truth()


class SwitchedWorld:
    """What a front end shared by the slots through a switch sees: the slot world its model's
    `slot` (ROUT:SLOT) selects.  Attached, it routes the model's World hooks to that slot only."""

    def __init__(self, rig: Rig) -> None:
        self.rig = rig
        self.lock = rig.lock
        self.seed = rig.seed
        self.sample_period_s = rig.sample_period_s
        self.model: Any = None
        self._routes: list[_Route] = []

    def _selected(self) -> World:
        k = int(getattr(self.model, "slot", 1)) - 1
        return self.rig.worlds[k] if 0 <= k < len(self.rig.worlds) else self.rig.table_world

    @property
    def t_s(self) -> float:
        return self.rig.t_s

    @property
    def ref_freq_hz(self) -> float:
        return self._selected().ref_freq_hz

    def state(self) -> Any:
        return self._selected().state()

    def attach(self, model: Any) -> None:
        with self.lock:
            self.model = model
            self._routes = [_Route(self, k) for k in range(len(self.rig.worlds))]
            for w, r in zip(self.rig.worlds, self._routes, strict=True):
                w.attach(r)

    def detach(self, model: Any) -> None:
        with self.lock:
            for w, r in zip(self.rig.worlds, self._routes, strict=True):
                w.detach(r)
            self._routes = []

    def set_force(self, source: str, force: Any) -> None:
        for w in self.rig.worlds:
            w.set_force(source, force)


class _Route:
    """Slot k's end of the switch: forwards the front end's hooks while the switch selects k."""

    def __init__(self, switch: SwitchedWorld, k: int) -> None:
        self.switch, self.k = switch, k

    def _on(self) -> bool:
        return int(getattr(self.switch.model, "slot", 1)) - 1 == self.k

    def before_block(self, world: World, t_s: float, n: int, dt_s: float) -> None:
        if self._on():
            self.switch.model.before_block(world, t_s, n, dt_s)
        else:
            from .frontend.model import FORCE_SOURCE

            world.set_force(FORCE_SOURCE, None)

    def after_block(self, world: World, block: Any) -> None:
        if self._on():
            self.switch.model.after_block(world, block)
