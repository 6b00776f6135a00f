"""The GUI's ring buffer and min/max decimation (pure numpy, no Qt)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.gui.params import ParamSpec
from bench.gui.ringbuffer import RingBuffer, decimate_minmax


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


def test_minmax_decimation_keeps_peaks_and_bounds_the_points():
    t = np.arange(300_000) * 1e-3  # 300 s at 1 kHz, the worst case
    y = np.sin(2 * np.pi * 0.1 * t)
    y[123_457] = 5.0  # a single-sample spike must survive
    xd, yd = decimate_minmax(t, y, 2000)
    assert len(xd) <= 2001
    assert yd.max() == 5.0 and yd.min() == pytest.approx(-1.0, abs=1e-4)
    assert np.all(np.diff(xd) >= 0)  # still in time order
    assert xd[-1] == t[-1]


def test_param_spec_errors_name_the_value_and_the_limit():
    spec = ParamSpec("rate_dps", "float", "deg/s", 100.0, -1000.0, 1000.0)
    assert spec.parse(" 250 ") == 250.0
    with pytest.raises(ValueError, match=r"rate_dps=1500 deg/s is above the limit 1000 deg/s"):
        spec.parse("1500")
    with pytest.raises(ValueError, match="must be finite"):
        spec.parse("nan")
    assert ParamSpec("n", "int", low=3).parse("7") == 7
    with pytest.raises(ValueError, match="not an integer"):
        ParamSpec("n", "int").parse("7.5")
