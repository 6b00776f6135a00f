"""Raw data of a run: one HDF5 file, written as the events arrive, readable after a crash.

Layout: `/streams/<name>` (rows x columns float64, chunked, attr `columns`), `/log` and
`/measurements` (one JSON string a row, appended as they happen), `/fits/<name>/<curve>`, and the
run's attributes on the root (params, station, software_version, truth when simulated,
procedure, run_id, ...; outcome, end_reason and safe_state once the run ends).  The file is
flushed whenever a second of data (bench-clock time) or a second of wall time has passed since
the last flush, so a process killed mid-run leaves a readable file with all but the last second.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from bench.engine import events as ev

CHUNK_ROWS = 4096
FLUSH_EVERY_S = 1.0
_STR = h5py.string_dtype()


def _json(value: Any) -> str:
    return json.dumps(value, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))


class Recorder:
    """Subscribes to the run's event bus and writes its raw streams and log to HDF5."""

    def __init__(self, path: str | Path, attrs: dict[str, Any] | None = None) -> None:
        self.path = Path(path).resolve()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._f = h5py.File(self.path, "w")  # default format: no open-for-write flag to clear after a crash
        self._f.create_group("streams")
        self._f.create_group("fits")
        self._log = self._text_dataset("log")
        self._meas = self._text_dataset("measurements")
        for key, value in (attrs or {}).items():
            self._f.attrs[key] = value if isinstance(value, (str, int, float, bool)) else _json(value)
        self._datasets: dict[str, h5py.Dataset] = {}
        self._pending: dict[str, list[np.ndarray]] = {}
        self._ncols: dict[str, int] = {}
        self._pending_rows: dict[str, int] = {}
        self._last_flush_sim: float | None = None
        self._last_flush_wall = time.monotonic()
        self._f.flush()

    @classmethod
    def for_run(cls, runs_dir: str | Path, record: Any, station: dict[str, Any] | None = None) -> Recorder:
        """The file `<runs_dir>/<run_id>.h5` with the run's identity as attributes."""
        attrs: dict[str, Any] = {
            "run_id": record.run_id,
            "procedure": record.procedure,
            "params": record.params,
            "station": station or {"id": record.station_id},
            "station_id": record.station_id,
            "simulated": bool(record.simulated),
            "software_version": record.software_version,
            "started_at": record.started_at,
            "operator": record.operator,
            "duts": record.duts,
        }
        if record.seed is not None:
            attrs["seed"] = int(record.seed)
        if record.truth is not None:
            attrs["truth"] = record.truth
        return cls(Path(runs_dir) / f"{record.run_id}.h5", attrs)

    def _text_dataset(self, name: str) -> h5py.Dataset:
        return self._f.create_dataset(name, shape=(0,), maxshape=(None,), dtype=_STR, chunks=(256,))

    # --- writing -------------------------------------------------------------------------
    def on_event(self, event: ev.Event) -> None:
        with self._lock:
            if self._f is None or not self._f.id.valid:
                return
            if isinstance(event, ev.SampleBlock):
                self.append(event.stream, event.columns, event.data)
            elif isinstance(event, ev.Measurement):
                row = {k: getattr(event, k) for k in ("name", "value", "unit", "ci95", "low", "high", "outcome", "dut")}
                row["t_sim_s"] = event.t_sim_s
                self._append_text(self._meas, _json(row))
            elif isinstance(event, ev.Log):
                self._log_row(event.t_sim_s, event.level, event.message)
            elif isinstance(event, (ev.StepStarted, ev.StepFinished)):
                kind = "step_started" if isinstance(event, ev.StepStarted) else f"step_{event.status}"
                self._log_row(event.t_sim_s, "STEP", f"{kind} {event.name}")
            elif isinstance(event, ev.FitUpdate):
                grp = self._f["fits"].require_group(event.name)
                for key, arr in event.curves.items():
                    if key in grp:
                        del grp[key]
                    grp.create_dataset(key, data=np.asarray(arr))
            self._maybe_flush(event.t_sim_s)

    def append(self, stream: str, columns: tuple[str, ...], data: np.ndarray) -> None:
        """Append rows to a stream; the first block fixes its columns.  Rows are buffered and
        written in chunk-sized pieces (and at every flush): h5py's cost is per call, not per row."""
        arr = np.asarray(data, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr.reshape(1, -1)
        with self._lock:
            ds = self._datasets.get(stream)
            if ds is None:
                ds = self._f["streams"].create_dataset(
                    stream,
                    shape=(0, arr.shape[1]),
                    maxshape=(None, arr.shape[1]),
                    dtype=np.float64,
                    chunks=(CHUNK_ROWS, arr.shape[1]),
                )
                ds.attrs["columns"] = _json(list(columns))
                self._datasets[stream] = ds
                self._pending[stream] = []
                self._ncols[stream] = arr.shape[1]
            if arr.shape[1] != self._ncols[stream]:
                raise ValueError(f"stream {stream!r}: block has {arr.shape[1]} columns, the stream has {ds.shape[1]}")
            pend = self._pending[stream]
            pend.append(arr.copy())
            self._pending_rows[stream] = self._pending_rows.get(stream, 0) + len(arr)
            if self._pending_rows[stream] >= CHUNK_ROWS:
                self._write_pending(stream)

    def _write_pending(self, stream: str) -> None:
        pend = self._pending[stream]
        if not pend:
            return
        rows = np.ascontiguousarray(np.concatenate(pend) if len(pend) > 1 else pend[0], dtype=np.float64)
        pend.clear()
        self._pending_rows[stream] = 0
        # h5py's low-level calls: the high-level resize and slice assignment cost ~0.5 ms a call
        # in selection building, and a fast lockstep run writes each stream every simulated second
        dsid = self._datasets[stream].id
        n0, ncols = dsid.shape
        n = rows.shape[0]
        dsid.set_extent((n0 + n, ncols))
        fspace = dsid.get_space()
        fspace.select_hyperslab((n0, 0), (n, ncols))
        dsid.write(h5py.h5s.create_simple((n, ncols)), fspace, rows)

    def _log_row(self, t_sim_s: float, level: str, message: str) -> None:
        self._append_text(self._log, _json({"t_sim_s": t_sim_s, "level": level, "msg": message}))

    def _append_text(self, ds: h5py.Dataset, text: str) -> None:
        n = ds.shape[0]
        ds.resize(n + 1, axis=0)
        ds[n] = text

    def _maybe_flush(self, t_sim_s: float) -> None:
        now = time.monotonic()
        if self._last_flush_sim is None:
            self._last_flush_sim = t_sim_s
        if t_sim_s - self._last_flush_sim >= FLUSH_EVERY_S or now - self._last_flush_wall >= FLUSH_EVERY_S:
            self.flush()
            self._last_flush_sim = t_sim_s
            self._last_flush_wall = now

    def flush(self) -> None:
        """Write the buffered rows and flush the file to disk."""
        with self._lock:
            if self._f is not None and self._f.id.valid:
                for stream in self._pending:
                    self._write_pending(stream)
                self._f.flush()

    def data(self) -> RunData:
        """What is recorded so far, through the open file."""
        with self._lock:
            self.flush()
            return RunData(self._f)

    def close(self, record: Any = None) -> None:
        """Write the run's end (outcome, end_reason, safe_state, measurements) and close."""
        with self._lock:
            if self._f is None:
                return
            for stream in self._pending:
                self._write_pending(stream)
            if record is not None:
                a = self._f.attrs
                a["outcome"] = record.outcome
                a["end_reason"] = record.end_reason
                a["safe_state"] = bool(record.safe_state)
                a["safe_detail"] = _json(record.safe_detail)
                a["simulated_s"] = float(record.simulated_s)
                a["wall_s"] = float(record.wall_s)
                a["finished_at"] = record.finished_at
                a["result"] = _json(record.as_json())
            self._f.close()
            self._f = None


class RunData:
    """Read access to a run's raw file (during the run or long after): attributes decoded, each
    stream as a dict of columns."""

    def __init__(self, source: str | Path | h5py.File) -> None:
        self._own = not isinstance(source, h5py.File)
        # no file lock: a run still being written can be read (the GUI, a report mid-run)
        self.f = h5py.File(source, "r", locking=False) if self._own else source
        self.path = Path(self.f.filename)
        self.attrs: dict[str, Any] = {}
        for key, value in self.f.attrs.items():
            if isinstance(value, bytes):
                value = value.decode()
            if isinstance(value, str) and value[:1] in "{[":
                try:
                    value = json.loads(value)
                except ValueError:
                    pass
            elif isinstance(value, np.generic):
                value = value.item()
            self.attrs[key] = value

    @property
    def params(self) -> dict[str, Any]:
        return dict(self.attrs.get("params", {}))

    @property
    def truth(self) -> dict[str, float] | None:
        return self.attrs.get("truth")

    def streams(self) -> list[str]:
        return list(self.f["streams"].keys())

    def columns(self, stream: str) -> list[str]:
        return json.loads(self.f["streams"][stream].attrs["columns"])

    def array(self, stream: str) -> np.ndarray:
        return self.f["streams"][stream][...]

    def table(self, stream: str) -> dict[str, np.ndarray]:
        """Columns of a stream by name: `data.table("fpga")["cx"]`."""
        arr = self.array(stream)
        return {c: arr[:, i] for i, c in enumerate(self.columns(stream))}

    def __contains__(self, stream: str) -> bool:
        return stream in self.f["streams"]

    def log(self) -> list[dict[str, Any]]:
        return [json.loads(x) for x in self.f["log"].asstr()[...]]

    def measurements(self) -> list[dict[str, Any]]:
        return [json.loads(x) for x in self.f["measurements"].asstr()[...]]

    def fits(self) -> dict[str, dict[str, np.ndarray]]:
        return {k: {c: g[c][...] for c in g} for k, g in self.f["fits"].items()}

    def close(self) -> None:
        if self._own:
            self.f.close()

    def __enter__(self) -> RunData:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_run(path: str | Path) -> RunData:
    return RunData(path)
