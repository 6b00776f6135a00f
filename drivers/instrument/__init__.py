"""Instruments a station names by their own role (`[devices.<name>]`): any PyMeasure instrument."""
