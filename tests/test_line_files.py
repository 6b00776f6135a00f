"""Sequence and limits files: the shipped ones load; a bad file is one message naming the key, the
value and what was allowed."""

import pytest

from bench.line import LineError
from bench.line.limits import load_limits
from bench.line.sequence import load_sequence


@pytest.mark.parametrize("name", ["eol-hrg", "eol-mems", "ci-mems", "ci-spin", "eol-hrg-thermal",
                                  "eol-hrg-thermal-soak"])
def test_shipped_sequences_load(name):
    seq = load_sequence(name)
    assert seq.name == name and seq.steps
    assert load_limits(seq.limits).limits


def test_eol_hrg_is_damping_with_compensation_then_free_decay():
    seq = load_sequence("eol-hrg")
    assert [s.procedure for s in seq.steps] == ["hrg-damping", "hrg-free-decay"]
    assert seq.steps[0].params["compensate"] is True
    assert seq.max_attempts == 2 and "MARGINAL" in seq.retest_on


def _write(tmp_path, text, name="f.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(("text", "words"), [
    ('[sequence]\nname="x"\n[[step]]\nprocedure="nope"\n', ["procedure='nope' is not one of", "mems-sweep"]),
    ('[sequence]\nname="x"\n[[step]]\nprocedure="table-spin"\n[step.params]\nhold_s=9999\n',
     ["[step.params]", "hold_s=9999", "above the limit 600"]),
    ('[sequence]\nname="x"\n[[step]]\nprocedure="table-spin"\n[step.params]\nspeed=1\n', ["speed"]),
    ('[sequence]\nname="x"\n', ["missing [[step]]"]),
    ('[sequence]\nname="x"\nstop_on_fail="maybe"\n[[step]]\nprocedure="table-spin"\n',
     ["stop_on_fail='maybe' is not true or false"]),
    ('[sequence]\nname="x"\n[retest]\nmax_attempts=50\n[[step]]\nprocedure="table-spin"\n',
     ["[retest]", "max_attempts=50 is above the limit 10"]),
    ('[sequence]\nname="x"\n[retest]\non=["LATER"]\n[[step]]\nprocedure="table-spin"\n', ["on='LATER'"]),
    ('[sequence]\nname="x"\nfoo=1\n[[step]]\nprocedure="table-spin"\n', ["foo: unknown key"]),
    ('[sequence\n', ["not valid TOML"]),
    ('[steps]\n', ["unknown table [steps]"]),
])
def test_bad_sequence_is_one_clear_message(tmp_path, text, words):
    with pytest.raises(LineError) as err:
        load_sequence(_write(tmp_path, text))
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path) in msg
    for w in words:
        assert w in msg, msg


@pytest.mark.parametrize(("text", "words"), [
    ('[product]\nname="p"\n[limits.nonsense]\nhigh=1\n', ["'nonsense' is not a measurement any procedure declares"]),
    ('[product]\nname="p"\n[limits.tau_s]\nlow=5\nhigh=1\n', ["low=5 is above high=1"]),
    ('[product]\nname="p"\n[limits.tau_s]\nrule="fuzzy"\nhigh=1\n', ["rule='fuzzy' is not one of guard-band, value"]),
    ('[product]\nname="p"\n[limits.tau_s]\nunit="ms"\nhigh=1\n', ["unit='ms' is not the declared unit ('s')"]),
    ('[product]\nname="p"\n[limits.tau_s]\nhigh="lots"\n', ["high='lots' is not a number"]),
    ('[product]\nname="p"\n[limits.tau_s]\n', ["missing key (low or high"]),
    ('[product]\nname="p"\n[limits.tau_s]\nhigh=4\nmarginal_high=3\n', ["belongs to rule = \"value\""]),
    ('[product]\nname="p"\n[limits.tau_s]\nhigh=4\nrule="value"\nmarginal_high=5\n', ["marginal_high=5 lies outside"]),
    ('[product]\nname="p"\n[limits.tau_s]\nhigh=4\nprocedure="mems-sweep"\n', ["does not declare 'tau_s'"]),
    ('[limits.tau_s]\nhigh=4\n', ["missing table [product]"]),
])
def test_bad_limits_is_one_clear_message(tmp_path, text, words):
    with pytest.raises(LineError) as err:
        load_limits(_write(tmp_path, text))
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


def test_missing_file_names_the_shipped_ones():
    shipped = "ci-mems, ci-spin, eol-hrg-thermal-soak, eol-hrg-thermal, eol-hrg, eol-mems"
    with pytest.raises(LineError, match=f"shipped: {shipped}"):
        load_sequence("no-such-sequence")
