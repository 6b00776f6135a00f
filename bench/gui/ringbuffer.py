"""Buffers for live plots: a ring of the last rows at full rate, and a whole-run history kept
min/max-decimated as it arrives, so drawing costs the same at second 1 and second 300 (the full
stream goes to disk through the recorder anyway) and the envelope of a fast signal stays visible.
"""

from __future__ import annotations

import numpy as np


def _named(n_cols: int | tuple[str, ...]) -> tuple[int, tuple[str, ...]]:
    """(number of columns, their names): a buffer is built with its columns' names (or a count)."""
    if isinstance(n_cols, int):
        return n_cols, tuple(str(i) for i in range(n_cols))
    return len(n_cols), tuple(n_cols)


class RingBuffer:
    """The last `capacity` rows of an (n, n_cols) float stream; `view()` returns them in order,
    `column(name)` one column of them by name."""

    def __init__(self, capacity: int, n_cols: int | tuple[str, ...]) -> None:
        n_cols, self.columns = _named(n_cols)
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

    def column(self, name: str) -> np.ndarray:
        """One column of `view()` by name."""
        return self.view()[:, self.columns.index(name)]


class MinMaxHistory:
    """A whole stream's history for drawing, at most ~max_points per column, kept incrementally.

    Rows are reduced into buckets as they arrive (each bucket keeps, per column, its min and its
    max with their times); when there are too many buckets, neighbours merge and the bucket size
    doubles.  Drawing costs O(max_points) however long the run, and a one-sample spike stays
    visible.  `history_s` drops buckets older than that (None keeps everything).  A NaN value
    (nothing to draw at that row) is neither a min nor a max: a bucket of NaN alone is a gap."""

    def __init__(self, n_cols: int | tuple[str, ...], max_points: int = 2000, history_s: float | None = None) -> None:
        n_cols, self.columns = _named(n_cols)
        if n_cols < 1 or max_points < 8:
            raise ValueError(f"MinMaxHistory n_cols={n_cols} must be >= 1 and max_points={max_points} >= 8")
        self.n_cols = int(n_cols)
        self.max_buckets = int(max_points) // 2
        self.history_s = history_s
        self.clear()

    def clear(self) -> None:
        self.bucket_rows = 1
        self.total_rows = 0
        self._pend_t = np.empty(0)
        self._pend_v = np.empty((0, self.n_cols))
        self._t_min = np.empty((0, self.n_cols))
        self._v_min = np.empty((0, self.n_cols))
        self._t_max = np.empty((0, self.n_cols))
        self._v_max = np.empty((0, self.n_cols))
        self.t_first = float("nan")
        self.t_last = float("nan")

    def __len__(self) -> int:
        return self.total_rows

    def append(self, t: np.ndarray, values: np.ndarray) -> None:
        """Rows at times t (n,) with values (n, n_cols), in time order."""
        t = np.asarray(t, dtype=float).reshape(-1)
        values = np.asarray(values, dtype=float).reshape(len(t), -1)
        if values.shape[1] != self.n_cols:
            raise ValueError(f"MinMaxHistory rows have {values.shape[1]} columns, expected {self.n_cols}")
        if len(t) == 0:
            return
        if self.total_rows == 0:
            self.t_first = float(t[0])
        self.total_rows += len(t)
        self.t_last = float(t[-1])
        pt = np.concatenate((self._pend_t, t))
        pv = np.concatenate((self._pend_v, values))
        b = self.bucket_rows
        n_full = len(pt) // b
        if b == 1:
            tt = np.broadcast_to(pt[:, None], pv.shape)
            self._push(tt, pv, tt, pv)
            pt, pv = pt[:0], pv[:0]
        elif n_full:
            m = n_full * b
            tb = np.broadcast_to(pt[:m].reshape(n_full, b, 1), (n_full, b, self.n_cols))
            vb = pv[:m].reshape(n_full, b, self.n_cols)
            # NaN (nothing to draw there) is neither min nor max; a bucket of NaN alone stays NaN (a gap)
            nan = np.isnan(vb)
            i_min = np.argmin(np.where(nan, np.inf, vb), axis=1)[:, None, :]
            i_max = np.argmax(np.where(nan, -np.inf, vb), axis=1)[:, None, :]
            self._push(np.take_along_axis(tb, i_min, 1)[:, 0], np.take_along_axis(vb, i_min, 1)[:, 0],
                       np.take_along_axis(tb, i_max, 1)[:, 0], np.take_along_axis(vb, i_max, 1)[:, 0])
            pt, pv = pt[m:], pv[m:]
        self._pend_t, self._pend_v = pt, pv
        self._trim()
        while len(self._t_min) > self.max_buckets:
            self._merge()

    def _push(self, t_min, v_min, t_max, v_max) -> None:
        self._t_min = np.concatenate((self._t_min, t_min))
        self._v_min = np.concatenate((self._v_min, v_min))
        self._t_max = np.concatenate((self._t_max, t_max))
        self._v_max = np.concatenate((self._v_max, v_max))

    def _trim(self) -> None:
        if self.history_s is None or not len(self._t_min):
            return
        if max(self._t_min[0].max(), self._t_max[0].max()) >= self.t_last - self.history_s:
            return  # the oldest bucket is still in the window
        keep = np.maximum(self._t_min, self._t_max).max(axis=1) >= self.t_last - self.history_s
        if not keep.all():
            self._t_min, self._v_min = self._t_min[keep], self._v_min[keep]
            self._t_max, self._v_max = self._t_max[keep], self._v_max[keep]
            if len(self._t_min):
                self.t_first = float(np.minimum(self._t_min[0], self._t_max[0]).min())

    def _merge(self) -> None:
        """Merge neighbouring buckets (an odd last one stays), doubling the bucket size."""
        n = len(self._t_min) // 2 * 2
        a, b = slice(0, n, 2), slice(1, n, 2)
        take_a = (self._v_min[a] <= self._v_min[b]) | np.isnan(self._v_min[b])  # NaN: a gap, kept only alone
        t_min = np.where(take_a, self._t_min[a], self._t_min[b])
        v_min = np.where(take_a, self._v_min[a], self._v_min[b])
        take_a = (self._v_max[a] >= self._v_max[b]) | np.isnan(self._v_max[b])
        t_max = np.where(take_a, self._t_max[a], self._t_max[b])
        v_max = np.where(take_a, self._v_max[a], self._v_max[b])
        rest = slice(n, None)
        self._t_min = np.concatenate((t_min, self._t_min[rest]))
        self._v_min = np.concatenate((v_min, self._v_min[rest]))
        self._t_max = np.concatenate((t_max, self._t_max[rest]))
        self._v_max = np.concatenate((v_max, self._v_max[rest]))
        self.bucket_rows *= 2

    def curve(self, col: int | str, positive_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) to draw for one column (by name, or position), in time order."""
        if isinstance(col, str):
            col = self.columns.index(col)
        if self.bucket_rows == 1:
            x = np.concatenate((self._t_min[:, col], self._pend_t))
            y = np.concatenate((self._v_min[:, col], self._pend_v[:, col]))
        else:
            tmin, tmax = self._t_min[:, col], self._t_max[:, col]
            vmin, vmax = self._v_min[:, col], self._v_max[:, col]
            first_min = tmin <= tmax
            x = np.empty(2 * len(tmin))
            y = np.empty(2 * len(tmin))
            x[0::2] = np.where(first_min, tmin, tmax)
            x[1::2] = np.where(first_min, tmax, tmin)
            y[0::2] = np.where(first_min, vmin, vmax)
            y[1::2] = np.where(first_min, vmax, vmin)
            tail_t, tail_v = _minmax_tail(self._pend_t, self._pend_v[:, col])  # < 1 bucket, but not raw
            x = np.concatenate((x, tail_t))
            y = np.concatenate((y, tail_v))
        if positive_only:
            ok = y > 0
            x, y = x[ok], y[ok]
        return x, y


def _minmax_tail(t: np.ndarray, v: np.ndarray, chunks: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """The rows not yet in a bucket, as the min and max of at most `chunks` pieces in time order
    (drawn raw they would be up to a whole bucket of points in the last pixels)."""
    n = len(t)
    if n <= 2 * chunks:
        return t, v
    size = -(-n // chunks)
    m = n // size * size
    tb, vb = t[:m].reshape(-1, size), v[:m].reshape(-1, size)
    nan = np.isnan(vb)
    i_min, i_max = np.argmin(np.where(nan, np.inf, vb), axis=1), np.argmax(np.where(nan, -np.inf, vb), axis=1)
    rows = np.arange(len(tb))
    first, second = np.minimum(i_min, i_max), np.maximum(i_min, i_max)
    x = np.column_stack((tb[rows, first], tb[rows, second])).reshape(-1)
    y = np.column_stack((vb[rows, first], vb[rows, second])).reshape(-1)
    return np.concatenate((x, t[m:])), np.concatenate((y, v[m:]))
