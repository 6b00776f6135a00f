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
