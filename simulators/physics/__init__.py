"""Resonator physics: parameters, the averaged slow-variable model, a carrier-level integrator."""
