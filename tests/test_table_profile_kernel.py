"""The table's compiled motion step (rate_table.kernels.profile_step) gives the numbers of the
per-sample Python loop it replaced, bit for bit: rate mode ramps up and down, position moves
(short, long, both directions, settling in position), a brake with the drive disabled, an
e-stop, and the watchdog's stop that disables the drive at rest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.rate_table import modbus_protocol as mp
from simulators.rate_table.mechanics import TableMechanics


def _python_step(m: TableMechanics, n: int, dt_s: float) -> np.ndarray:
    """The loop as it was written in Python (the reference)."""
    alpha = 1.0 - math.exp(-dt_s / m.tau_s)
    angles = np.empty(n)
    for k in range(n):
        goal, a = m._goal(dt_s)
        dv = a * dt_s
        ref_old = m.ref_dps
        m.ref_dps = goal if abs(goal - ref_old) <= dv else ref_old + math.copysign(dv, goal - ref_old)
        m.ref_angle_deg += 0.5 * (ref_old + m.ref_dps) * dt_s
        if m.mode == mp.MODE_POSITION and m.enabled and not m._position_done:
            err = m._target_unwrapped_deg - m.ref_angle_deg
            if abs(err) <= 1e-9 or (abs(err) <= a * dt_s * dt_s and abs(m.ref_dps) <= dv):
                m.ref_angle_deg, m.ref_dps, m._position_done = m._target_unwrapped_deg, 0.0, True
        y_old = m.rate_dps
        y = y_old + (m.ref_dps - y_old) * alpha
        if abs(y - m.ref_dps) < 1e-9:
            y = m.ref_dps
        m.rate_dps = y
        m.angle_deg += 0.5 * (y_old + y) * dt_s
        if m.watchdog_expired and m.enabled and y == 0.0 and m.ref_dps == 0.0:
            m.enabled = False
        angles[k] = m.angle_deg
    return angles


def _state(m: TableMechanics) -> tuple:
    return (m.ref_dps, m.ref_angle_deg, m.rate_dps, m.angle_deg, m._position_done, m.enabled)


SCRIPTS = {
    "rate up and down": [("rate", 300.0, 200.0), ("run", 120), ("rate", -50.0, 500.0), ("run", 80)],
    "position moves": [("pos", 40.0, 123.4, 300.0), ("run", 200), ("pos", 90.0, 10.0, 50.0), ("run", 300)],
    "brake when disabled": [("rate", 200.0, 400.0), ("run", 40), ("disable",), ("run", 60)],
    "e-stop": [("rate", 150.0, 300.0), ("run", 30), ("estop",), ("run", 40)],
    "watchdog stop": [("rate", 20.0, 200.0), ("run", 20), ("watchdog",), ("run", 80)],
}


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_the_compiled_motion_step_is_the_python_loop_bit_for_bit(name):
    tables = [TableMechanics(seed=1, watchdog_s=0.0) for _ in range(2)]
    for m in tables:
        m.set_enabled(True)
    blocks: list[list[np.ndarray]] = [[], []]
    for action in SCRIPTS[name]:
        kind = action[0]
        for i, m in enumerate(tables):
            if kind == "rate":
                m.command(mp.MODE_RATE, action[1], 0.0, action[2])
            elif kind == "pos":
                m.command(mp.MODE_POSITION, action[1], action[2], action[3])
            elif kind == "disable":
                m.set_enabled(False)
            elif kind == "estop":
                m.estop_pressed = m.estop_latched = True
            elif kind == "watchdog":
                m.watchdog_expired = True
                m.mode = mp.MODE_STOP
            elif kind == "run":
                blocks[i] = [m._step(50, 1e-3) if i == 0 else _python_step(m, 50, 1e-3) for _ in range(action[1] // 10)]
        if kind == "run":
            assert all(np.array_equal(a, b) for a, b in zip(blocks[0], blocks[1], strict=True)), (name, action)
        assert _state(tables[0]) == _state(tables[1]), (name, action)
