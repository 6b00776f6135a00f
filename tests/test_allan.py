"""Allan read-offs (bench.analysis.allan) on seeded synthetic rate records of known N, B, K: the
values, and the coverage of their intervals (benchmarks/allan_coverage.py runs more seeds)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.analysis.allan import adev_band, allan_deviation, read_noise_terms
from simulators.physics.noise import NOISE_PRESETS, Environment, NoiseParams, rad_s_to_dph

TO_DPH = rad_s_to_dph(1.0)
#: hrg-wa's noise with the flicker band's top under the 10 Hz records' Nyquist frequency
NOISE = dataclasses.replace(NOISE_PRESETS["hrg-wa"], flicker_high_hz=2.0)


def _record(nz: NoiseParams, seed: int, hours: float = 2.0, fs: float = 10.0) -> np.ndarray:
    return Environment(nz, seed=seed, sample_period_s=1.0 / fs).rate_samples(int(hours * 3600 * fs)) * TO_DPH


def test_allantools_gives_the_overlapping_adev_of_white_noise():
    rng = np.random.default_rng(0)
    curve = allan_deviation(rng.standard_normal(100_000), 10.0)
    assert curve.tau_s[0] == pytest.approx(0.1) and np.all(np.diff(np.log2(curve.tau_s)) == pytest.approx(1.0))
    # white rate of sd 1 at 10 Hz: sigma(tau) = sqrt(0.1 / tau)
    assert np.allclose(curve.adev[:8], np.sqrt(0.1 / curve.tau_s[:8]), rtol=0.05)


def test_read_offs_cover_the_known_terms():
    """40 seeded 2 h records: each 95 % interval holds the truth in at least 34 of them (a binomial
    0.95 gives fewer than 34 with probability 0.005), and the estimates are unbiased to a few %."""
    hits = dict.fromkeys("NBK", 0)
    ratios = {k: [] for k in "NBK"}
    truth = {"N": NOISE.arw_deg_rth, "B": NOISE.bias_instability_dph, "K": NOISE.rrw_dph_rth}
    seeds = 40
    for seed in range(seeds):
        terms = read_noise_terms(allan_deviation(_record(NOISE, seed), 10.0))
        for k, t in (("N", terms.arw), ("B", terms.bias_instability), ("K", terms.rrw)):
            hits[k] += t.ci[0] <= truth[k] <= t.ci[1]
            ratios[k].append(t.value / truth[k])
    assert all(h >= 34 for h in hits.values()), hits
    assert abs(np.mean(ratios["N"]) - 1) < 0.02 and abs(np.mean(ratios["B"]) - 1) < 0.06
    assert abs(np.mean(ratios["K"]) - 1) < 0.15, np.mean(ratios["K"])


def test_a_long_record_reads_each_term_at_its_slope():
    terms = read_noise_terms(allan_deviation(_record(NOISE, 100, hours=10.0), 10.0))
    assert 0.8 <= terms.arw.tau_s <= 3.2 and terms.arw.share > 0.7  # the -1/2 slope near tau = 1 s
    assert 10 <= terms.bias_instability.tau_s <= 60  # the flat minimum
    assert terms.rrw.tau_s >= 50 and terms.rrw.share > 0.4  # the +1/2 slope
    for t, true in ((terms.arw, NOISE.arw_deg_rth), (terms.bias_instability, NOISE.bias_instability_dph),
                    (terms.rrw, NOISE.rrw_dph_rth)):
        assert abs(t.value - true) <= 1.5 * (t.ci[1] - t.ci[0]) / 2, t  # (coverage: the test above)
        assert t.ci[0] > 0  # decisive: the term is seen
    curve = allan_deviation(_record(NOISE, 100, hours=10.0), 10.0)
    sel = (curve.tau_s >= 0.8) & (curve.tau_s <= 500.0)  # (longer: too few clusters to pin it)
    assert np.all(np.abs(terms.model_adev(curve.tau_s[sel]) / curve.adev[sel] - 1) < 0.06)  # through the curve
    lo, hi = adev_band(curve, terms)
    assert np.all((lo < curve.adev) & (curve.adev < hi))


def test_white_noise_alone_reads_no_floor_and_no_walk():
    """20 records of white rate noise: N covered (at least 16 of 20: binomial 0.95 gives fewer with
    probability 0.016), and B and K consistent with none (their intervals reach 0) as often."""
    n_hits = b_none = k_none = 0
    for seed in range(20):
        terms = read_noise_terms(allan_deviation(_record(NoiseParams(arw_deg_rth=0.01), seed), 10.0))
        n_hits += terms.arw.ci[0] <= 0.01 <= terms.arw.ci[1]
        b_none += terms.bias_instability.ci[0] == 0.0
        k_none += terms.rrw.ci[0] == 0.0
    assert n_hits >= 16 and b_none >= 16 and k_none >= 16, (n_hits, b_none, k_none)


def test_too_short_a_record_is_named():
    with pytest.raises(ValueError, match="at least 8 samples"):
        allan_deviation(np.zeros(5), 10.0)
