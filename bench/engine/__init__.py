"""The procedure engine: events, typed parameters, procedures as named steps, the runner and
the safe state."""
