"""The production line: sequences of procedures per unit, limits on the uncertainty, one record per
unit and attempt, the line database, a simulated lot and the line report (`gyrobench line ...`)."""

from bench.validation import ValidationError


class LineError(ValidationError):
    """A bad sequence or limits file, or a line run that cannot start; one line naming the key,
    the value and the limit."""
