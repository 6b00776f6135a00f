"""The lab engineer's window (PySide6 + pyqtgraph) over the engine's event stream.

`run_gui(station, run=, screenshot=, at_s=)` is what `gyrobench gui` calls; `MainWindow(backend)`
is the window; a backend (`GuiBackend`) runs procedures in a worker thread and publishes events.
Qt is imported only when the window is built, so `import bench.gui` is cheap.
"""

from __future__ import annotations

from .app import make_backend, run_gui

__all__ = ["make_backend", "run_gui"]
