"""Simulated temperature chambers (docs/chamber.md)."""
