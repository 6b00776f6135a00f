"""The one-pass measured layout (bench.figure_layout) places a report's axes where matplotlib's
constrained layout does (within 0.03 in: the page looks the same) and keeps every text inside the
figure, for the kinds of grid the hrg-damping report draws and for ticks with an offset text."""

from __future__ import annotations

import io

import numpy as np
import pytest

from bench.figures import new_figure


def _stacked(layout: str):
    fig, ax = new_figure(2, 1, height_in=3.6, sharex=True, gridspec_kw={"height_ratios": [3, 1.3]}, layout=layout)
    t = np.linspace(0.0, 900.0, 500)
    ax[0, 0].plot(t, -t / 150.0, label="measured")
    ax[0, 0].legend(loc="best")
    ax[0, 0].set_ylabel("ln E (1)")
    ax[1, 0].plot(t, 1e-3 * np.sin(t))
    ax[1, 0].set_ylabel("residual ln E (1)")
    ax[1, 0].set_xlabel("time t (s)")
    return fig


def _two_columns_with_titles_and_a_legend_above(layout: str):
    fig, ax = new_figure(2, 2, height_in=4.6, sharex=True, sharey="row", gridspec_kw={"height_ratios": [3, 1.3]},
                         layout=layout)
    th = np.linspace(-45.0, 45.0, 90)
    for j, name in enumerate(("before", "after")):
        ax[0, j].plot(th, 30 * np.cos(np.radians(4 * th)), ".", label="measured (per block)")
        ax[0, j].plot(th, 29 * np.cos(np.radians(4 * th)), label="fit of the angle record: mean + 4θ")
        ax[0, j].set_title(f"compensation ({name})")
        ax[1, j].plot(th, np.sin(th), ".")
        ax[1, j].set_xlabel("wave angle θ, folded (deg)")
    ax[0, 0].set_ylabel("drift, output-referred (deg/h)")
    ax[1, 0].set_ylabel("measured − model (deg/h)")
    handles, labels = ax[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=2)
    return fig


def _four_rows_with_offset_texts(layout: str):
    fig, ax = new_figure(4, 1, height_in=5.1, sharex=True, layout=layout)
    t = np.linspace(0.0, 1100.0, 800)
    for i, scale in enumerate((1.0, 1e-6, 1e6, 1.0)):
        ax[i, 0].plot(t, scale * (1000.0 + np.sin(t / 50.0)) if i == 3 else scale * np.sin(t / 50.0))
        ax[i, 0].set_ylabel(f"c{i}\n(1)")
    ax[-1, 0].set_xlabel("time t (s)")
    return fig


BUILDERS = [_stacked, _two_columns_with_titles_and_a_legend_above, _four_rows_with_offset_texts]
#: the hrg-damping report's grids; an offset text ("1e-6") gets more room than the constrained layout
#: gives it (checked below for texts inside the figure and clear of the other axes only)
SAME_AS_CONSTRAINED = [_stacked, _two_columns_with_titles_and_a_legend_above]
TOLERANCE_IN = 0.03


def _drawn(fig):
    fig.savefig(io.StringIO(), format="svg")
    return fig


@pytest.mark.parametrize("build", SAME_AS_CONSTRAINED, ids=lambda b: b.__name__)
def test_axes_sit_where_the_constrained_layout_puts_them(build) -> None:
    ours, theirs = _drawn(build("measured")), _drawn(build("constrained"))
    w, h = ours.get_size_inches()
    for a, b in zip(ours.axes, theirs.axes, strict=True):
        got = np.array(a.get_position().extents) * [w, h, w, h]
        want = np.array(b.get_position().extents) * [w, h, w, h]
        assert np.abs(got - want).max() < TOLERANCE_IN, (got, want)
    for a, b in zip(ours.legends, theirs.legends, strict=True):
        renderer = ours._get_renderer()
        got, want = a.get_window_extent(renderer).extents, b.get_window_extent(theirs._get_renderer()).extents
        assert np.abs(got - want).max() / ours.dpi < TOLERANCE_IN


@pytest.mark.parametrize("build", BUILDERS, ids=lambda b: b.__name__)
def test_every_text_is_inside_the_figure(build) -> None:
    fig = _drawn(build("measured"))
    renderer = fig._get_renderer()
    box = fig.bbox
    for ax in fig.axes:
        bb = ax.get_tightbbox(renderer)
        assert bb.x0 >= box.x0 - 0.5 and bb.y0 >= box.y0 - 0.5, (bb, box)
        assert bb.x1 <= box.x1 + 0.5 and bb.y1 <= box.y1 + 0.5, (bb, box)
        texts = [ax.xaxis.label, ax.yaxis.label, ax.title, ax.yaxis.offsetText, ax.xaxis.offsetText,
                 *ax.get_xticklabels(), *ax.get_yticklabels()]
        for text in (t for t in texts if t.get_visible() and t.get_text()):
            tb = text.get_window_extent(renderer)
            for other in fig.axes:  # an axes' labels, ticks and offset text stay clear of the other axes' frames
                if other is not ax:
                    frame = other.get_window_extent(renderer)
                    assert not tb.overlaps(frame), (text.get_text(), other.get_ylabel())
    for leg in fig.legends:
        bb = leg.get_window_extent(renderer)
        assert box.contains(bb.x0, bb.y0) and box.contains(bb.x1, bb.y1)
        for ax in fig.axes:  # above the axes and their titles
            assert not bb.overlaps(ax.get_tightbbox(renderer))


def test_a_figure_too_small_for_its_labels_is_left_as_it_is() -> None:
    fig, ax = new_figure(3, 1, height_in=0.6, width_in=0.8, layout="measured")
    for a in ax.flat:
        a.set_ylabel("a long label\nover two lines (unit)")
        a.set_title("a title")
    before = np.array([a.get_position().extents for a in fig.axes])
    _drawn(fig)  # no error, no negative sizes
    assert np.array_equal(np.array([a.get_position().extents for a in fig.axes]), before)
