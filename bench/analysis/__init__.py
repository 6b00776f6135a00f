"""Pure analysis: arrays in, frozen results out.  Imports no driver, simulator, clock or file."""
