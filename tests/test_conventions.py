"""Conventions every registered procedure, station file and driver keeps, checked over all of them
(as PyMeasure's test over all instruments does), so a new one that breaks them fails here:

* procedures: every module imports; a docstring, a kebab-case name, the device roles it needs;
  every step titled; every parameter documented, numeric ones with limits, a name with a unit
  suffix (`_s`, `_hz`, `_dps`, ...) carrying that unit and a unit shown in the name; defaults valid;
* station files under bench/stations: each loads, is checked, names itself by its file;
* drivers: every config key documented, numeric keys with limits and units as above, each value
  checked by bench.validation in its words; every SCPI property and FPGA register likewise; rate
  table models implement only the transport (the limits are checked once, in the base class).
"""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
import re
from types import SimpleNamespace

import pytest

import procedures
from bench.devices import DRIVERS, ROLES, Key, StationError
from bench.engine.demands import KINDS, Demand
from bench.engine.params import Param
from bench.station_config import SIM_KEYS, STATION_KEYS, builtin_stations, load_config
from bench.validation import LimitError, fmt_value
from procedures import all_procedures

#: name suffix -> the unit a value so named carries (longest suffix first)
SUFFIX_UNITS = {
    "_dph_s_per_hz": "deg/h/(Hz/s)",
    "_dph_per_hz": "deg/h/Hz",
    "_ppm_per_hz": "ppm/Hz",
    "_degc_per_min": "degC/min",
    "_ppm_per_min": "ppm/min",
    "_per_s": "1/s",
    "_dps2": "deg/s^2",
    "_dps": "deg/s",
    "_dph": "deg/h",
    "_deg": "deg",
    "_hz": "Hz",
    "_v": "V",
    "_s": "s",
    "_degc": "degC",
}
BUILTIN_PROCEDURES = {"table-spin", "hrg-damping", "hrg-free-decay", "mems-sweep"}
BUILTIN_STATIONS = {"sim-hrg", "sim-mems"}


def _suffix_unit(name: str) -> str | None:
    low = name.lower()
    for suffix, unit in SUFFIX_UNITS.items():
        if low.endswith(suffix):
            return unit
    return None


def _unit_problems(name: str, unit: str, numeric: bool) -> list[str]:
    """A name with a unit suffix carries that unit; a number with a unit has it in its name."""
    expected = _suffix_unit(name)
    if expected is not None and unit != expected:
        return [f"{name}: its name says {expected!r}, its unit is {unit!r}"]
    if expected is None and numeric and unit:
        return [f"{name}: a value in {unit!r} needs the unit in its name"]
    return []


# --- procedures ----------------------------------------------------------------------------------
def test_every_procedure_module_imports_and_is_registered():
    """`all_procedures` skips a module that fails to import (one broken file must not hide the
    others from the window); here, none may fail."""
    for info in pkgutil.walk_packages(procedures.__path__, prefix="procedures."):
        importlib.import_module(info.name)
    assert BUILTIN_PROCEDURES <= set(all_procedures())


@pytest.mark.parametrize("name", sorted(all_procedures()))
def test_a_procedure_found_by_name_is_the_registered_one(name):
    """`procedure_named` (a run imports its own procedure's module only) finds what the registry
    has, its own module's (in the package or its examples) or, failing that, any module's."""
    from procedures import find_procedure, procedure_named

    assert procedure_named(name) is all_procedures()[name]
    assert find_procedure(name) is all_procedures()[name]


def test_an_unknown_procedure_name_is_none_and_find_procedure_lists_the_known():
    from procedures import ProcedureNotFound, find_procedure, procedure_named

    for name in ("no-such-procedure", "", "hrg-damping.x", "../etc", "__init__", "examples"):
        assert procedure_named(name) is None
    with pytest.raises(ProcedureNotFound, match="known: .*hrg-damping"):
        find_procedure("no-such-procedure")


@pytest.mark.parametrize("name", sorted(all_procedures()))
def test_procedure_conventions(name):
    cls = all_procedures()[name]
    problems: list[str] = []
    if not (cls.__doc__ or "").strip():
        problems.append("no docstring")
    if not re.fullmatch(r"[a-z][a-z0-9]*(-[a-z0-9]+)*", cls.name):
        problems.append(f"name {cls.name!r} is not kebab-case")
    if not cls.requires or not set(cls.requires) <= set(ROLES):
        problems.append(f"requires={cls.requires!r}: declare the device roles needed, from {ROLES}")
    kinds = getattr(cls, "kinds", ())
    if not isinstance(kinds, tuple) or not set(kinds) <= set(KINDS):
        problems.append(f"kinds={kinds!r}: a tuple of kinds from {KINDS} (empty: any gyro)")
    for d in cls({}).demands():  # what the defaults ask of the station, checked before anything moves
        if not isinstance(d, Demand) or d.role not in cls.requires:
            problems.append(f"demand {d!r}: a Demand on one of the required roles {cls.requires}")
        elif not d.limit_key.startswith("max_") or not d.unit:
            problems.append(f"demand {d.text()}: limited by a station max_* key, with a unit")
    steps = cls.step_specs()
    if not steps:
        problems.append("no steps")
    problems += [f"step {m}: no title" for m, title in steps if not str(title).strip()]
    params = cls.param_specs()
    for pname, p in params.items():
        assert isinstance(p, Param)
        numeric = p.type in (int, float) and p.choices is None
        if not p.doc.strip():
            problems.append(f"{pname}: no doc")
        if numeric and (p.low is None or p.high is None):
            problems.append(f"{pname}: a number needs low and high limits")
        if p.choices is not None and p.default not in p.choices:
            problems.append(f"{pname}: default {p.default!r} is not one of its choices")
        if p.type is bool and p.unit:
            problems.append(f"{pname}: true/false with a unit {p.unit!r}")
        problems += _unit_problems(pname, p.unit, numeric)
    assert not problems, f"{name}: " + "; ".join(problems)
    assert set(cls({}).params) == set(params)  # every default passes its own check


#: a gyro kind's simulated station preset (its truth is `ResonatorParams.truth()`, as the station's)
KIND_PRESETS = {"hrg": "hrg", "mems-ring": "mems"}
#: the slow-variable model's coefficients under the paper's names (their `_s` means sine, not seconds)
PAPER_COEFFICIENTS = {"b_s", "h_s"}


@pytest.mark.parametrize("name", sorted(all_procedures()))
def test_declared_measurements_are_consistent(name):
    """Every declared measurement: a unique name, a unit string ('' = dimensionless) agreeing with
    its name's unit suffix (an `_ee` twin named as its base), a doc, a condition that evaluates on
    the default parameters, and a truth rule that resolves to a finite number on a simulated station
    of each kind the procedure is written for."""
    from bench.engine import Measurement
    from simulators.physics.params import preset

    cls = all_procedures()[name]
    decls = cls.measurements
    assert decls, f"{name}: declares no measurements"
    names = [m.name for m in decls]
    assert len(names) == len(set(names)), f"{name}: a measurement declared twice"
    proc = cls({})
    problems: list[str] = []
    for m in decls:
        assert isinstance(m, Measurement)
        if not isinstance(m.unit, str):
            problems.append(f"{m.name}: unit {m.unit!r} is not a string")
        if not m.doc.strip():
            problems.append(f"{m.name}: no doc")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", m.name):
            problems.append(f"{m.name}: not a plain identifier")
        base = m.name.removesuffix("_ee")
        expected = None if base.removeprefix("maslov_") in PAPER_COEFFICIENTS else _suffix_unit(base)
        if expected is not None and m.unit != expected:
            problems.append(f"{m.name}: its name says {expected!r}, its unit is {m.unit!r}")
        if m.when is not None and not m.when_doc:
            problems.append(f"{m.name}: a condition without when_doc (what `gyrobench list` shows)")
        m.applies(proc)  # raises if the condition cannot be evaluated
        m.limits_for(proc)
        for kind in cls.kinds or tuple(KIND_PRESETS):
            if m.truth is None:
                continue
            value = m.truth_of(preset(KIND_PRESETS[kind]).truth())
            if value is None or not math.isfinite(value):
                problems.append(f"{m.name}: truth rule {m.truth!r} does not resolve on a simulated {kind}")
    assert not problems, f"{name}: " + "; ".join(problems)


# --- station files -------------------------------------------------------------------------------
def test_every_station_file_loads_and_names_itself():
    stations = builtin_stations()
    assert BUILTIN_STATIONS <= set(stations)
    for stem, path in stations.items():
        config = load_config(path)  # checked by bench.validation through Key.check; raises if not
        assert config.id == stem, f"{path}: id {config.id!r} differs from the file name"
        for role, cfg in config.devices.items():
            spec = DRIVERS[cfg["driver"]]
            kind = role if role in ROLES else "instrument"  # an instrument goes under a name of its own
            assert spec.role == kind, f"{path}: [devices.{role}] uses {spec.name}, a {spec.role} driver"
            assert set(cfg) - {"role"} <= set(spec.keys), f"{path}: [devices.{role}] keys beyond the spec"
    text = "".join(p.read_text() for p in stations.values())
    assert "\t" not in text


# --- config keys ---------------------------------------------------------------------------------
def _all_keys() -> list[tuple[str, str, Key]]:
    out = [("[station]", n, k) for n, k in STATION_KEYS.items()]
    out += [("[simulation]", n, k) for n, k in SIM_KEYS.items()]
    for spec in DRIVERS.values():
        out += [(f"[{spec.name}]", n, k) for n, k in spec.keys.items()]
    return out


def test_every_driver_spec_is_complete():
    assert {"modbus-table", "ascii-table", "scpi-frontend", "fpga-link"} <= set(DRIVERS)
    for spec in DRIVERS.values():
        assert spec.doc.strip() and spec.role in (*ROLES, "instrument") and callable(spec.build), spec.name
        assert spec.keys["driver"].required, f"{spec.name}: `driver` names the model and is required"


@pytest.mark.parametrize("where, name, key", _all_keys(), ids=[f"{w}{n}" for w, n, _ in _all_keys()])
def test_every_config_key_is_documented_and_checked_in_the_shared_words(where, name, key):
    numeric = key.type in (int, float) and key.choices is None
    assert name == "driver" or key.doc.strip(), f"{where} {name}: no doc"
    if numeric:
        assert key.low is not None and key.high is not None, f"{where} {name}: a number needs limits"
    assert not _unit_problems(name, key.unit, numeric), _unit_problems(name, key.unit, numeric)
    if not key.required:
        assert key.check(where, name, key.default) == key.default  # the default is valid
    kind_word = {float: "a number", int: "an integer", str: "text", bool: "true or false", dict: "a table"}[key.type]
    with pytest.raises(StationError) as bad_kind:
        key.check(where, name, ["x"])
    assert str(bad_kind.value) == f"{where} {name}=['x'] is not {kind_word}"
    if numeric:
        too_high = key.high + max(1, abs(key.high))
        with pytest.raises(StationError) as high:
            key.check(where, name, key.type(too_high))
        expected = f"{where} {name}={fmt_value(key.type(too_high), key.unit)} is above the limit "
        assert str(high.value) == expected + fmt_value(key.type(key.high), key.unit)
    if key.choices is not None:
        with pytest.raises(StationError, match=re.escape(f"{name}='bogus' is not one of")):
            key.check(where, name, "bogus")


# --- driver properties -----------------------------------------------------------------------------
def _controls():
    from drivers.frontend import driver as fe
    from drivers.frontend.properties import control

    out = []
    for cls_name, cls in inspect.getmembers(fe, inspect.isclass):
        if cls.__module__ != fe.__name__:
            continue
        out += [(cls_name, name, c) for name, c in vars(cls).items() if isinstance(c, control)]
    return out


def _owner(cls_name: str):
    from drivers.frontend.driver import FrontEndLimits

    limits = FrontEndLimits()
    if cls_name == "FrontEndChannel":
        return SimpleNamespace(parent=SimpleNamespace(limits=limits), label="ch1", channel_id=1)
    return SimpleNamespace(limits=limits, label="", channel_id="")


@pytest.mark.parametrize("cls_name, name, prop", _controls(), ids=[f"{c}.{n}" for c, n, _ in _controls()])
def test_every_scpi_property_is_documented_and_checked_in_the_shared_words(cls_name, name, prop):
    from drivers.frontend import properties as pr

    assert (prop.__doc__ or "").strip(), f"{name}: no doc"
    numeric = prop.validator in (pr.strict_range, pr.strict_int_range, pr.strict_discrete_set)
    assert not _unit_problems(name, prop.unit, numeric), _unit_problems(name, prop.unit, numeric)
    if prop.set_cmd is None:
        return
    assert prop.validator in (pr.strict_range, pr.strict_int_range, pr.strict_discrete_set, pr.boolean)
    owner = _owner(cls_name)
    qual = prop.qualified_name(owner)
    allowed = prop.allowed(owner)
    if prop.validator is pr.boolean:
        bad, words = 1, f"{qual}=1 is not true or false"
    elif prop.validator is pr.strict_discrete_set:
        bad = max(allowed) * 3
        words = f"{qual}={fmt_value(bad)} is not one of " + ", ".join(map(str, allowed))
    else:
        lo, hi = allowed
        bad = hi + max(1, abs(hi))
        words = f"{qual}={fmt_value(bad, prop.unit)} is above the limit {fmt_value(hi, prop.unit)}"
    with pytest.raises(LimitError) as err:
        prop.validate(owner, bad)
    assert str(err.value) == words and err.value.name == qual


def test_every_writable_fpga_register_is_documented_and_checked_in_the_shared_words():
    from drivers.fpga import protocol as p
    from drivers.fpga.link import _check_register

    for reg in p.REGISTERS:
        assert reg.doc.strip(), reg.name
        # the register map's names are the device's: only a unit suffix must match (FM_RATE_HZ in Hz)
        assert not _unit_problems(reg.name, reg.unit, False), _unit_problems(reg.name, reg.unit, False)
        if reg.access == "ro":
            continue
        bad = reg.hi + max(1, abs(reg.hi))
        with pytest.raises(LimitError) as err:
            _check_register(reg, bad)
        shown = fmt_value(int(bad) if reg.kind == "u" else float(bad), reg.unit)
        assert str(err.value) == f"{reg.name}={shown} is above the limit {fmt_value(reg.hi, reg.unit)}"


def test_rate_table_models_implement_only_the_transport():
    """The checked commands (limits, then the write) live once in RateTable; a model that
    overrode one could bypass the limits."""
    from drivers.rate_table import ascii_driver, modbus_driver
    from drivers.rate_table.base import RateTable

    checked = ("set_rate", "move_to", "stop", "_check_rate", "_check_accel", "safe_state")
    models = [c for m in (ascii_driver, modbus_driver) for c in vars(m).values()
              if inspect.isclass(c) and issubclass(c, RateTable) and c is not RateTable]
    assert len(models) >= 2
    for model in models:
        assert not [name for name in checked if name in vars(model)], model.__name__


def test_the_reference_lists_the_declared_measurements():
    """The docs site's procedures page (generated at build time by docs/reference_pages.py) holds
    every registered procedure's measurement table as docs/measurement_tables.py makes it."""
    import sys
    from pathlib import Path

    from procedures import all_procedures

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "docs"))
    try:
        from measurement_tables import table
        from reference_pages import procedures_page
    finally:
        sys.path.remove(str(root / "docs"))
    page = procedures_page()
    for name, cls in all_procedures().items():
        assert f"## `{name}`" in page and table(cls) in page, name
