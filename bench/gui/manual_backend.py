"""The engine backend's side of manual control: a manual session runs in the backend's run
thread through the same Runner as a procedure, so one excludes the other, and the safe-state
button works whatever the station is doing (a run: abort; a session: abort; idle: the safe
state now)."""

from __future__ import annotations

import threading
from typing import Any

from bench.engine import events as ev
from bench.engine.manual import ManualSession, busy_text


class ManualBackendMixin:
    """Mixed into EngineBackend (which provides station, runner, bus, _thread, _run, _io_gate)."""

    manual: ManualSession | None = None

    def busy_text(self) -> str | None:
        """Why a run or a manual session cannot start now (None: the station is idle)."""
        if not self.running():
            return None
        rec = self.runner.record
        if rec is None:
            return f"station {self.station.id!r} is busy"
        return busy_text(rec.procedure, rec.run_id, self.station.id)

    def manual_active(self) -> bool:
        return self.manual is not None and self.running() and self.runner.record is not None \
            and self.runner.record.procedure == "manual"

    def start_manual(self) -> ManualSession:
        """Start a manual-control session on the idle station (RuntimeError saying why not)."""
        why = self.busy_text()
        if why is not None:
            raise RuntimeError(why)
        session = ManualSession(self.station)
        with self._io_gate:  # from here on only the session talks to the devices
            self._in_run = True
        self.manual = session
        self._thread = threading.Thread(target=self._run, args=(session.procedure(),), name="manual-control",
                                        daemon=True)
        self._thread.start()
        return session

    def end_manual(self) -> None:
        """End the session; the runner brings the station to its safe state."""
        if self.manual is not None:
            self.manual.end()

    def safe_state_now(self, reason: str = "safe state asked from the window") -> str:
        """Bring the station to its safe state now: a run or a session is aborted (the runner's
        safe state follows); an idle station is made safe in a worker thread.  Returns what was done."""
        self._safe_result = None
        if self.running():
            self._safe_run = True
            self.runner.abort(reason)
            return "aborting to the safe state..."
        self._safe_run = False

        def work() -> None:
            clock = self.station.clock
            try:
                with self._io_gate:
                    report = self.station.safe_state()
                ok = report.confirmed
                detail = f"{report.devices}" + (f" errors {report.errors}" if report.errors else "")
            except Exception as exc:  # noqa: BLE001 - said in the log, never a traceback
                ok, detail = False, f"{type(exc).__name__}: {exc}"
            self.bus.publish(ev.Log("", clock.now(), level="INFO" if ok else "ERROR",
                                    message=f"{reason}: safe state {'confirmed' if ok else 'NOT confirmed'}: {detail}"))
            self._safe_result = (ok, f"safe state {'confirmed' if ok else 'NOT confirmed'}")
            self.publish_status()

        threading.Thread(target=work, name="safe-state", daemon=True).start()
        return "bringing the idle station to its safe state..."

    def safe_state_done(self) -> tuple[bool, str] | None:
        """After safe_state_now: (confirmed, what to show) once the engine is done, None before."""
        if getattr(self, "_safe_run", False):
            if self.running():
                return None
            rec = self.runner.record
            ok = bool(rec is not None and rec.safe_state)
            return ok, (f"run {rec.run_id} {rec.outcome}: " if rec is not None else "") + \
                f"safe state {'confirmed' if ok else 'NOT confirmed'}"
        return getattr(self, "_safe_result", None)

    # provided by EngineBackend
    station: Any
    runner: Any
    bus: Any
