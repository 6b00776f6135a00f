"""Standard normal draws handed out in small pieces from one big draw: a 50 ms block's few
hundred draws cost a numpy call (~2 us, and a release of the GIL) each block otherwise.

numpy's Generator fills an array of standard normals one value after the other from its bit
stream, so pieces of one draw of m values are the values m draws of one would give: the numbers a
caller gets, and their order, are those of drawing each piece from the generator directly.  Only
the generator's own state runs ahead (up to one chunk): nothing else may draw from it.
"""

from __future__ import annotations

import numpy as np

CHUNK = 8192  # values drawn at a time


class NormalBuffer:
    """Standard normals of one generator, taken piece by piece in the generator's order."""

    def __init__(self, rng: np.random.Generator, chunk: int = CHUNK) -> None:
        self.rng = rng
        self.chunk = int(chunk)
        self._buf = np.empty(0)
        self._pos = 0

    def take(self, n: int) -> np.ndarray:
        """The next n standard normals (n,), a fresh array the caller may write (a copy, not a
        view: allocated as a direct draw's array is, so later numpy and BLAS work on it is alike)."""
        buf, pos = self._buf, self._pos
        if pos + n <= len(buf):
            self._pos = pos + n
            return buf[pos : pos + n].copy()
        rest = buf[pos:]
        fresh = self.rng.standard_normal(max(self.chunk, n - len(rest)))
        need = n - len(rest)
        self._buf, self._pos = fresh, need
        return np.concatenate((rest, fresh[:need]))
