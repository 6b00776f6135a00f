"""Loading the procedures stays light (issue 36): a line station's start (its limits, which read
every procedure's declared measurements) and `gyrobench list` import no analysis library a run of
another procedure needs - allantools, scipy.stats, scipy.optimize, scipy.integrate (~1 s of CPU in
every station process) - and no WeasyPrint. Checked in a fresh interpreter's sys.modules."""

from __future__ import annotations

import os
import subprocess
import sys

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: imported on first use by the analysis that needs them, never by loading a procedure
HEAVY = ("allantools", "scipy.stats", "scipy.optimize", "scipy.integrate", "weasyprint")


def _heavy_after(code: str) -> list[str]:
    """The HEAVY modules imported by running `code` in a fresh interpreter."""
    probe = code + f"\nimport sys\nprint(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    env = dict(os.environ, PYTHONPATH=_ROOT)
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_a_line_stations_start_imports_no_analysis_library():
    code = ("import bench.line.stations\n"
            "from bench.line.limits import load_limits\n"
            "from bench.line.sequence import load_sequence\n"
            "from bench.line.run import LineContext, run_unit\n"
            "from procedures import all_procedures\n"
            "assert load_limits(load_sequence('ci-spin').limits).limits\n"
            "assert {'table-spin', 'cvg-allan', 'hrg-free-decay'} <= set(all_procedures())\n")
    assert _heavy_after(code) == []


def test_the_analysis_modules_import_their_libraries_on_first_use():
    code = ("import bench.analysis.allan, bench.analysis.selfcal, bench.analysis.thermal_fit\n"
            "import bench.analysis.thermal_ramp, bench.analysis.maslov, bench.analysis.free_decay_oe\n"
            "import bench.line.certificate\n")
    assert _heavy_after(code) == []
    used = _heavy_after("from bench.analysis.thermal_fit import birge_half_widths\nimport numpy as np\n"
                        "birge_half_widths(np.eye(2), 4.0, 2)\n")
    assert "scipy.stats" in used  # the probe sees an import made on first use
