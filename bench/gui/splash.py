"""First start on a fresh checkout: the simulated devices' kernels compile for a minute or more
(bench.kernel_cache, simulators/warm.py).  A splash shows from the first second, naming each
kernel as it starts compiling with the seconds gone, while a worker thread compiles them."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QApplication, QLabel, QProgressBar, QVBoxLayout, QWidget


class KernelSplash(QWidget):
    """A small frameless window: what is going on, a busy bar, the kernel compiling now."""

    def __init__(self) -> None:
        super().__init__(None, Qt.WindowType.SplashScreen | Qt.WindowType.WindowStaysOnTopHint)
        self.setObjectName("kernel_splash")
        lay = QVBoxLayout(self)
        title = QLabel("<b>gyrobench</b> — first start: compiling the simulated devices' kernels "
                       "(once per change of their source; a minute or two)")
        title.setWordWrap(True)
        lay.addWidget(title)
        self.bar = QProgressBar()
        self.bar.setRange(0, 0)  # busy: numba does not say how long a kernel takes
        lay.addWidget(self.bar)
        self.line = QLabel("")
        self.line.setWordWrap(True)
        lay.addWidget(self.line)
        self.messages: list[str] = []  # every line shown (tests, and what a log would keep)
        self.show_line("   0 s  starting the compiler (numba)...")
        self.resize(520, 130)

    def show_line(self, text: str) -> None:
        self.messages.append(text)
        self.line.setText(text)


def warm_with_splash(app: QApplication, warm: Callable[[Callable[[str], None]], None] | None = None,
                     cold: bool | None = None, poll_s: float = 0.05) -> KernelSplash | None:
    """On a cold kernel cache: show the splash at once and run `warm(on_compile)` (default:
    bench.composition.warm_simulators) in a worker thread, the event loop pumped meanwhile; the
    splash (closed) or None when the cache was filled and nothing was shown."""
    from bench import kernel_cache

    if cold is None:
        cold = not kernel_cache.is_filled()
    if not cold:
        return None
    if warm is None:
        from bench.composition import warm_simulators as warm
    splash = KernelSplash()
    splash.show()
    app.processEvents()
    names: queue.Queue[str] = queue.Queue()
    failed: list[BaseException] = []

    def work() -> None:
        try:
            warm(names.put)
        except BaseException as exc:  # noqa: BLE001 - said on the splash's caller, after it closes
            failed.append(exc)

    t0 = time.monotonic()
    worker = threading.Thread(target=work, name="kernel-warm", daemon=True)
    worker.start()
    n, current = 0, ""
    while worker.is_alive():
        while not names.empty():
            n, current = n + 1, names.get()
        shown = f"{time.monotonic() - t0:4.0f} s  kernel {n}: {current}" if current else \
            f"{time.monotonic() - t0:4.0f} s  loading..."
        if not splash.messages or splash.messages[-1] != shown:
            splash.show_line(shown)
        app.processEvents()
        worker.join(poll_s)
    while not names.empty():
        n, current = n + 1, names.get()
        splash.show_line(f"{time.monotonic() - t0:4.0f} s  kernel {n}: {current}")
    splash.show_line(f"{time.monotonic() - t0:4.0f} s  kernels ready")
    app.processEvents()
    splash.close()
    if failed:
        raise failed[0]
    return splash
