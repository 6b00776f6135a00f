"""A one-pass layout for a report's grid of axes: each margin and gap measured from what sits
there (tick labels as the locator and formatter give them, axis labels, titles, offset texts, a
figure legend at the top) and set once, instead of matplotlib's constrained layout, which builds
every tick and takes every artist's extent twice before the figure is drawn (about a third of a
report figure's drawing; issue 36, benchmarks/report_speed.py).  The spacing is the constrained
layout's (3/72 in around each axes' decorations), so a page looks the same."""

from __future__ import annotations

from typing import Any

import matplotlib as mpl
from matplotlib.layout_engine import LayoutEngine

PAD_IN = 3 / 72  # constrained layout's w_pad / h_pad


class MeasuredLayout(LayoutEngine):
    """Margins and gaps of one GridSpec's axes from their decorations' measured sizes (inches)."""

    _adjust_compatible = True
    _colorbar_gridspec = True

    def execute(self, fig: Any) -> None:
        axes = [ax for ax in fig.axes if ax.get_subplotspec() is not None]
        if not axes:
            return
        gs = axes[0].get_subplotspec().get_gridspec()
        renderer = fig._get_renderer()
        for _ in range(2):  # again once placed: the ticks a locator picks depend on the axes' length
            self._place(fig, gs, axes, renderer)

    def _place(self, fig: Any, gs: Any, axes: list[Any], renderer: Any) -> None:
        nrows, ncols = gs.get_geometry()
        per_in = renderer.points_to_pixels(72.0)
        w, h = fig.get_size_inches()
        over = {id(ax): _overhangs(ax, renderer, per_in) for ax in axes}
        left, right = [0.0] * ncols, [0.0] * ncols
        top, bottom = [0.0] * nrows, [0.0] * nrows
        for ax in axes:
            ss = ax.get_subplotspec()
            o = over[id(ax)]
            for c in range(ss.colspan.start, ss.colspan.stop):
                left[c], right[c] = max(left[c], o["left"]), max(right[c], o["right"])
            for r in range(ss.rowspan.start, ss.rowspan.stop):
                top[r], bottom[r] = max(top[r], o["top"]), max(bottom[r], o["bottom"])
        legend_in = sum(_legend_height_in(leg, renderer, per_in) for leg in fig.legends)
        m_left, m_right = PAD_IN + left[0], PAD_IN + right[-1]
        m_top, m_bottom = PAD_IN + top[0] + legend_in, PAD_IN + bottom[-1]
        wgap = max((right[c] + left[c + 1] + 2 * PAD_IN for c in range(ncols - 1)), default=0.0)
        hgap = max((bottom[r] + top[r + 1] + 2 * PAD_IN for r in range(nrows - 1)), default=0.0)
        width_in = w - m_left - m_right
        height_in = h - m_top - m_bottom
        mean_w = (width_in - (ncols - 1) * wgap) / ncols
        mean_h = (height_in - (nrows - 1) * hgap) / nrows
        if mean_w <= 0 or mean_h <= 0:  # decorations larger than the figure: leave the grid as it is
            return
        gs.update(left=m_left / w, right=1 - m_right / w, bottom=m_bottom / h, top=1 - m_top / h,
                  wspace=wgap / mean_w if ncols > 1 else None, hspace=hgap / mean_h if nrows > 1 else None)
        for ax in axes:  # GridSpec.update moves the axes of pyplot's figures only
            ax.set_position(ax.get_subplotspec().get_position(fig))
        for leg in fig.legends:  # what constrained layout does for loc="outside upper ...": above the axes
            leg.set_bbox_to_anchor((0.0, 0.0, 1.0, 1.0), transform=fig.transFigure)


def _legend_height_in(leg: Any, renderer: Any, per_in: float) -> float:
    loc = getattr(leg, "_outside_loc", None) or ""
    if not loc.startswith("upper"):
        return 0.0
    pad_in = leg.borderaxespad * leg._fontsize / 72  # its distance from the figure's top edge
    return leg.get_window_extent(renderer).height / per_in + pad_in


def _text_in(text: Any, renderer: Any, per_in: float) -> tuple[float, float]:
    """(width, height) in inches of a Text as drawn (its rotation included); 0 when hidden or empty."""
    if not text.get_visible() or not text.get_text():
        return 0.0, 0.0
    bb = text.get_window_extent(renderer)
    return bb.width / per_in, bb.height / per_in


def _tick_labels(axis: Any, which_side: str) -> tuple[list[str], list[float], Any]:
    """The major tick labels the axis will draw on one side: (texts, positions as axes fractions, a label)."""
    params = axis.get_tick_params(which="major")
    if not params.get(which_side, which_side in ("labelleft", "labelbottom")):
        return [], [], None
    locs = [loc for loc in axis.get_majorticklocs() if _within(axis, loc)]
    texts = axis.get_major_formatter().format_ticks(locs)
    ax = axis.axes
    if axis.axis_name == "x":
        frac = [(ax.transData + ax.transAxes.inverted()).transform((loc, 0.0))[0] for loc in locs]
    else:
        frac = [(ax.transData + ax.transAxes.inverted()).transform((0.0, loc))[1] for loc in locs]
    return texts, frac, axis.get_major_ticks(1)[0].label1


def _within(axis: Any, loc: float) -> bool:
    lo, hi = sorted(axis.get_view_interval())
    eps = 1e-10 * max(abs(hi - lo), 1e-300)
    return lo - eps <= loc <= hi + eps


def _overhangs(ax: Any, renderer: Any, per_in: float) -> dict[str, float]:
    """How far an axes' decorations reach beyond its frame on each side, inches."""
    rc = mpl.rcParams
    pt = 1 / 72
    out = {"left": 0.0, "right": 0.0, "top": 0.0, "bottom": 0.0}
    pos = ax.get_position()
    fig_w, fig_h = ax.figure.get_size_inches()
    ax_w, ax_h = pos.width * fig_w, pos.height * fig_h
    # y axis (left side)
    texts, frac, proto = _tick_labels(ax.yaxis, "labelleft")
    tick_len = rc["ytick.major.size"] * pt if rc["ytick.direction"] != "in" else 0.0
    reach = tick_len
    if texts:
        sizes = [_measure(proto, s, renderer, per_in) for s in texts]
        reach += rc["ytick.major.pad"] * pt + max(wd for wd, _ in sizes)
        for f, (_, ht) in zip(frac, sizes, strict=True):  # a label at the frame's end reaches past it
            out["top"] = max(out["top"], (f - 1.0) * ax_h + ht / 2)
            out["bottom"] = max(out["bottom"], -f * ax_h + ht / 2)
    lw, _ = _text_in(ax.yaxis.label, renderer, per_in)
    if lw:
        reach += rc["axes.labelpad"] * pt + lw
    out["left"] = reach
    # x axis (bottom side)
    texts, frac, proto = _tick_labels(ax.xaxis, "labelbottom")
    tick_len = rc["xtick.major.size"] * pt if rc["xtick.direction"] != "in" else 0.0
    reach = tick_len
    if texts:
        sizes = [_measure(proto, s, renderer, per_in) for s in texts]
        reach += rc["xtick.major.pad"] * pt + max(ht for _, ht in sizes)
        for f, (wd, _) in zip(frac, sizes, strict=True):
            out["right"] = max(out["right"], (f - 1.0) * ax_w + wd / 2)
            out["left"] = max(out["left"], -f * ax_w + wd / 2)
    _, lh = _text_in(ax.xaxis.label, renderer, per_in)
    if lh:
        reach += rc["axes.labelpad"] * pt + lh
    out["bottom"] = max(out["bottom"], reach)
    # above: the title, the y axis's offset text (a common factor or offset of its ticks)
    above = 0.0
    for title in (ax.title, getattr(ax, "_left_title", ax.title), getattr(ax, "_right_title", ax.title)):
        _, th = _text_in(title, renderer, per_in)
        if th:
            above = max(above, rc["axes.titlepad"] * pt + th)
    ax.yaxis.get_major_formatter().format_ticks(ax.yaxis.get_majorticklocs())
    offset = ax.yaxis.get_major_formatter().get_offset()
    if offset:
        _, oh = _measure(ax.yaxis.offsetText, offset, renderer, per_in)
        above = max(above, oh + rc["ytick.major.pad"] * pt)
    out["top"] = max(out["top"], above)
    xoff = ax.xaxis.get_major_formatter()
    xoff.format_ticks(ax.xaxis.get_majorticklocs())
    if xoff.get_offset() and out["right"] < 0.6:  # the x offset text sits at the right end, below the labels
        out["bottom"] += _measure(ax.xaxis.offsetText, xoff.get_offset(), renderer, per_in)[1]
    return out


def _measure(proto: Any, s: str, renderer: Any, per_in: float) -> tuple[float, float]:
    """(width, height) in inches of text s in the font of Text `proto` (its rotation ignored)."""
    if not s:
        return 0.0, 0.0
    from matplotlib.text import Text

    t = Text(0, 0, s, fontproperties=proto.get_fontproperties())
    t.figure = proto.figure
    bb = t.get_window_extent(renderer)
    return bb.width / per_in, bb.height / per_in
