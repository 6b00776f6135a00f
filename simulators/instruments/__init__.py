"""Simulated bench instruments a station can name under its own device names (driver "pymeasure")."""
