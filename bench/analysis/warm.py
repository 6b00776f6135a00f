"""Imported by the compute workers' forkserver (bench.engine.compute.PRELOAD): fills the
estimators' one-time tables there, so that every worker forked from it starts with them instead
of computing them again (the damping belt alone takes ~0.1 s, a worker's whole fit ~0.03 s)."""

from __future__ import annotations

from .damping import _belt_table

_belt_table(0.95)  # delta_interval's default level: every fit_free_decay asks for it
