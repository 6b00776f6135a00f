"""A report's figures built and drawn (SVG for the page, PNG for the PDF) by this process and a
forked one at once, each taking the next part from a shared counter (issue 36: building and drawing
the figures was ~60 % of a report's time; benchmarks/report_speed.py).  Serial where a fork is not
safe (another thread running, as in the window) or not available, and whenever anything fails in
the parallel path, so a report never depends on it."""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bench.figures import PRINT_DPI, ReportFigure

#: a part of a report's figures: a function of nothing that builds them (matplotlib figures)
Part = Callable[[], list[ReportFigure]]


@dataclass
class DrawnFigure:
    """A report figure already drawn: what the page (SVG) and the PDF (PNG) show, without the
    matplotlib figure (so it crosses a process boundary)."""

    key: str
    title: str
    note: str
    table: tuple[list[str], list[list[str]]] | None
    svg_text: str
    png_bytes: bytes | None = None

    def svg(self) -> str:
        return self.svg_text

    def png(self, dpi: int = PRINT_DPI) -> bytes:
        if self.png_bytes is None or dpi != PRINT_DPI:
            raise ValueError(f"{self.key}: drawn without a {dpi} dpi PNG")
        return self.png_bytes


def draw(fig: ReportFigure, png: bool) -> DrawnFigure:
    """One figure as SVG and, with png, as the PDF's PNG (one layout for both: ReportFigure)."""
    svg = fig.svg()
    return DrawnFigure(fig.key, fig.title, fig.note, fig.table, svg, fig.png() if png else None)


def draw_parts(parts: list[Part], png: bool = False, *, workers: int = 2,
               meanwhile: Callable[[], Any] | None = None,
               in_child: Callable[[], Any] | None = None) -> list[DrawnFigure]:
    """Build and draw every part, in the parts' order; with workers > 1 and a fork that is safe,
    workers - 1 forked processes take parts alongside this one (each the next part not yet
    taken).  meanwhile: work of this process done once while the others start drawing (an
    import); in_child: what a forked process does first (reopen a file).  A part that raises
    raises here, as drawn serially."""
    done: list[bool] = []

    def once() -> None:
        if meanwhile is not None and not done:
            done.append(True)
            meanwhile()

    children = min(workers, len(parts), os.cpu_count() or 1) - 1
    if children > 0 and fork_is_safe():
        try:
            return _draw_forked(parts, png, children, once, in_child)
        except _ForkFailed:
            pass
    once()
    return [draw(f, png) for part in parts for f in part()]


def fork_is_safe() -> bool:
    """A fork copies only the calling thread: with another thread alive (a window's event loop, a
    station's reader) a lock it holds would never be released in the copy."""
    import multiprocessing

    return (sys.platform.startswith("linux") and threading.active_count() == 1
            and "fork" in multiprocessing.get_all_start_methods())


class _ForkFailed(RuntimeError):
    """The forked drawing did not deliver (no process, a lost pipe): draw serially instead."""


def _draw_forked(parts: list[Part], png: bool, children: int, meanwhile: Callable[[], Any],
                 in_child: Callable[[], Any] | None) -> list[DrawnFigure]:
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    taken = ctx.Value("i", 0)  # the next part to take, shared by every process
    pipes, procs = [], []
    try:
        for _ in range(children):
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(parts, png, taken, send, in_child), daemon=True)
            proc.start()
            send.close()
            pipes.append(recv)
            procs.append(proc)
    except OSError as exc:  # no process could be made (limits, memory)
        _stop(procs)
        raise _ForkFailed(str(exc)) from exc
    try:
        try:
            meanwhile()
            drawn = dict(_take(parts, png, taken))
        except BaseException:
            with taken.get_lock():
                taken.value = len(parts)  # the others stop after the part in hand
            raise  # as the serial path raises it
        for recv in pipes:
            try:
                status, got = recv.recv()
            except (EOFError, OSError) as exc:  # the child died
                raise _ForkFailed(f"a drawing process ended without its figures ({exc})") from exc
            if status != "ok":  # a part failed there: the serial path raises it here, with its traceback
                raise _ForkFailed(got)
            drawn.update(got)
    finally:
        _stop(procs)
    return [d for i in range(len(parts)) for d in drawn[i]]


def _take(parts: list[Part], png: bool, taken: Any) -> list[tuple[int, list[DrawnFigure]]]:
    """Take the next part not yet taken, build and draw it, until none is left."""
    out = []
    while True:
        with taken.get_lock():
            i = taken.value
            taken.value += 1
        if i >= len(parts):
            return out
        out.append((i, [draw(f, png) for f in parts[i]()]))


def _child(parts: list[Part], png: bool, taken: Any, send: Any, in_child: Callable[[], Any] | None) -> None:
    """A forked process's share: its drawn parts, or the error, sent to the parent."""
    try:
        if in_child is not None:
            in_child()
        send.send(("ok", _take(parts, png, taken)))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which draws serially
        with taken.get_lock():
            taken.value = len(parts)  # the parent stops taking parts
        send.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        send.close()


def _stop(procs: list[Any]) -> None:
    for proc in procs:
        proc.join(timeout=5.0)
        if proc.is_alive():
            proc.kill()
            proc.join()
