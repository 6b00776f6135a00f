"""bench.validation on its own: the kinds of number a driver is handed (numpy's scalars from an
analysis, Python's ints) pass as they did before the drivers checked through it; open bounds."""

from __future__ import annotations

import numpy as np
import pytest

from bench.validation import LimitError, ValidationError, check_limit, convert
from drivers.frontend.properties import strict_int_range, strict_range


def test_numpy_scalars_are_numbers_and_numpy_bools_are_not():
    assert convert("rate_dps", np.float32(2.5), float) == 2.5
    assert type(convert("rate_dps", np.int64(3), float)) is float
    assert strict_range("amplitude_v", np.float64(0.5), (0.0, 1.0), "V") == 0.5
    assert strict_int_range("points", np.int64(7), (1, 10)) == 7
    assert strict_int_range("points", 7.0, (1, 10)) == 7
    with pytest.raises(ValidationError, match=r"^flag=np.True_ is not a number$"):
        convert("flag", np.bool_(True), float)
    with pytest.raises(ValidationError, match=r"^n=7.5 is not an integer$"):
        convert("n", np.float64(7.5), int)


def test_open_bounds_and_the_limit_error():
    assert check_limit("accel_dps2", 1e-9, low=0.0, low_open=True) == 1e-9
    with pytest.raises(LimitError) as err:
        check_limit("accel_dps2", 0.0, low=0.0, low_open=True, high=300.0, unit="deg/s^2")
    assert str(err.value) == "accel_dps2=0 deg/s^2 is not above the limit 0 deg/s^2"
    e = err.value
    assert (e.name, e.value, e.limit, e.unit) == ("accel_dps2", 0.0, "(0, 300]", "deg/s^2")
    with pytest.raises(LimitError, match=r"^angle_deg=360 deg is not below the limit 360 deg$"):
        check_limit("angle_deg", 360.0, low=0.0, high=360.0, high_open=True, unit="deg")
