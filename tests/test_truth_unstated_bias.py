"""A bias's truth is stated only where the simulator's truth rules hold: on a unit with error sources
whose bias they leave out (readout phase delay, electrode angles, ...: the realistic presets) the
bias is compared with no truth and says why (it read 152.9 deg/h against a 'truth' of 29.6)."""

from __future__ import annotations

import math

from bench.composition import load_station
from procedures import find_procedure, no_truth_reasons
from procedures.cvg_output import UNSTATED_BIAS_NO_TRUTH, mean_bias_truth, static_bias_truth, unstated_bias_sources


def test_bias_truth_on_a_plain_unit_and_none_on_a_realistic_one():
    plain = load_station("sim-hrg-wa", seed=0).truth()
    realistic = load_station("sim-hrg-thermal-quick", seed=0).truth()
    assert unstated_bias_sources(plain) == []
    assert math.isfinite(static_bias_truth(plain)) and math.isfinite(mean_bias_truth(plain))
    assert "pickoff_phase_x_deg" in unstated_bias_sources(realistic)
    assert static_bias_truth(realistic) is None and mean_bias_truth(realistic) is None


def test_the_reason_is_declared_where_the_truth_would_be():
    for proc, name in (("thermal-soak", "bias_at_25c_dph"), ("thermal-ramp", "bias_at_25c_dph"),
                       ("cvg-scale-factor", "bias_dph")):
        cls = find_procedure(proc)
        declared = {m.name for m in cls.measurements}
        if name not in declared:  # the scale-factor series names its mean bias its own way
            name = next(m.name for m in cls.measurements if m.truth is mean_bias_truth)
        assert no_truth_reasons(proc)[name] == UNSTATED_BIAS_NO_TRUTH


def test_the_first_turn_on_bias_has_no_truth_where_turn_ons_vary():
    from procedures.cvg_bias import FIRST_TURN_ON_NO_TRUTH, first_turn_on_bias_truth

    varies = load_station("sim-hrg-wa", seed=0).truth()  # turn-on bias sd 2 deg/h
    assert varies["turn_on_bias_sd_dph"] > 0 and first_turn_on_bias_truth(varies) is None
    same = dict(varies, turn_on_bias_sd_dph=0.0)
    assert first_turn_on_bias_truth(same) == static_bias_truth(same)
    assert no_truth_reasons("cvg-bias")["bias_first_dph"] == FIRST_TURN_ON_NO_TRUTH
