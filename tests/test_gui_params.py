"""One parameter code for the command line, the engine and the window (issue 14, item 5): the same
table of typed texts through `gyrobench run --set`, `Param.convert` and the window's form gives
the same accept or refuse, the same value and the same message, word for word.  (The window
accepted `0x10` where the command line refused it while each had its own parsing.)"""

from __future__ import annotations

import math

import pytest

pytest.importorskip("pytestqt")

import bench.composition as composition
from bench.cli import main  # noqa: E402
from bench.devices import StationError
from bench.engine import procedure as procedure_module  # noqa: E402
from bench.engine.params import Param, ParamError  # noqa: E402
from bench.gui.param_form import ParameterForm  # noqa: E402
from procedures import find_procedure  # noqa: E402

NUMBERS = ["0x10", "1e3", "abc", "", " 5 ", "nan", "inf", "-inf", "-0", "+7", "1_000", "99999", "-5000",
           "1.5", "0b11", "010", "5 deg/s", "true"]
#: (procedure, parameter, typed texts); the truth for each text is written out below
CASES = [
    ("table-spin", "rate_dps", NUMBERS),
    ("mems-sweep", "n_points", NUMBERS),
    ("hrg-free-decay", "model", ["linear", " cubic ", "Cubic", "bogus", "", "1"]),
    ("hrg-damping", "compensate", ["true", "False", " on ", "0", "yes", "2", "", "maybe"]),
]
TRUTH = {  # (procedure, parameter, text) -> value accepted, or the message
    ("table-spin", "rate_dps", "0x10"): "rate_dps='0x10' is not a number",
    ("table-spin", "rate_dps", "1e3"): 1000.0,
    ("table-spin", "rate_dps", "abc"): "rate_dps='abc' is not a number",
    ("table-spin", "rate_dps", ""): "rate_dps='' is not a number",
    ("table-spin", "rate_dps", " 5 "): 5.0,
    ("table-spin", "rate_dps", "nan"): "rate_dps=nan is not a finite number",
    ("table-spin", "rate_dps", "inf"): "rate_dps=inf is not a finite number",
    ("table-spin", "rate_dps", "-inf"): "rate_dps=-inf is not a finite number",
    ("table-spin", "rate_dps", "-0"): -0.0,
    ("table-spin", "rate_dps", "+7"): 7.0,
    ("table-spin", "rate_dps", "1_000"): 1000.0,
    ("table-spin", "rate_dps", "99999"): "rate_dps=99999 deg/s is above the limit 1000 deg/s",
    ("table-spin", "rate_dps", "-5000"): "rate_dps=-5000 deg/s is below the limit -1000 deg/s",
    ("table-spin", "rate_dps", "1.5"): 1.5,
    ("table-spin", "rate_dps", "0b11"): "rate_dps='0b11' is not a number",
    ("table-spin", "rate_dps", "010"): 10.0,
    ("table-spin", "rate_dps", "5 deg/s"): "rate_dps='5 deg/s' is not a number",
    ("table-spin", "rate_dps", "true"): "rate_dps='true' is not a number",
    ("mems-sweep", "n_points", "0x10"): 16,
    ("mems-sweep", "n_points", "1e3"): "n_points='1e3' is not an integer",
    ("mems-sweep", "n_points", "abc"): "n_points='abc' is not an integer",
    ("mems-sweep", "n_points", ""): "n_points='' is not an integer",
    ("mems-sweep", "n_points", " 5 "): 5,
    ("mems-sweep", "n_points", "nan"): "n_points='nan' is not an integer",
    ("mems-sweep", "n_points", "inf"): "n_points='inf' is not an integer",
    ("mems-sweep", "n_points", "-inf"): "n_points='-inf' is not an integer",
    ("mems-sweep", "n_points", "-0"): "n_points=0 is below the limit 5",
    ("mems-sweep", "n_points", "+7"): 7,
    ("mems-sweep", "n_points", "1_000"): 1000,
    ("mems-sweep", "n_points", "99999"): "n_points=99999 is above the limit 2001",
    ("mems-sweep", "n_points", "-5000"): "n_points=-5000 is below the limit 5",
    ("mems-sweep", "n_points", "1.5"): "n_points='1.5' is not an integer",
    ("mems-sweep", "n_points", "0b11"): "n_points=3 is below the limit 5",
    ("mems-sweep", "n_points", "010"): 10,
    ("mems-sweep", "n_points", "5 deg/s"): "n_points='5 deg/s' is not an integer",
    ("mems-sweep", "n_points", "true"): "n_points='true' is not an integer",
    ("hrg-free-decay", "model", "linear"): "linear",
    ("hrg-free-decay", "model", " cubic "): "cubic",
    ("hrg-free-decay", "model", "Cubic"): "model='Cubic' is not one of linear, cubic, quintic",
    ("hrg-free-decay", "model", "bogus"): "model='bogus' is not one of linear, cubic, quintic",
    ("hrg-free-decay", "model", ""): "model='' is not one of linear, cubic, quintic",
    ("hrg-free-decay", "model", "1"): "model='1' is not one of linear, cubic, quintic",
    ("hrg-damping", "compensate", "true"): True,
    ("hrg-damping", "compensate", "False"): False,
    ("hrg-damping", "compensate", " on "): True,
    ("hrg-damping", "compensate", "0"): False,
    ("hrg-damping", "compensate", "yes"): True,
    ("hrg-damping", "compensate", "2"): "compensate='2' is not true or false",
    ("hrg-damping", "compensate", ""): "compensate='' is not true or false",
    ("hrg-damping", "compensate", "maybe"): "compensate='maybe' is not true or false",
}
ACCEPTED = "stopped after the parameters were accepted"


def _via_cli(procedure: str, name: str, text: str, capsys, monkeypatch) -> object:
    """`gyrobench run PROC --set name=text`, stopped before any station exists: the value the
    procedure received, or the one line the user read (without the `gyrobench: ` prefix)."""
    got: list[dict] = []
    real = procedure_module.resolve_params

    def spy(cls, given):
        got.append(real(cls, given))
        return got[-1]

    def no_station(*_a, **_k):
        raise StationError(ACCEPTED)

    monkeypatch.setattr(procedure_module, "resolve_params", spy)
    monkeypatch.setattr(composition, "load_station", no_station)
    code = main(["run", procedure, "--set", f"{name}={text}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("gyrobench: "), err
    message = err.removeprefix("gyrobench: ")
    return got[-1][name] if message == ACCEPTED else message


def _via_param(procedure: str, name: str, text: str) -> object:
    param: Param = find_procedure(procedure).param_specs()[name]
    try:
        return param.convert(text)
    except ParamError as exc:
        return str(exc)


def _via_form(form: ParameterForm, procedure: str, name: str, text: str) -> object:
    """The window's form as the window builds it (the procedure's Param objects); the text typed
    into the field (or, for a check box or a list, the nearest thing a user can pick)."""
    form.set_specs(tuple(find_procedure(procedure).param_specs().values()))
    field = form.fields[name]
    from PySide6.QtWidgets import QCheckBox, QComboBox

    if isinstance(field, QCheckBox | QComboBox):
        return None  # not typed: checked separately below
    form.set_value(name, text)
    if name in form.errors:
        return form.errors[name]
    return form.values()[name]


def _refused(outcome: object) -> bool:
    return isinstance(outcome, str) and "=" in outcome  # a message, not an accepted text value


def _same(a: object, b: object) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b and math.copysign(1, a) == math.copysign(1, b) or (math.isnan(a) and math.isnan(b))
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("procedure, name, texts", CASES, ids=[c[1] for c in CASES])
def test_cli_engine_and_window_agree_on_every_text(qtbot, capsys, monkeypatch, procedure, name, texts):
    form = ParameterForm()
    qtbot.addWidget(form)
    for text in texts:
        truth = TRUTH[(procedure, name, text)]
        param = _via_param(procedure, name, text)
        cli = _via_cli(procedure, name, text, capsys, monkeypatch)
        window = _via_form(form, procedure, name, text)
        assert _same(param, truth), (text, param, truth)
        assert _same(cli, truth), (text, cli, truth)
        if window is not None:
            assert _same(window, truth), (text, window, truth)
            assert form.is_valid() == (not _refused(truth)), text


def test_window_picks_only_what_the_engine_accepts(qtbot):
    """Lists and check boxes: every entry the window offers converts through the engine's Param to
    the declared choice, and the form's text for it is the `--set` text."""
    form = ParameterForm()
    qtbot.addWidget(form)
    for cls in (find_procedure("hrg-free-decay"), find_procedure("hrg-damping"), find_procedure("mems-sweep")):
        form.set_specs(tuple(cls.param_specs().values()))
        assert form.is_valid(), form.errors  # every default shows as valid text
        # and reads back as the engine's defaults, exactly (a nominal parameter's 0 = the nominal value)
        assert form.values() == {name: spec.convert(spec.default) for name, spec in cls.param_specs().items()}
        assert cls(form.values()).params == cls({}).params
        for p in form.specs:
            for choice in p.choices or ():
                form.set_value(p.name, choice)
                assert form.values()[p.name] == choice and form.text(p.name) == str(choice)
            if p.type is bool:
                for v in (True, False):
                    form.set_value(p.name, v)
                    assert form.values()[p.name] is v and p.convert(form.text(p.name)) is v
