"""A report's figures drawn by two processes at once (bench.reporting.drawing, issue 36): the same
figures in the same order as drawn serially, a failing part raises as it does serially, no fork
while another thread runs, and the PDF's PNG as RGB with Agg's pixels."""

from __future__ import annotations

import io
import re
import sys
import threading

import numpy as np
import pytest

from bench.figures import PRINT_DPI, ReportFigure, new_figure, plot_record
from bench.reporting.drawing import draw_parts, fork_is_safe

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the forked drawing is Linux's")


def _figure(k: int) -> list[ReportFigure]:
    """A small figure whose content depends on k (a record long enough to be drawn as an envelope)."""
    fig, ax = new_figure(2, 1, height_in=2.5, sharex=True)
    t = np.linspace(0.0, 10.0, 5001)
    plot_record(ax[0, 0], t, np.sin((k + 1) * t), color="C0")
    ax[1, 0].plot(t[:50], np.cos(t[:50]) * k, ".")
    ax[0, 0].set_ylabel("y (1)")
    ax[1, 0].set_xlabel("t (s)")
    return [ReportFigure(f"fig{k}", f"Figure {k}", fig, f"note {k}", (["a"], [[str(k)]]))]


def _parts(n: int) -> list:
    return [lambda k=k: _figure(k) for k in range(n)]


def _same_svg(svg: str) -> str:
    """An SVG without its random element ids (matplotlib salts them per drawing)."""
    return re.sub(r"(id=\"|#|url\(#)[A-Za-z0-9_-]+", r"\1ID", svg)


_IN_A_FRESH_PROCESS = """
import json, sys
from pathlib import Path
from bench.reporting.drawing import draw_parts, fork_is_safe
from tests.test_report_drawing import _parts, _same_svg
marker = Path(sys.argv[1])
out = {"safe": fork_is_safe()}
serial = draw_parts(_parts(5), png=True, workers=1)
forked = draw_parts(_parts(5), png=True, workers=2, in_child=lambda: marker.write_text("ran"))
out["child"] = marker.is_file()
out["keys"] = [[f.key for f in serial], [f.key for f in forked]]
out["same"] = all((a.title, a.note, a.table, _same_svg(a.svg()), a.png()) == (b.title, b.note, b.table,
                  _same_svg(b.svg()), b.png()) for a, b in zip(serial, forked, strict=True))
def broken():
    raise ValueError("no such stream")
parts = _parts(3)
parts.insert(1, broken)
try:
    draw_parts(parts, workers=2, in_child=lambda: marker.write_text("ran again"))
except ValueError as exc:
    out["raised"] = str(exc)
out["child_again"] = marker.read_text() == "ran again"
print(json.dumps(out))
"""


def test_figures_drawn_by_two_processes_are_the_serial_ones_and_a_failing_part_raises(tmp_path):
    """In a process of its own (a test worker may run other threads, and then nothing forks): the
    figures in the parts' order, the same as drawn serially, and a part that fails raises its error
    as it does drawn serially, whichever process took it."""
    import json
    import os
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    res = subprocess.run([sys.executable, "-c", _IN_A_FRESH_PROCESS, str(tmp_path / "child")], capture_output=True,
                         text=True, cwd=root, env={**os.environ, "PYTHONPATH": str(root)}, timeout=300)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.splitlines()[-1])
    assert out["safe"] and out["child"] and out["child_again"]  # a second process was made each time
    assert out["keys"] == [[f"fig{k}" for k in range(5)]] * 2 and out["same"]
    assert out["raised"] == "no such stream"


def test_a_part_that_fails_raises_here_as_well():
    def broken() -> list[ReportFigure]:
        raise ValueError("no such stream")

    parts = _parts(3)
    parts.insert(1, broken)
    with pytest.raises(ValueError, match="no such stream"):
        draw_parts(parts, workers=1)
    with pytest.raises(ValueError, match="no such stream"):
        draw_parts(parts, workers=2)


def test_no_fork_while_another_thread_runs(tmp_path):
    """A window's process has other threads: a fork would copy none of them and maybe a lock they
    hold, so the figures are drawn here."""
    marker = tmp_path / "child"
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not fork_is_safe()  # (a test worker's own threads may already say so)
        drawn = draw_parts(_parts(3), workers=2, in_child=lambda: marker.write_text("ran"))
    finally:
        stop.set()
        other.join()
    assert [f.key for f in drawn] == ["fig0", "fig1", "fig2"] and not marker.exists()


def test_the_pdf_png_is_rgb_with_the_pixels_agg_draws():
    """No alpha channel (WeasyPrint would split it into a second image): the figure's opaque
    pixels, as Agg's own PNG has them."""
    from PIL import Image

    fig = _figure(2)[0]
    fig.svg()
    ref = io.BytesIO()
    fig.figure.savefig(ref, format="png", dpi=PRINT_DPI)
    agg = np.asarray(Image.open(ref))
    png = Image.open(io.BytesIO(fig.png()))
    assert png.mode == "RGB" and png.size == (agg.shape[1], agg.shape[0])
    assert (agg[..., 3] == 255).all() and np.array_equal(np.asarray(png), agg[..., :3])
