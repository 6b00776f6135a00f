"""The simulated bench: resonator physics, a World with virtual time, and device simulators."""
