"""Calibration procedures, one module a procedure."""
