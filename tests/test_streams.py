"""Streams with a schema: each stream is announced (StreamDeclared) before its first block, the
raw file stores the declaration (a unit for every column of every dataset, a legend for every
coded column, readable by the stock `h5dump`), and columns are read by name."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import h5py
import numpy as np
import pytest

from bench.engine import events as ev
from bench.streams import Column, StreamSchema, declare, schema_of, unit_from_name

SHORT_DAMPING = {"rate_dps": 20.0, "record_s": 2.0, "stream_hz": 200.0, "verify_rate_dps": 4.0,
                 "verify_s": 8.0, "verify_settle_s": 0.5, "drift_block_s": 0.5}


@pytest.fixture(scope="module")
def damping_run(tmp_path_factory):
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from procedures.hrg_damping import HrgDamping

    tmp = tmp_path_factory.mktemp("streams")
    station = SimStation("sim-hrg", seed=0).open()
    events: list = []
    try:
        runner = Runner(station, runs_dir=tmp / "runs")
        runner.bus.subscribe(events.append)
        record = runner.run(HrgDamping, SHORT_DAMPING)
    finally:
        station.close()
    return record, events


def test_schema_by_name():
    s = StreamSchema("t_demo", "test", (Column("t_s", "s"), Column("v", "V", "f4"), Column("k", "", "i1")))
    block = np.arange(12.0).reshape(4, 3)
    assert s.names == ("t_s", "v", "k") and s.units == ("s", "V", "1")
    np.testing.assert_array_equal(s.column(block, "v"), [1, 4, 7, 10])
    np.testing.assert_array_equal(s.columns_of(block, "k", "t_s"), block[:, [2, 0]])
    with pytest.raises(KeyError, match="no column 'x'"):
        s.index("x")
    with pytest.raises(ValueError, match="repeats"):
        StreamSchema("t_bad", "test", (Column("a", "s"), Column("a", "s")))
    declare(s)
    with pytest.raises(ValueError, match="declared twice"):
        declare(StreamSchema("t_demo", "other", (Column("t_s", "s"),)))
    with pytest.raises(KeyError, match="not declared"):
        schema_of("no_such_stream")
    assert [unit_from_name(n) for n in ("tau_s", "drift_dph", "f0_hz", "energy")] == ["s", "deg/h", "Hz", "1"]
    np.testing.assert_array_equal(s.row(k=2, t_s=0.5, v=1.5), [0.5, 1.5, 2.0])  # a row built by name
    with pytest.raises(ValueError, match=r"misses \['v'\]"):
        s.row(t_s=0.5, k=2)


def test_every_stream_is_declared_before_its_first_block(damping_run):
    record, events = damping_run
    assert record.outcome != "ERROR", record.end_reason
    declared: dict[str, StreamSchema] = {}
    for e in events:
        if isinstance(e, ev.StreamDeclared):
            assert e.schema.name not in declared, f"{e.schema.name} declared twice"
            declared[e.schema.name] = e.schema
        elif isinstance(e, ev.SampleBlock):
            assert e.stream in declared, f"a block of {e.stream!r} before its declaration"
            assert e.columns == declared[e.stream].names
    assert {"fpga", "table", "damping_windows", "damping_reference"} <= set(declared)


def test_every_column_of_every_dataset_has_units_and_coded_columns_a_legend(damping_run):
    from procedures.hrg_damping import HrgDamping

    record, _ = damping_run
    seen = {"streams": 0, "parameters": 0, "fits": 0}

    def visit(name: str, obj) -> None:
        if not isinstance(obj, h5py.Dataset) or name in ("log", "measurements"):
            return
        top = name.split("/")[0]
        units = obj.attrs.get("units")
        assert units is not None, f"/{name} has no units"
        if top == "streams":
            cols = json.loads(obj.attrs["columns"])
            assert len(units) == len(cols) == obj.shape[1], f"/{name}: {len(units)} units for {len(cols)} columns"
            assert all(isinstance(u, (str, bytes)) and u for u in units)
        seen[top] += 1

    with h5py.File(record.raw_file, "r") as f:
        f.visititems(visit)
        win = f["streams/damping_windows"]
        # the legend is an HDF5 enum type (not a JSON attribute): /legends/<stream>/<column>
        assert "legend_kind" not in win.attrs
        assert h5py.check_enum_dtype(f["legends/damping_windows/kind"].dtype) == {
            "decay": 0, "verify_off": 1, "verify_on": 2}
        assert [u.decode() if isinstance(u, bytes) else u for u in win.attrs["units"]] == ["1", "s", "s"]
        fpga = f["streams/fpga"]
        assert list(fpga.attrs["units"])[:3] == ["1", "s", "1"] and fpga.attrs["source"] == "fpga"
        assert f["parameters/rate_dps"].attrs["units"] == "deg/s" and f["parameters/rate_dps"][()] == 20.0
        assert f["parameters/fit_method"].attrs["units"] == "1"
    assert seen["streams"] >= 4 and seen["parameters"] == len(HrgDamping.param_specs()) and seen["fits"] > 0


def test_h5dump_shows_units_and_legends(damping_run):
    record, _ = damping_run
    h5dump = shutil.which("h5dump")
    if h5dump is None:
        if os.environ.get("CI") == "true":
            pytest.fail("h5dump (the HDF5 tools) is missing on CI")
        pytest.skip("h5dump is not installed")
    out = subprocess.run([h5dump, "-A", record.raw_file], capture_output=True, text=True, timeout=60, check=True).stdout
    assert 'DATATYPE "kind"' in out and "H5T_ENUM" in out and '"verify_off"' in out
    assert 'ATTRIBUTE "units"' in out and '"deg/s"' in out


def test_reader_and_report_show_declared_units_and_meanings(damping_run):
    from bench.figures import stream_figure
    from bench.recorder import open_run

    record, _ = damping_run
    with open_run(record.raw_file) as d:
        assert d.units("damping_windows") == {"kind": "1", "t_start_s": "s", "t_end_s": "s"}
        assert d.legends("damping_windows") == {"kind": {0: "decay", 1: "verify_off", 2: "verify_on"}}
        assert d.units("table")["rate_dps"] == "deg/s" and d.legends("fpga") == {}
        fig = stream_figure(d, "fpga", ["freq_ctrl", "quad_ctrl"])
    assert [a.get_ylabel() for a in fig.figure.axes] == ["frequency control (Hz)", "quadrature control (1/s)"]


def test_legends_of_a_file_written_before_enum_types_are_still_read(tmp_path):
    """An older raw file kept each legend as a `legend_<column>` JSON attribute: the reader and
    the window's replay still find it; a new file's legend is the enum type alone."""
    from bench.recorder import open_run, stored_legends
    from bench.streams import schema_from_attrs

    path = tmp_path / "old.h5"
    with h5py.File(path, "w") as f:
        for name in ("log", "measurements", "fits"):
            f.create_group(name) if name == "fits" else f.create_dataset(name, shape=(0,), dtype=h5py.string_dtype())
        ds = f.create_group("streams").create_dataset("sweep_old", data=np.array([[0.0, 1.0], [1.0, -1.0]]))
        ds.attrs["columns"] = json.dumps(["t_s", "direction"])
        ds.attrs["units"] = ["s", "1"]
        ds.attrs["legend_direction"] = json.dumps({"1": "up", "-1": "down"})
    with open_run(path) as d:
        assert d.legends("sweep_old") == {"direction": {1: "up", -1: "down"}}
        legends = stored_legends(d.f, "sweep_old", d.f["streams/sweep_old"].attrs)
        schema = schema_from_attrs("sweep_old", ("t_s", "direction"), d.f["streams/sweep_old"].attrs, legends)
    assert schema is not None and dict(schema.columns[1].legend) == {-1: "down", 1: "up"}
