"""simulators.physics.normals: pieces taken from the buffer are the values, in the order, that
drawing each piece from the generator directly gives (seeded runs stay bit-identical)."""

from __future__ import annotations

import numpy as np

from simulators.physics.normals import NormalBuffer


def test_pieces_equal_direct_draws_across_chunk_boundaries():
    buf = NormalBuffer(np.random.default_rng(7), chunk=64)
    direct = np.random.default_rng(7)
    for n in (1, 50, 13, 64, 200, 3, 64, 65, 7):  # pieces smaller than, equal to and beyond a chunk
        got = buf.take(n)
        assert got.shape == (n,)
        np.testing.assert_array_equal(got, direct.standard_normal(n))


def test_pieces_are_fresh_writable_arrays():
    buf = NormalBuffer(np.random.default_rng(1), chunk=16)
    a = buf.take(4)
    a[:] = 0.0  # the caller may write its piece: the next piece is not touched
    np.testing.assert_array_equal(buf.take(4), np.random.default_rng(1).standard_normal(8)[4:])


def test_scaled_pieces_equal_rng_normal():
    """The resonator's measure(): q + (0 + sigma z) is rng.normal(0, sigma) added, bit for bit."""
    sigma, q = 0.003, np.linspace(-1.0, 1.0, 40).reshape(10, 4)
    z = NormalBuffer(np.random.default_rng(5)).take(40).reshape(10, 4)
    np.testing.assert_array_equal(q + (0.0 + sigma * z), q + np.random.default_rng(5).normal(0.0, sigma, (10, 4)))
