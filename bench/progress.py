"""The CLI's live progress on a terminal (rich): steps, the current step's progress, measurements."""

from __future__ import annotations

import threading

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from bench.engine import events as ev

_STYLE = {
    "PASS": "green",
    "FAIL": "bold red",
    "MARGINAL": "yellow",
    "COMPLETE": "cyan",
    "ERROR": "bold red",
    "ABORTED": "bold magenta",
}


class RichProgress:
    """Subscribes to a run's event bus and draws it; `close()` ends the display."""

    def __init__(self, bus: ev.EventBus, console: Console | None = None) -> None:
        self.console = console or Console(stderr=True)
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            TextColumn("{task.percentage:>3.0f}%"),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            console=self.console,
            transient=False,
        )
        self._lock = threading.Lock()
        self._run_task = None
        self._step_task = None
        self._total = 1
        self.progress.start()
        self._unsubscribe = bus.subscribe(self.on_event)

    def on_event(self, e: ev.Event) -> None:
        with self._lock:
            p = self.progress
            if isinstance(e, ev.RunStarted):
                self._total = max(1, len(e.steps))
                self._run_task = p.add_task(f"{e.procedure} on {e.station}", total=self._total, info="")
            elif isinstance(e, ev.StepStarted):
                if self._step_task is not None:
                    p.remove_task(self._step_task)
                self._step_task = p.add_task(f"  {e.index + 1}/{e.total} {e.title}", total=1.0, info="")
                if self._run_task is not None:
                    p.update(self._run_task, completed=e.index, info=f"t = {e.t_sim_s:.2f} s")
            elif isinstance(e, ev.Progress) and self._step_task is not None:
                p.update(self._step_task, completed=e.fraction, info=e.message)
            elif isinstance(e, ev.StepFinished):
                if self._step_task is not None:
                    p.update(self._step_task, completed=1.0 if e.status == "done" else None, info=e.status)
                if self._run_task is not None:
                    p.update(self._run_task, completed=e.index + 1, info=f"t = {e.t_sim_s:.2f} s")
            elif isinstance(e, ev.Measurement):
                style = _STYLE.get(e.outcome, "")
                p.console.print(f"  {e.name} = {e.value:.6g} {e.unit}  [{style}]{e.outcome}[/]")
            elif isinstance(e, ev.Log) and e.level in ("WARNING", "ERROR"):
                p.console.print(f"  [{'yellow' if e.level == 'WARNING' else 'red'}]{e.level}[/] {e.message}")
            elif isinstance(e, ev.RunFinished):
                style = _STYLE.get(e.outcome, "")
                p.console.print(
                    f"[{style}]{e.outcome}[/]: {e.end_reason}; safe state "
                    f"{'confirmed' if e.safe_state else '[bold red]NOT confirmed[/]'}"
                )

    def close(self) -> None:
        self._unsubscribe()
        self.progress.stop()
