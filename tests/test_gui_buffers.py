"""The GUI's ring buffer and min/max decimation (pure numpy, no Qt)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.gui.ringbuffer import MinMaxHistory, RingBuffer


def test_ring_buffer_keeps_the_newest_rows_in_order():
    rb = RingBuffer(10, 2)
    rows = np.column_stack((np.arange(27.0), -np.arange(27.0)))
    for i in range(0, 27, 4):  # blocks that straddle the wrap
        rb.append(rows[i:i + 4])
    assert len(rb) == 10 and rb.total_rows == 27
    assert np.array_equal(rb.view(), rows[-10:])
    rb.append(rows[:25])  # a block larger than the buffer
    assert np.array_equal(rb.view(), rows[15:25])
    with pytest.raises(ValueError, match="3 columns, expected 2"):
        rb.append(np.zeros((1, 3)))


def test_minmax_history_keeps_peaks_and_bounds_the_points():
    t = np.arange(300_000) * 1e-3  # 300 s at 1 kHz, the worst case
    y = np.sin(2 * np.pi * 0.1 * t)
    y[123_457] = 5.0  # a single-sample spike must survive
    y[200_001] = -7.0
    h = MinMaxHistory(2, max_points=2000)
    for i in range(0, len(t), 137):  # odd block sizes, as a link delivers them
        h.append(t[i:i + 137], np.column_stack((y[i:i + 137], -y[i:i + 137])))
    assert h.total_rows == 300_000
    x, yd = h.curve(0)
    assert len(x) <= 2000 + h.bucket_rows
    assert yd.max() == 5.0 and yd.min() == -7.0
    assert x[np.argmax(yd)] == t[123_457]  # at its own time
    assert np.all(np.diff(x) >= 0) and x[-1] == t[-1]
    assert h.curve(1)[1].max() == 7.0
    short = MinMaxHistory(1, max_points=2000)
    short.append(t[:500], y[:500, None])  # a short run is drawn at full resolution
    assert np.array_equal(short.curve(0)[0], t[:500])
    win = MinMaxHistory(1, max_points=100, history_s=10.0)
    win.append(t[:30_000], y[:30_000, None])
    assert win.curve(0)[0][0] >= t[30_000 - 1] - 10.0 - win.bucket_rows * 1e-3


def test_buffers_read_columns_by_name():
    """The live buffers are built with their columns' names and read by them (issue 14 item 3)."""
    rb = RingBuffer(4, ("freq_hz", "amplitude"))
    rb.append(np.array([[1.0, 10.0], [2.0, 20.0]]))
    assert np.array_equal(rb.column("amplitude"), [10.0, 20.0])
    h = MinMaxHistory(("rate_dps", "angle_deg"), max_points=100)
    h.append(np.arange(3.0), np.array([[1.0, 5.0], [2.0, 6.0], [3.0, 7.0]]))
    assert np.array_equal(h.curve("angle_deg")[1], [5.0, 6.0, 7.0])
    assert np.array_equal(h.curve("angle_deg")[1], h.curve(1)[1])
