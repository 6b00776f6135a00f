"""`gyrobench gui`: build the backend for a station, open the window, or run a procedure
headless and save a screenshot of the window at a chosen simulated second."""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

from bench.validation import ValidationError, not_one_of, unknown_name

from .backend import GuiBackend


def make_backend(station: str | None, *, seed: int = 0) -> GuiBackend:
    """The engine on a station (built-in name or file; sim-hrg when none is given)."""
    from .engine_backend import EngineBackend, default_station

    return EngineBackend(station or default_station(), seed=seed)


def _simulated(station: str | None) -> bool:
    """Whether the station (sim-hrg when none) is simulated: only then do kernels compile; a
    station file that does not read says so later, when the backend opens it."""
    from bench.station_config import load_config

    from .engine_backend import default_station

    try:
        return load_config(station or default_station()).simulation is not None
    except Exception:  # noqa: BLE001 - the backend names the problem
        return False


def has_display(environ: dict[str, str] | None = None) -> bool:
    """Whether a window can be shown: an X or Wayland display on Linux (other systems always)."""
    env = os.environ if environ is None else environ
    if not sys.platform.startswith("linux"):
        return True
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def window_unavailable(command: str, environ: dict[str, str] | None = None) -> str | None:
    """Why `command` cannot show its window (no display, and no Qt platform that needs none), in
    one line; None when it can. Checked before anything starts: Qt without a display aborts the
    process (exit 134) with a misleading message about libxcb."""
    env = os.environ if environ is None else environ
    platform = env.get("QT_QPA_PLATFORM", "")
    if has_display(env) or (platform and not platform.startswith(("xcb", "wayland"))):
        return None
    return (f"{command}: no display (DISPLAY / WAYLAND_DISPLAY unset): the window cannot be shown"
            + (f" on QT_QPA_PLATFORM={platform}" if platform else "")
            + "; run without the window, or set QT_QPA_PLATFORM=offscreen")


def choose_qt_platform(environ: dict[str, str] | None = None) -> str | None:
    """With no display and no QT_QPA_PLATFORM, pick Qt's offscreen platform (set in the
    environment, before the QApplication exists): Qt would otherwise abort the process."""
    env = os.environ if environ is None else environ
    if env.get("QT_QPA_PLATFORM") or has_display(env):
        return None
    env["QT_QPA_PLATFORM"] = "offscreen"
    return "offscreen"


#: what Qt's platform plugins say that tells the user nothing: the offscreen plugin (headless
#: screenshots, CI) reports each size hint it cannot pass to a window manager it does not have
QUIET_QT_MESSAGES = frozenset({"This plugin does not support propagateSizeHints()"})
_QT_HANDLER: list = []  # the installed handler, kept alive


def quiet_qt_messages() -> None:
    """Route Qt's messages through a handler that drops QUIET_QT_MESSAGES and prints the rest to
    stderr as Qt would (once a process)."""
    if _QT_HANDLER:
        return
    from PySide6.QtCore import qInstallMessageHandler

    def handler(_mode, _context, message: str) -> None:
        if message not in QUIET_QT_MESSAGES:
            sys.stderr.write(message + "\n")

    _QT_HANDLER.append(handler)
    qInstallMessageHandler(handler)


def _app():
    from PySide6.QtWidgets import QApplication

    choose_qt_platform()
    quiet_qt_messages()

    app = QApplication.instance()
    return app if app is not None else QApplication(["gyrobench"])


def take_screenshot(window, procedure: str, path: str | Path, *, at_s: float | None = None,
                    params: dict | None = None, timeout_s: float = 600.0) -> Path:
    """Run `procedure` on the window's backend; when an event reaches simulated second `at_s`
    (or the run ends), hold the engine there, draw everything received, save the window as a
    PNG, then abort the run and wait for its safe state.  Returns the PNG's path."""
    from PySide6.QtWidgets import QApplication

    from bench.engine.events import RunFinished

    path = Path(path)
    reached = threading.Event()
    release = threading.Event()

    def gate(event) -> None:  # engine thread: holds the run at the chosen second
        if at_s is not None and not reached.is_set() and event.t_sim_s >= at_s and not isinstance(event, RunFinished):
            backend.pause()  # the engine holds at its next checkpoint, whichever thread this is
            reached.set()
            release.wait(timeout_s)

    backend = window.backend
    window.bridge.set_gate(gate)
    window.show()
    idx = window.procedure.findText(procedure)
    if idx < 0:
        names = [window.procedure.itemText(i) for i in range(window.procedure.count())]
        raise ValidationError(not_one_of("--run", procedure, names))
    window.procedure.setCurrentIndex(idx)
    for k, v in (params or {}).items():
        if k not in window.form.fields:
            raise ValidationError(unknown_name(k, f"not a parameter of {procedure}", window.form.fields))
        window.form.set_value(k, v)
    if not window.form.is_valid():
        raise ValidationError("; ".join(window.form.errors.values()))
    window.start()
    if not window.run_active:
        raise RuntimeError(f"{procedure} did not start (see the log)")
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline and not reached.is_set() and window.run_active:
            QApplication.processEvents()
            time.sleep(0.002)
        window.bridge.drain()
        QApplication.processEvents()
        window.flush_labels()
        window.plots.refresh(force=True)
        QApplication.processEvents()
        path.parent.mkdir(parents=True, exist_ok=True)
        if not window.grab().save(str(path), "PNG"):
            raise OSError(f"could not write the screenshot {path}")
        window.screenshot_t_s = window.t_sim_s
    finally:
        window.bridge.set_gate(None)
        if window.run_active:
            backend.abort()
        backend.resume()
        release.set()
        while window.run_active and time.monotonic() < deadline:
            QApplication.processEvents()
            time.sleep(0.005)
    return path


class QuitOnSignal:
    """Ctrl+C and SIGTERM on the window's process: the run (if any) is aborted to the safe state,
    the window closes and the process exits with 128 + the signal's number, with no traceback.

    Python runs a signal handler only when the interpreter has control: a timer wakes it from Qt's
    event loop every `poll_ms`; outside the loop (starting, a headless screenshot) the signal
    becomes a KeyboardInterrupt that `cmd_gui` turns into the same clean exit."""

    def __init__(self, poll_ms: int = 200) -> None:
        self.signum: int | None = None
        self.in_loop = False
        self.window = None
        self._timer = None
        self._old: dict[int, object] = {}
        self.poll_ms = poll_ms

    def install(self) -> QuitOnSignal:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self.handler)
        return self

    def uninstall(self) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()
        if self._timer is not None:
            self._timer.stop()

    def handler(self, signum: int, _frame=None) -> None:
        self.signum = signum
        if not self.in_loop:
            raise KeyboardInterrupt(signal.Signals(signum).name)

    def watch(self, window) -> None:
        """From here on a signal closes `window` (its closeEvent waits for the safe state)."""
        from PySide6.QtCore import QTimer

        self.window = window
        self.in_loop = True
        self._timer = QTimer()
        self._timer.timeout.connect(self.check)
        self._timer.start(self.poll_ms)

    def check(self) -> None:
        """GUI thread: act on a signal that arrived (once)."""
        if self.signum is None or self.window is None:
            return
        window, self.window = self.window, None
        name = signal.Signals(self.signum).name
        quit_for_signal = getattr(window, "quit_for_signal", None)
        if quit_for_signal is not None:
            quit_for_signal(name)
        else:
            window.close()
        from PySide6.QtWidgets import QApplication

        QApplication.quit()

    @property
    def exit_code(self) -> int:
        return 0 if self.signum is None else 128 + int(self.signum)


def run_replay(open_run: str, *, screenshot: str | None = None) -> int:
    """`gui --open RUN.h5`: the recorded run in its own window, no station opened."""
    app = _app()
    from .replay_view import ReplayWindow

    guard = QuitOnSignal().install()
    win = ReplayWindow(open_run)
    try:
        win.show()
        if screenshot is not None:
            app.processEvents()
            win.plots.refresh(force=True)
            if not win.grab().save(str(screenshot), "PNG"):
                raise OSError(f"could not write the screenshot {screenshot}")
            return 0
        guard.watch(win)
        code = int(app.exec())
        return guard.exit_code or code
    finally:
        guard.uninstall()
        win.close()
        win.deleteLater()
        app.processEvents()


def run_gui(station: str | None = None, *, run: str | None = None, screenshot: str | None = None,
            at_s: float | None = None, seed: int = 0, speed: float | None = None,
            open_run: str | None = None, params: dict[str, str] | None = None, start: bool = False) -> int:
    """Open the window (blocking until it closes), or with `screenshot`, run headless and exit.
    `open_run` alone opens that recorded run's replay only; `start` starts `run` at once."""
    if screenshot is None and not os.environ.get("QT_QPA_PLATFORM") and not has_display():
        raise SystemExit("gyrobench gui: no display (DISPLAY / WAYLAND_DISPLAY unset): the window cannot be "
                         "shown; use --screenshot FILE to run headless, or set QT_QPA_PLATFORM")
    if open_run is not None and run is None:
        return run_replay(open_run, screenshot=screenshot)
    app = _app()
    from .main_window import MainWindow

    guard = QuitOnSignal().install()
    try:
        if screenshot is None and _simulated(station):
            from .splash import warm_with_splash

            warm_with_splash(app)  # a fresh checkout compiles kernels: a splash from the first second
        backend = make_backend(station, seed=seed)
    except BaseException:
        guard.uninstall()
        raise
    window = MainWindow(backend)
    code = 0
    try:
        if speed is not None and backend.simulated:
            window.station.set_speed(speed)
        elif backend.simulated and screenshot is None:
            window.station.set_speed(1.0)  # an interactive demo starts in real time
        replay = window.open_run(open_run) if open_run is not None else None  # its own window
        if screenshot is not None:
            if run is None:
                shown = replay or window
                shown.show()
                app.processEvents()
                shown.plots.refresh(force=True)
                shown.grab().save(str(screenshot), "PNG")
            else:
                out = take_screenshot(window, run, screenshot, at_s=at_s, params=params)
                fin = window.last_finished
                print(f"screenshot {out} at t = {window.screenshot_t_s:.1f} s"
                      + (f"; run {fin.outcome}, safe state {'confirmed' if fin.safe_state else 'NOT confirmed'}"
                         if fin else ""))
        else:
            if run is not None:
                idx = window.procedure.findText(run)
                if idx >= 0:
                    window.procedure.setCurrentIndex(idx)
                for k, v in (params or {}).items():
                    if k in window.form.fields:
                        window.form.set_value(k, v)
            window.show()
            guard.watch(window)
            if start and run is not None:
                window.start()
                if window.run_active:
                    print(f"gyrobench gui: {run} started", flush=True)  # a script waits for this line
            code = int(app.exec())
            if guard.signum is not None:
                fin = window.last_finished
                safe = "" if fin is None else "confirmed" if fin.safe_state else "NOT confirmed"
                print(f"gyrobench gui: stopped by {signal.Signals(guard.signum).name}"
                      + (f"; run {fin.run_id} {fin.outcome}, safe state {safe}" if fin else ""), flush=True)
                code = guard.exit_code
    finally:
        guard.uninstall()
        backend.close()
        window.close()
        window.deleteLater()
        app.processEvents()
    return code


def parse_speed(text: str) -> float:
    """'1', '10', '100' or 'max' -> x real time (inf for max); ValidationError otherwise."""
    from bench.validation import convert

    if text.strip().lower() in ("max", "inf"):
        return math.inf
    return convert("--speed", text, float, low=0.0, parse_text=True)
