"""`gyrobench run`'s printed table writes numbers by the report's digit rule (bench.numbers)."""

from __future__ import annotations


def _record(measurements):
    return {"run_id": "r1", "procedure": "hrg-free-decay", "outcome": "COMPLETE", "end_reason": "done",
            "measurements": measurements, "limits": None, "safe_state": True, "simulated_s": 1.0,
            "wall_s": 1.0, "raw_file": None, "truth": None}


def test_values_and_intervals_take_two_digits_of_the_half_width(capsys):
    """300.0123 +- 0.05 prints as 300.012 [299.962, 300.062], not '300 [300, 300]'; no interval: 4 digits."""
    from bench.cli.record_table import print_record

    print_record(_record({
        "tau_s": {"value": 300.0123, "ci95": [299.9623, 300.0623], "unit": "s", "limits": None,
                  "outcome": "COMPLETE"},
        "f_hz": {"value": 5183627.4, "ci95": None, "unit": "Hz", "limits": [5e6, 6e6], "outcome": "COMPLETE"},
    }))
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if line.strip().startswith("tau_s"))
    assert "300.012" in row and "[299.962, 300.062]" in row and "[300, 300]" not in row
    f_row = next(line for line in text.splitlines() if line.strip().startswith("f_hz"))
    assert "5.184e6" in f_row and "5.18363e+06" not in f_row
    assert "[5e6, 6e6]" in f_row  # limits as the report writes them


def test_a_measurement_compared_with_no_truth_says_why_under_the_table(capsys):
    """hrg-damping's mean drift on a simulated station: no truth, no flag, and the reason printed
    (marked * in the truth column), as the report and the window say it."""
    from bench.cli.record_table import print_record
    from procedures.hrg_damping import MEAN_DRIFT_NO_TRUTH

    js = _record({
        "drift_before_mean_dph": {"value": -0.038, "ci95": [-0.048, -0.027], "unit": "deg/h", "limits": None,
                                  "outcome": "COMPLETE"},
        "drift_before_dph": {"value": 29.9, "ci95": [29.5, 30.3], "unit": "deg/h", "limits": None,
                             "outcome": "COMPLETE"},
    })
    js |= {"procedure": "hrg-damping", "truth": {"drift_before_mean_dph": 0.0, "drift_before_dph": 29.79}}
    print_record(js)
    text = capsys.readouterr().out
    row = next(line for line in text.splitlines() if line.strip().startswith("drift_before_mean_dph"))
    assert row.rstrip().endswith("*") and "!" not in row
    assert f"  * {MEAN_DRIFT_NO_TRUTH}" in text
    assert "0 of 1 truths outside" in text
