"""Estimators bound their work and fail with a named error on data they cannot fit (issue 13
item 13: mems-sweep's identification ran for more than 15 minutes on an HRG's sweep)."""

from __future__ import annotations

import numpy as np
import pytest

import bench.analysis.maslov_forced as mf
from bench.analysis.maslov_forced import ForcedFitError
from procedures.mems_sweep import MemsSweep, sweep_analysis


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forced_identification_of_a_sweep_without_a_resonance_fails_by_name(seed, monkeypatch):
    calls = {"rhs": 0}
    rhs = mf.forced_rhs

    def counted(*a, **k):
        calls["rhs"] += 1
        return rhs(*a, **k)

    monkeypatch.setattr(mf, "forced_rhs", counted)
    p = MemsSweep({})
    f = np.concatenate([p.frequencies(), p.frequencies()[::-1]])
    direction = np.concatenate([np.ones(p.n_points), -np.ones(p.n_points)])
    q = 3e-4 * np.random.default_rng(seed).standard_normal((f.size, 4))  # what an HRG answers off its resonance
    with pytest.raises(ForcedFitError, match="the data do not fit the (linear )?forced model"):
        sweep_analysis(f, q, direction, natural_freq_hz=p.natural_freq_hz, bryan_factor=p.bryan_factor,
                       improvement=p.improvement)
    # settling integrations bounded per point and per call (plus the Newton solves around them)
    assert calls["rhs"] <= (mf.MAX_SETTLES + 1) * mf.MAX_SETTLE_EVALUATIONS + 241 * 2000
