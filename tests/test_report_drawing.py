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


def test_figures_drawn_by_two_processes_are_the_serial_ones_in_the_parts_order(tmp_path):
    marker = tmp_path / "child"
    assert fork_is_safe()
    serial = draw_parts(_parts(5), png=True, workers=1)
    forked = draw_parts(_parts(5), png=True, workers=2, in_child=lambda: marker.write_text("ran"))
    assert marker.read_text() == "ran"  # a second process was made (which parts it drew is not fixed)
    assert [f.key for f in forked] == [f.key for f in serial] == [f"fig{k}" for k in range(5)]
    for a, b in zip(serial, forked, strict=True):
        assert (a.title, a.note, a.table) == (b.title, b.note, b.table)
        assert _same_svg(a.svg()) == _same_svg(b.svg())
        assert a.png() == b.png()


def test_a_part_that_fails_raises_as_it_does_drawn_serially():
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
        assert not fork_is_safe()
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
