"""table-spin's interval of the mean: Student's t quantile from scipy.special.stdtrit (what
scipy.stats.t.ppf calls), so a run does not import scipy.stats (~0.4 s of each process, issue 36)
and its results stay bit for bit what they were."""

from __future__ import annotations

import numpy as np
from scipy import stats

from procedures.examples.table_spin import TableSpin


class _Data:
    def __init__(self, rate_dps: np.ndarray) -> None:
        self.rate_dps = rate_dps

    def table(self, name: str) -> dict[str, np.ndarray]:
        assert name == "hold"
        return {"rate_dps": self.rate_dps}


def test_interval_of_the_mean_is_the_t_interval_bit_for_bit():
    rng = np.random.default_rng(5)
    for n in (2, 3, 10, 41):
        rate = 100.0 + 0.01 * rng.standard_normal(n)
        (result,) = TableSpin().analysis(_Data(rate))
        mean = float(rate.mean())
        half = float(stats.t.ppf(0.975, n - 1) * rate.std(ddof=1) / n**0.5)  # the textbook interval
        assert result.value == mean and result.ci95 == (mean - half, mean + half)


def test_one_reading_has_no_interval():
    (result,) = TableSpin().analysis(_Data(np.array([5.0])))
    assert result.value == 5.0 and result.ci95 is None
