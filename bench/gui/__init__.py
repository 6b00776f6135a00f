"""The lab engineer's window (PySide6 + pyqtgraph) over the engine's event stream.

`run_gui(station, run=, screenshot=, at_s=)` is what `gyrobench gui` calls; `MainWindow(backend)`
is the window; a backend (`GuiBackend`) runs procedures in a worker thread and publishes events.
Qt is imported only when the window is built and .app (the engine, numba) on first use of its
names, so `import bench.gui` is cheap.
"""

from __future__ import annotations

from typing import Any

__all__ = ["make_backend", "run_gui"]


def __getattr__(name: str) -> Any:
    """`make_backend` and `run_gui` from .app on first use: importing the package (as `gyrobench
    --help` does for the `gui` subcommand's arguments) must not import the engine and numba."""
    if name in __all__:
        from . import app

        return getattr(app, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
