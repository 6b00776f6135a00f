"""The event bridge's coalescing (the window at "max", lockstep): a wake-up within min_gap_s of the
last drain is put off, so drains come fewer and fuller; nothing is lost or reordered; a queue half
way to max_pending is drained at once, so the backpressure never holds the engine for the gap."""

from __future__ import annotations

import threading

import pytest

pytest.importorskip("pytestqt")

from bench.engine import events as ev  # noqa: E402
from bench.gui.bridge import EventBridge  # noqa: E402


@pytest.fixture
def make_bridge(qtbot):
    """EventBridges that are detached and deleted in the GUI thread when the test ends: left to the
    garbage collector, a bridge with its put-off drain's timer running was deleted from whatever
    thread collected it (a later test's), and the GUI thread crashed in its event loop."""
    made: list[EventBridge] = []

    def make(*args, **kwargs) -> EventBridge:
        made.append(EventBridge(*args, **kwargs))
        return made[-1]

    yield make
    for bridge in made:
        bridge.detach()
        bridge.deleteLater()
    qtbot.wait(1)  # the deferred deletes run here, in this thread


def _collect(bridge: EventBridge) -> tuple[list[float], list[int]]:
    got: list[float] = []
    sizes: list[int] = []

    def on_batch(batch):
        sizes.append(len(batch))
        got.extend(e.t_sim_s for e in batch)

    bridge.events.connect(on_batch)
    return got, sizes


def test_a_put_off_drain_delivers_everything_in_order_in_one_batch(qtbot, make_bridge):
    bus = ev.EventBus()
    bridge = make_bridge(bus, min_gap_s=0.3, max_pending=50)
    got, sizes = _collect(bridge)
    bus.publish(ev.Log("r", 0.0, message="first"))  # the first wake-up drains at once
    qtbot.waitUntil(lambda: len(got) == 1, timeout=5000)
    worker = threading.Thread(target=lambda: [bus.publish(ev.Log("r", float(i), message="x")) for i in range(1, 21)])
    worker.start()
    worker.join(10)
    assert not worker.is_alive()
    qtbot.waitUntil(lambda: len(got) == 21, timeout=10_000)
    assert got == [float(i) for i in range(21)]  # none lost, in order
    assert sizes[0] == 1 and len(sizes) <= 3  # the 20 came in one or two drains, not twenty (max_pending 50)
    assert not bus.errors


def test_a_half_full_queue_is_drained_at_once(qtbot, make_bridge):
    """With a gap far longer than the test (60 s) and backpressure on, 40 events still arrive:
    each time the queue is half way to max_pending (5) the GUI drains at once."""
    bus = ev.EventBus()
    bridge = make_bridge(bus, min_gap_s=60.0, max_pending=10, max_wait_s=60.0)
    got, sizes = _collect(bridge)
    bus.publish(ev.Log("r", 0.0, message="first"))
    qtbot.waitUntil(lambda: len(got) == 1, timeout=5000)
    worker = threading.Thread(target=lambda: [bus.publish(ev.Log("r", float(i), message="x")) for i in range(1, 41)])
    worker.start()
    qtbot.waitUntil(lambda: len(got) >= 36, timeout=20_000)  # all but the last few (under half full: the gap)
    worker.join(20)
    assert not worker.is_alive()  # never held for the 60 s gap (nor the 60 s max_wait_s)
    assert got == [float(i) for i in range(len(got))]
    bridge.drain()  # the rest, as the screenshot mode or a close would take them
    assert got == [float(i) for i in range(41)]
    assert max(sizes) <= 10
