"""Fixed-size ring buffers for live plots, and the decimation that keeps drawing cheap.

The GUI keeps the last few minutes of each stream in memory (everything goes to disk through
the recorder anyway) and draws at most a few thousand points per curve, whatever the stream
rate: min/max decimation keeps the envelope of a fast signal visible.
"""

from __future__ import annotations

import numpy as np


class RingBuffer:
    """The last `capacity` rows of an (n, n_cols) float stream; `view()` returns them in order."""

    def __init__(self, capacity: int, n_cols: int) -> None:
        if capacity < 1 or n_cols < 1:
            raise ValueError(f"RingBuffer capacity={capacity} and n_cols={n_cols} must be >= 1")
        self.capacity = int(capacity)
        self.n_cols = int(n_cols)
        self._data = np.empty((self.capacity, self.n_cols))
        self._start = 0
        self._size = 0
        self.total_rows = 0  # rows ever appended (the stream's count, not the buffer's)

    def __len__(self) -> int:
        return self._size

    def clear(self) -> None:
        self._start = 0
        self._size = 0
        self.total_rows = 0

    def append(self, rows: np.ndarray) -> None:
        """Append rows (n, n_cols); the oldest rows fall out when full."""
        rows = np.asarray(rows, dtype=float)
        if rows.ndim == 1:
            rows = rows.reshape(1, -1)
        if rows.shape[1] != self.n_cols:
            raise ValueError(f"RingBuffer rows have {rows.shape[1]} columns, expected {self.n_cols}")
        n = rows.shape[0]
        self.total_rows += n
        if n >= self.capacity:
            self._data[:] = rows[-self.capacity:]
            self._start = 0
            self._size = self.capacity
            return
        end = (self._start + self._size) % self.capacity
        first = min(n, self.capacity - end)
        self._data[end:end + first] = rows[:first]
        self._data[: n - first] = rows[first:]
        overflow = max(0, self._size + n - self.capacity)
        self._size = min(self.capacity, self._size + n)
        self._start = (self._start + overflow) % self.capacity

    def view(self) -> np.ndarray:
        """The rows in order, oldest first (a copy when the buffer has wrapped)."""
        if self._start + self._size <= self.capacity:
            return self._data[self._start:self._start + self._size]
        return np.concatenate((self._data[self._start:], self._data[: (self._start + self._size) % self.capacity]))


def decimate_minmax(x: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ~max_points (x, y) pairs: each bucket keeps its min and max, in time order, so
    peaks survive decimation (a stride would alias a 1 kHz ripple into a false slow wave)."""
    n = len(x)
    if n <= max_points or max_points < 4:
        return x, y
    n_buckets = max_points // 2
    size = n // n_buckets
    m = size * n_buckets
    yb = y[:m].reshape(n_buckets, size)
    xb = x[:m].reshape(n_buckets, size)
    i_min = np.argmin(yb, axis=1)
    i_max = np.argmax(yb, axis=1)
    lo = np.minimum(i_min, i_max)
    hi = np.maximum(i_min, i_max)
    rows = np.arange(n_buckets)
    xd = np.empty(2 * n_buckets)
    yd = np.empty(2 * n_buckets)
    xd[0::2], xd[1::2] = xb[rows, lo], xb[rows, hi]
    yd[0::2], yd[1::2] = yb[rows, lo], yb[rows, hi]
    if m < n:  # keep the newest samples visible
        xd = np.append(xd, x[-1])
        yd = np.append(yd, y[-1])
    return xd, yd
