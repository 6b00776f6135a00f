"""A command's process imports only what it uses (issue 36: the suite starts ~200 gyrobench and
line station processes on 2 cores): `gyrobench list` (every driver's and procedure's entry) imports
no driver's library (pyvisa, pymodbus, pyserial) nor numba, the simulators take the rate table's and
the front end's protocol modules without their drivers, and a line station that opens a line
database already at the newest migration does not import alembic; `gyrobench show RUN` asks the
results store without h5py (the raw file's library, for `show FILE.h5` only).  Checked in a fresh
interpreter's sys.modules."""

from __future__ import annotations

import os
import subprocess
import sys

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: imported only by a process that builds the device (or compiled kernel, or migration) needing it
HEAVY = ("pyvisa", "pymodbus", "serial", "numba", "alembic", "h5py")


def _heavy_after(code: str, cwd: str | None = None) -> list[str]:
    """The HEAVY modules imported by running `code` in a fresh interpreter."""
    probe = code + f"\nimport sys\nprint(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    env = dict(os.environ, PYTHONPATH=_ROOT)
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True, cwd=cwd)
    return out.stdout.strip().splitlines()[-1].split() if out.stdout.strip() else []


def test_gyrobench_list_imports_no_device_library_nor_numba(tmp_path):
    code = ("import contextlib, io\nfrom bench.cli import main\nbuf = io.StringIO()\n"
            "with contextlib.redirect_stdout(buf):\n    assert main(['list', '--json']) == 0\n"
            "assert 'fpga-link' in buf.getvalue() and 'hrg-selfcal' in buf.getvalue()\n")
    assert _heavy_after(code, cwd=str(tmp_path)) == []


def test_the_simulators_protocol_modules_come_without_their_drivers():
    code = ("from drivers.rate_table import modbus_protocol, ascii_protocol, acutronic_protocol\n"
            "from drivers.frontend import commands\nimport drivers.fpga.spec, drivers.fpga.stream\n")
    assert _heavy_after(code) == []


def test_the_driver_packages_still_give_their_names():
    code = ("from drivers.rate_table import ModbusRateTable, AsciiRateTable, TableLimits\n"
            "from drivers.frontend import ScpiFrontEnd, FrontEndLimits\n"
            "from drivers.fpga.protocol import OUTPUT_MODES, MODE_FORCE_TO_REBALANCE\n"
            "assert OUTPUT_MODES['force-to-rebalance'] == MODE_FORCE_TO_REBALANCE == 1\n")
    assert {"pyvisa", "pymodbus", "numba"} <= set(_heavy_after(code))  # the probe sees an import on first use


def test_a_line_database_at_the_head_opens_without_alembic(tmp_path):
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    assert "alembic" in _heavy_after(f"from bench.line.db import LineDB\nLineDB({url!r}).close()\n")  # migrated
    assert _heavy_after(f"from bench.line.db import LineDB\nLineDB({url!r}).close()\n") == []


def test_the_line_heads_read_from_the_files_are_alembics():
    from alembic.script import ScriptDirectory

    from bench.line.db import MIGRATIONS, _alembic_config
    from bench.results.store import head_revision

    assert head_revision(MIGRATIONS / "versions") == ScriptDirectory.from_config(_alembic_config()).get_current_head()


def test_show_asks_the_store_without_the_raw_files_library(tmp_path):
    code = ("import contextlib, io\nfrom bench.cli import main\nerr = io.StringIO()\n"
            "with contextlib.redirect_stderr(err):\n"
            f"    assert main(['show', 'no-such-run', '--results', {str(tmp_path / 'results.sqlite')!r}]) == 2\n"
            "assert 'no-such-run' in err.getvalue()\n")
    assert _heavy_after(code, cwd=str(tmp_path)) == []
