"""gyrobench: engine, station, clock, recorder, results, analysis, CLI, GUI and reports."""

__version__ = "0.1.0"
