"""First start with a cold kernel cache: a splash shows before the kernels compile and names each
as it starts (compiled by a worker thread while the window's event loop keeps running); with a
filled cache nothing is shown."""

from __future__ import annotations

import threading

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtWidgets import QApplication  # noqa: E402

from bench.gui.splash import KernelSplash, warm_with_splash  # noqa: E402


def test_a_cold_cache_shows_the_splash_first_and_names_each_kernel(qtbot):
    app = QApplication.instance()
    seen: dict[str, object] = {}

    def fake_warm(on_compile):
        seen["thread"] = threading.get_ident()
        seen["splash_up"] = any(isinstance(w, KernelSplash) and w.isVisible() for w in app.topLevelWidgets())
        on_compile("simulators.world.step_block")
        on_compile("drivers.fpga.protocol.parse_frames")

    splash = warm_with_splash(app, fake_warm, cold=True, poll_s=0.01)
    assert seen["splash_up"] and seen["thread"] != threading.get_ident()  # shown first; compiled off the GUI thread
    text = "\n".join(splash.messages)
    assert "kernel 1: simulators.world.step_block" in text or "kernel 2: drivers.fpga.protocol.parse_frames" in text
    assert splash.messages[-1].endswith("kernels ready") and not splash.isVisible()
    assert warm_with_splash(app, fake_warm, cold=False) is None


def test_a_failed_compile_is_raised_after_the_splash_closes(qtbot):
    app = QApplication.instance()

    def broken(_on_compile):
        raise RuntimeError("numba said no")

    with pytest.raises(RuntimeError, match="numba said no"):
        warm_with_splash(app, broken, cold=True, poll_s=0.01)
    assert not any(isinstance(w, KernelSplash) and w.isVisible() for w in app.topLevelWidgets())
