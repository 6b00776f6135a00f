"""Raw data of a run: one HDF5 file, written as the events arrive, readable after a crash.

Layout: `/streams/<name>` (rows x columns float64, chunked; attributes `columns`, `units`,
`dtypes` and `source` from the stream's declaration, bench.streams),
`/legends/<stream>/<column>` (a coded column's legend as a named HDF5 enum type, which h5dump
shows with its meanings; files written before these hold `legend_<column>` JSON attributes,
still read), `/parameters/<name>` (scalars with `units`), `/log` and `/measurements` (one JSON
string a row, appended as they happen), `/fits/<name>/<curve>` (with `units`, from the curve's
name), and the run's attributes on the root (params, station, software_version, truth when
simulated, procedure, run_id, ...; outcome, end_reason and safe_state once the run ends).  The file is
flushed whenever a second of data (bench-clock time; and a quarter of a wall second or CHUNK_ROWS
rows) or a second of wall time has passed since the last flush, so a process killed mid-run
leaves a readable file with all but the last second (in lockstep: the last quarter wall second).

Each stream, `/log` and `/measurements` carry `rows_flushed`: how many of their rows a completed
flush put on disk, written (and flushed) after that flush.  HDF5 writes a flush's metadata in turn
(the dataset's header with its new extent, then its chunk index, then the superblock), so a process
killed between two of those writes leaves a dataset longer than its data: rows past the extent
the index covers read as zeros.  Rows past `rows_flushed` are never data the run wrote; `RunData`
reads up to it (and says so in its notes); a closed file has it equal to every dataset's length.

While the run goes on the streams are stored uncompressed: fixed-size chunks never move, so the
index on disk after any flush points at valid data whatever happens next (a compressed chunk
that grows is moved at every flush and its old place reused, so a kill between the two could
leave the index pointing at another chunk's bytes).  `close()` then rewrites the file with the
streams gzip-compressed at level 1 (readable by the stock HDF5 tools; about 3.3x smaller; see
benchmarks/raw_compression.py) into a temporary file that replaces the original atomically.

A write that fails (disk full, read-only or failing disk) ends the recording: the recorder frees
a space reserve it holds beside the file, cuts the streams back to what the last flush put on
disk, closes the file cleanly and raises `RawDataError` (the runner ends the run on it).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import resource
import threading
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from bench.engine import events as ev
from bench.engine.context import RunAborted
from bench.engine.recording import PAUSE_LEVEL
from bench.results.redact import redact
from bench.streams import StreamSchema, schema_of, unit_from_name

CHUNK_ROWS = 4096
#: each dataset's count of rows a completed flush put on disk (rows past it are not data: module docstring)
ROWS_FLUSHED = "rows_flushed"
#: the file is flushed after each second of bench time (and each wall second): a killed process or a
#: full disk loses at most the last second of data, in lockstep as in real time (a lockstep run makes a
#: bench second in a few wall ms; benchmarks/flush_cadence.py measured no cost in wall time)
FLUSH_EVERY_S = 1.0
#: filters of the streams in the closed file: readable by the stock HDF5 tools (h5dump); chosen by
#: benchmarks/raw_compression.py.  None keeps the file as written.
#: (gzip 1 without shuffle: on today's streams smaller than gzip 4 with shuffle, and ~40 % less CPU)
STREAM_FILTERS: dict[str, Any] | None = {"compression": "gzip", "compression_opts": 1}
COMPACT_CHUNK_ROWS = 16384
#: bytes held beside the raw file and freed when the disk fills, so that the file can still be closed
RESERVE_BYTES = 1 << 20
_STR = h5py.string_dtype()


class RawDataError(RunAborted):
    """The raw file cannot be written (disk full, read-only, I/O error): the run ends at once, as
    an abort does, but with outcome ERROR."""

    outcome = "ERROR"


class _NoRoom(OSError):
    """Less room left than the recorder keeps free: disk full, declared before any write fails."""


def _json(value: Any) -> str:
    return json.dumps(value, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o))


def _why(exc: BaseException) -> str:
    """'disk full' or the system's words for a failed write (h5py wraps errno in its message)."""
    text = str(exc)
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return "disk full" if exc.strerror == os.strerror(errno.ENOSPC) else f"disk full ({exc.strerror})"
    if "errno = 28," in text:
        return "disk full"
    if isinstance(exc, OSError) and exc.errno == errno.EFBIG:
        return "file size limit reached" + (f" ({exc.strerror})" if exc.strerror != os.strerror(errno.EFBIG) else "")
    found = re.search(r"error message = '([^']*)'", text)  # HDF5's words for the system's error
    if found:
        return f"write failed ({found.group(1)})"
    if isinstance(exc, OSError) and exc.strerror:
        return f"write failed ({exc.strerror})"
    return f"write failed ({(text.splitlines() or [type(exc).__name__])[0]})"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


class Recorder:
    """Subscribes to the run's event bus and writes its raw streams and log to HDF5."""

    def __init__(self, path: str | Path, attrs: dict[str, Any] | None = None,
                 param_units: dict[str, str] | None = None) -> None:
        self.path = Path(path).resolve()
        self.failure: str | None = None  # the message, once a write has failed
        #: close() leaves the compression to the caller (`compact_in_background`): the file as
        #: written is complete and readable; `compaction_pending` says whether it is left to do
        self.defer_compaction = False
        self.compaction_pending = False
        self._lock = threading.RLock()
        self._f: h5py.File | None = None
        self._reserve: Path | None = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._take_reserve()
            self._f = h5py.File(self.path, "w")  # default format: no open-for-write flag to clear after a crash
            self._f.create_group("streams")
            self._f.create_group("fits")
            self._log = self._text_dataset("log")
            self._meas = self._text_dataset("measurements")
            for key, value in redact(attrs or {}).items():  # a store URL's password never lands in the file
                self._f.attrs[key] = value if isinstance(value, (str, int, float, bool)) else _json(value)
            self._write_parameters(dict((attrs or {}).get("params") or {}), param_units or {})
            self._f.flush()
        except (ValueError, TypeError) as exc:  # a value HDF5 cannot hold (a NUL in an id): no stub left
            self._drop_reserve()
            if self._f is not None:
                with contextlib.suppress(Exception):
                    self._f.close()
                with contextlib.suppress(OSError):
                    self.path.unlink()
            raise RawDataError(f"raw data: cannot create {self.path}: a run attribute cannot be stored ({exc})") \
                from exc
        except (OSError, RuntimeError) as exc:
            self._drop_reserve()
            if self._f is not None:
                with contextlib.suppress(Exception):
                    self._f.close()
            where = self.path if self.path.parent.is_dir() else self.path.parent
            why = _why(exc).removeprefix("write failed (").removesuffix(")")
            blocking = next((p for p in (self.path.parent, *self.path.parent.parents) if p.exists()), None)
            if blocking is not None and not blocking.is_dir():
                where, why = blocking, "it is a file, not a directory"
            elif why == "disk full":
                st = os.statvfs(self.path.parent)
                why += f" ({st.f_bavail * st.f_frsize / 1e6:.2f} MB free, a run needs {RESERVE_BYTES / 1e6:.2f} MB)"
            raise RawDataError(f"raw data: cannot create {where}: {why}") from exc
        self._datasets: dict[str, h5py.Dataset] = {}
        self._schemas: dict[str, StreamSchema] = {}  # announced by StreamDeclared events
        self._pending: dict[str, list[np.ndarray]] = {}
        self._ncols: dict[str, int] = {}
        self._pending_rows: dict[str, int] = {}
        # rows of each stream from the start of its last flushed chunk on (first row index, blocks):
        # what is rewritten from memory when a failed write may have left that chunk unreadable
        self._tail: dict[str, tuple[int, list[np.ndarray]]] = {}
        self._flushed_rows: dict[str, int] = {"log": 0, "measurements": 0}
        self._marked: dict[str, int] = {"log": 0, "measurements": 0}  # rows_flushed as written
        self._flushed_t: float | None = None
        self._last_t: float | None = None
        self._last_flush_sim: float | None = None
        self._last_flush_wall = time.monotonic()

    # --- the space reserve ---------------------------------------------------------------
    def _take_reserve(self) -> None:
        """Hold RESERVE_BYTES on the file's disk (freed to close the file when the disk fills);
        reserves and half-written compressed copies left by killed processes are removed."""
        for pattern in (".*.reserve-*", ".*.compact-*"):
            for old in self.path.parent.glob(pattern):
                pid = old.name.rpartition("-")[2]
                if pid.isdigit() and not _pid_alive(int(pid)):
                    with contextlib.suppress(OSError):
                        old.unlink()
        reserve = self.path.parent / f".{self.path.name}.reserve-{os.getpid()}"
        fd = os.open(reserve, os.O_CREAT | os.O_WRONLY | os.O_TRUNC, 0o600)
        self._reserve = reserve
        try:
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            except OSError as exc:
                if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                    raise
                os.write(fd, bytes(RESERVE_BYTES))  # a file system without fallocate
        finally:
            os.close(fd)

    def _drop_reserve(self) -> None:
        if self._reserve is not None:
            with contextlib.suppress(OSError):
                self._reserve.unlink()
            self._reserve = None

    @classmethod
    def for_run(cls, runs_dir: str | Path, record: Any, station: dict[str, Any] | None = None,
                param_units: dict[str, str] | None = None) -> Recorder:
        """The file `<runs_dir>/<run_id>.h5` with the run's identity as attributes and its
        parameters (with their units) as `/parameters`."""
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
        return cls(Path(runs_dir) / f"{record.run_id}.h5", attrs, param_units)

    def _text_dataset(self, name: str) -> h5py.Dataset:
        ds = self._f.create_dataset(name, shape=(0,), maxshape=(None,), dtype=_STR, chunks=(256,))
        ds.attrs[ROWS_FLUSHED] = np.int64(0)
        return ds

    def _named_datasets(self) -> tuple[tuple[str, h5py.Dataset], ...]:
        """Every dataset that grows during the run, by the name `_flushed_rows` keeps it under."""
        return (*self._datasets.items(), ("log", self._log), ("measurements", self._meas))

    def _mark_flushed(self) -> None:
        """Each dataset's `rows_flushed` to what the last completed flush put on disk, then flushed
        itself: only ever a count of rows whose data and index are already on disk."""
        marked = self._marked
        changed = False
        for name, ds in self._named_datasets():
            n = self._flushed_rows.get(name, 0)
            if marked.get(name) != n:
                h5py.h5a.open(ds.id, ROWS_FLUSHED.encode()).write(np.array(n, dtype=np.int64))
                marked[name] = n
                changed = True
        if changed:
            self._f.flush()

    # --- writing -------------------------------------------------------------------------
    def on_event(self, event: ev.Event) -> None:
        """Write one event; raises RawDataError once, on the write that fails."""
        with self._lock:
            if self._f is None or self.failure is not None or not self._f.id.valid:
                return
            self._last_t = event.t_sim_s
            try:
                self._write_event(event)
                self._maybe_flush(event.t_sim_s)
            except (OSError, RuntimeError) as exc:
                self._fail(exc)

    def _write_event(self, event: ev.Event) -> None:
        if isinstance(event, ev.SampleBlock):
            self.append(event.stream, event.columns, event.data)
        elif isinstance(event, ev.StreamDeclared):
            self._schemas[event.schema.name] = event.schema
        elif isinstance(event, ev.RunStarted):  # the replay's time origin: the run's start, in bench time
            self._f.attrs["t_start_s"] = float(event.t_sim_s)
        elif isinstance(event, ev.Measurement):
            keys = ("name", "value", "unit", "ci95", "low", "high", "marginal_low", "marginal_high", "outcome", "dut")
            row = {k: getattr(event, k) for k in keys}
            row["t_sim_s"] = event.t_sim_s
            self._append_text(self._meas, _json(row))
        elif isinstance(event, ev.Log):
            self._log_row(event.t_sim_s, event.level, event.message)
        elif isinstance(event, (ev.StepStarted, ev.StepFinished)):
            kind = "step_started" if isinstance(event, ev.StepStarted) else f"step_{event.status}"
            self._log_row(event.t_sim_s, "STEP", f"{kind} {event.name}")
        elif isinstance(event, ev.FitUpdate):
            grp = self._f["fits"].require_group(event.name)
            declared = _fit_columns(event.name)
            for key, arr in event.curves.items():
                if key in grp:
                    del grp[key]
                ds = grp.create_dataset(key, data=np.asarray(arr))
                col = declared.get(key)
                ds.attrs["units"] = col.unit if col is not None else unit_from_name(key)
                if col is not None and col.quantity:
                    ds.attrs["quantity"] = col.quantity

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
                self._describe(ds, stream, tuple(columns))
                ds.attrs[ROWS_FLUSHED] = np.int64(0)
                self._datasets[stream] = ds
                self._pending[stream] = []
                self._ncols[stream] = arr.shape[1]
                self._flushed_rows.setdefault(stream, 0)
                self._tail[stream] = (0, [])
            if arr.shape[1] != self._ncols[stream]:
                raise ValueError(f"stream {stream!r}: block has {arr.shape[1]} columns, the stream has {ds.shape[1]}")
            pend = self._pending[stream]
            pend.append(arr.copy())
            self._pending_rows[stream] = self._pending_rows.get(stream, 0) + len(arr)
            if self._pending_rows[stream] >= CHUNK_ROWS:
                self._write_pending(stream)

    def _describe(self, ds: h5py.Dataset, stream: str, columns: tuple[str, ...]) -> None:
        """A stream's declaration in its dataset's attributes: `columns`, `units`, `dtypes` (each
        column's own type; the table is stored as float64) and `source`; each coded column's legend
        is the enum type /legends/<stream>/<column> (code -> meaning).  A stream announced by no StreamDeclared
        event takes the schema declared under its name if the columns agree, or else units from
        its column names (a file written outside a run)."""
        schema = self._schemas.get(stream)
        if schema is not None and schema.names != columns:
            raise ValueError(f"stream {stream!r}: columns {columns} are not the declared {schema.names}")
        if schema is None:
            with contextlib.suppress(KeyError):
                schema = schema_of(stream)
            if schema is not None and schema.names != columns:
                schema = None
        ds.attrs["columns"] = _json(list(columns))
        if schema is None:
            ds.attrs["units"] = np.array([unit_from_name(c) for c in columns], dtype=_STR)
            ds.attrs["dtypes"] = np.array(["f8"] * len(columns), dtype=_STR)
            return
        ds.attrs["source"] = schema.source
        ds.attrs["units"] = np.array(schema.units, dtype=_STR)
        ds.attrs["quantities"] = np.array(schema.quantities, dtype=_STR)
        ds.attrs["dtypes"] = np.array([c.dtype for c in schema.columns], dtype=_STR)
        for col in schema.columns:  # a coded column's legend is an HDF5 enum type: /legends/<stream>/<column>
            if col.legend:
                grp = self._f.require_group(f"legends/{stream}")
                if col.name not in grp:
                    base = np.dtype(col.dtype) if np.dtype(col.dtype).kind in "iu" else np.dtype("i8")
                    grp[col.name] = h5py.enum_dtype({meaning: code for code, meaning in col.legend}, basetype=base)

    def _write_parameters(self, params: dict[str, Any], units: dict[str, str]) -> None:
        """The run's parameters as `/parameters/<name>` scalars, each with its `units`."""
        grp = self._f.create_group("parameters")
        for name, value in params.items():
            data = value if isinstance(value, (bool, int, float, np.number)) else str(value)
            grp.create_dataset(name, data=data).attrs["units"] = units.get(name) or "1"

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
        self._tail[stream][1].append(rows)

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
        wall_s = now - self._last_flush_wall
        if t_sim_s - self._last_flush_sim >= FLUSH_EVERY_S or wall_s >= FLUSH_EVERY_S:
            self._flush()
            self._last_flush_sim = t_sim_s
            self._last_flush_wall = now

    def _check_space(self) -> None:
        """Disk full is declared while RESERVE_BYTES are still free, before a write fails: a write
        that HDF5 saw fail may leave its internal state (and the file it closes) inconsistent.
        The same for the process's file size limit (ulimit -f)."""
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if limit != resource.RLIM_INFINITY:
            size = self.path.stat().st_size
            if size + RESERVE_BYTES > limit:
                raise _NoRoom(errno.EFBIG, f"{size / 1e6:.2f} MB written, the process's file size limit is "
                                           f"{limit / 1e6:.2f} MB")
        st = os.statvfs(self.path.parent)
        free = st.f_bavail * st.f_frsize
        if free < RESERVE_BYTES:
            raise _NoRoom(
                errno.ENOSPC,
                f"{free / 1e6:.2f} MB free on {self.path.parent}, "
                f"the recorder stops below {RESERVE_BYTES / 1e6:.2f} MB",
            )

    def _flush(self) -> None:
        self._check_space()
        for stream in self._pending:
            self._write_pending(stream)
        self._f.flush()
        # what is on disk now: a failure later cuts the file back to this
        for name, ds in self._named_datasets():
            self._flushed_rows[name] = ds.shape[0]
        for stream, (start, blocks) in self._tail.items():
            n = self._flushed_rows[stream]
            keep_from = (n // CHUNK_ROWS) * CHUNK_ROWS
            rows = np.concatenate(blocks) if len(blocks) > 1 else (blocks[0] if blocks else np.empty((0, 0)))
            self._tail[stream] = (keep_from, [rows[keep_from - start : n - start]] if n > keep_from else [])
        self._flushed_t = self._last_t
        self._mark_flushed()

    def flush(self) -> None:
        """Write the buffered rows and flush the file to disk (RawDataError if that fails)."""
        with self._lock:
            if self._f is not None and self.failure is None and self._f.id.valid:
                try:
                    self._flush()
                except (OSError, RuntimeError) as exc:
                    self._fail(exc)

    # --- a failed write ----------------------------------------------------------------------
    def _fail(self, exc: BaseException) -> None:
        """Keep what the last flush put on disk, close the file cleanly, raise RawDataError."""
        if self.failure is not None:
            raise RawDataError(self.failure) from exc
        t = "?" if self._last_t is None else f"{self._last_t:.1f}"
        kept = "nothing" if self._flushed_t is None else f"the data up to t = {self._flushed_t:.1f} s"
        kind, _, detail = _why(exc).partition(" (")
        detail = f" ({detail}" if detail else ""
        self.failure = f"raw data: {kind} at t = {t} s{detail}; {kept} is kept in {self.path}"
        if not self.path.exists():  # the file (or its folder) was removed under the run: nothing is kept
            gone = self.path if self.path.parent.is_dir() else f"{self.path} (its folder {self.path.parent} too)"
            self.failure = (f"raw data: {kind} at t = {t} s{detail}; the raw file {gone} was deleted during the run: "
                            "all of its recorded data is lost")
            self._drop_reserve()
            with contextlib.suppress(Exception):
                self._f.close()
            self._f = None  # nothing left to close
            raise RawDataError(self.failure) from exc
        self._drop_reserve()  # room for the file's last metadata
        try:
            if not isinstance(exc, _NoRoom):  # HDF5 saw a write fail: its state is not to be trusted
                self._reopen()
            self._cut_back()
        except Exception as again:  # noqa: BLE001 - the disk refuses even this
            self.failure += f" (and reopening it to close it: {_why(again)}; the file may lack its last second)"
        raise RawDataError(self.failure) from exc

    def _reopen(self) -> None:
        """Close the file without letting HDF5 write any more (its descriptor is pointed at
        /dev/null first), then open it again from what is on disk."""
        fd = self._f.id.get_vfd_handle()
        null = os.open(os.devnull, os.O_RDWR)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
        with contextlib.suppress(Exception):
            self._f.close()
        self._f = None
        try:
            self._f = h5py.File(self.path, "r+")
        except OSError as exc:  # the superblock's end of file went to disk, the data at its end did not
            stored = re.search(r"truncated file: .*stored_eof = (\d+)", str(exc))
            if stored is None:
                raise
            os.truncate(self.path, int(stored.group(1)))  # a hole: no block of the disk is needed
            self._f = h5py.File(self.path, "r+")
        self._log, self._meas = self._f["log"], self._f["measurements"]
        self._datasets = {name: self._f["streams"][name] for name in self._f["streams"]}

    def _cut_back(self) -> None:
        """Each stream, the log and the measurements back to the last flush (rows after it may
        never have reached the disk), the last flushed chunk rewritten from memory, the failure
        logged, then flushed."""
        for name, ds in self._named_datasets():
            n = min(ds.shape[0], self._flushed_rows.get(name, 0))
            if ds.shape[0] != n:
                ds.resize(n, axis=0)
        for stream, (start, blocks) in self._tail.items():
            n = self._flushed_rows.get(stream, 0)
            if stream in self._datasets and blocks and n > start:
                self._datasets[stream][start:n] = np.concatenate(blocks)[: n - start]
        for pend in self._pending.values():
            pend.clear()
        self._log_row(self._last_t or 0.0, "ERROR", self.failure)
        self._f.flush()
        for _name, ds in self._named_datasets():
            ds.attrs[ROWS_FLUSHED] = np.int64(ds.shape[0])  # what is kept, all of it on disk now
        self._f.flush()

    def data(self) -> RunData:
        """What is recorded so far, through the open file (RawDataError once a write failed)."""
        with self._lock:
            if self.failure is not None:
                raise RawDataError(self.failure)
            self.flush()
            return RunData(self._f)

    def close(self, record: Any = None) -> None:
        """Write the run's end (outcome, end_reason, safe_state, measurements) and close."""
        with self._lock:
            if self._f is None:
                return
            try:
                if self.failure is None:
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
                    a["stream_overflow_blocks"] = int(getattr(record, "stream_overflow_blocks", 0))
                    if self.failure is not None:
                        a["incomplete"] = self.failure
                if self.failure is None:  # every row on disk, then said so (a kill in between: the last count)
                    self._f.flush()
                    for name, ds in self._named_datasets():
                        self._flushed_rows[name] = ds.shape[0]
                    self._mark_flushed()
            except (OSError, RuntimeError) as exc:
                failed_now = self.failure is None
                with contextlib.suppress(RawDataError):
                    self._fail(exc)
                if failed_now:
                    raise RawDataError(self.failure) from exc
            finally:
                f, self._f = self._f, None
                self._drop_reserve()
                f.close()
            if STREAM_FILTERS is not None and self.failure is None:
                if self.defer_compaction:
                    self.compaction_pending = True
                else:
                    compact(self.path, STREAM_FILTERS)


def compact(path: str | Path, filters: dict[str, Any], chunk_rows: int = COMPACT_CHUNK_ROWS) -> bool:
    """Rewrite a closed raw file with its streams filtered (compressed); the original is replaced
    atomically and kept as it is if anything fails (a full disk).  True when it was replaced."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.compact-{os.getpid()}")
    before = _stamp(path)
    st = os.statvfs(path.parent)
    if st.f_bavail * st.f_frsize < path.stat().st_size + RESERVE_BYTES:
        return False  # a write failing inside HDF5 is what the recorder never lets happen
    try:
        # no lock on the source, as RunData: a window may open the run's report meanwhile (the
        # run has finished for it; a mismatch of lock flags in one process refuses the open)
        with h5py.File(path, "r", locking=False) as src, h5py.File(tmp, "w") as dst:
            dst.attrs.update(src.attrs)
            for name in src:
                if name != "streams":
                    src.copy(src[name], dst, name=name)
            streams = dst.create_group("streams")
            for name, ds in src["streams"].items():
                n, ncols = ds.shape
                out = streams.create_dataset(
                    name, shape=ds.shape, maxshape=(None, ncols), dtype=ds.dtype,
                    chunks=(max(1, min(n, chunk_rows)), ncols), **filters,
                )
                for a in range(0, n, 8 * chunk_rows):
                    out[a : a + 8 * chunk_rows] = ds[a : a + 8 * chunk_rows]
                out.attrs.update(ds.attrs)
        if _stamp(path) != before:  # written meanwhile (an annotation): that file stays, uncompressed
            raise RuntimeError(f"{path} changed while it was compressed")
        os.replace(tmp, path)
        return True
    except Exception:  # noqa: BLE001 - whatever went wrong, the file as written stays
        with contextlib.suppress(OSError):
            tmp.unlink()
        return False


def _stamp(path: Path) -> tuple[int, int, int]:
    """(inode, size, modification time in ns): whether a file was written since."""
    st = path.stat()
    return st.st_ino, st.st_size, st.st_mtime_ns


def compact_in_background(path: str | Path) -> Any:
    """Compress a closed raw file in a detached process (`python -m bench.compaction`), so a command
    returns without waiting ~1 s for it: until the atomic replace the file is the complete one as
    written, and a file written meanwhile is left as it is (`compact`).  The Popen."""
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-m", "bench.compaction", str(path)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)


def annotate(path: str | Path, key: str, value: Any) -> None:
    """Add one attribute to a finished run's raw file (JSON for a dict or list): what a face
    decided after the run, e.g. the lab's limits and their verdicts (`gyrobench run --limits`)."""
    with h5py.File(path, "a") as f:
        f.attrs[key] = value if isinstance(value, (str, int, float, bool)) else _json(value)


def data_rows(ds: h5py.Dataset) -> tuple[np.ndarray, int]:
    """(the rows of a dataset that are data, how many rows past them were left out): up to its
    `rows_flushed` where a writer stopped mid-flush left it longer (the module's docstring); all of
    it in a file written before the attribute or held open by its writer."""
    n = ds.shape[0]
    kept = int(ds.attrs[ROWS_FLUSHED]) if ROWS_FLUSHED in ds.attrs else n
    if kept < n:
        return ds[:kept], n - kept
    return ds[()], 0


class MissingStream(KeyError):
    """A stream the analysis needs is not in the raw file (the run ended before writing it)."""

    def __str__(self) -> str:
        return str(self.args[0])


class RunData:
    """Read access to a run's raw file (during the run or long after): attributes decoded, each
    stream as a dict of columns.  `incomplete` says why a run's data may be partial; an
    analysis hook adds to `notes` what it did about it."""

    def __init__(self, source: str | Path | h5py.File) -> None:
        self._own = not isinstance(source, h5py.File)
        self._arrays: dict[str, np.ndarray] = {}  # array(): each stream read once (read-only files)
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
        self.notes: list[str] = []

    @property
    def incomplete(self) -> str | None:
        """Why the recorded data may be partial (killed, aborted, failed, disk full); None when
        the run went through all its steps."""
        a = self.attrs
        if "outcome" not in a:
            return "the run did not finish (the process was killed or is still running)"
        if a.get("incomplete"):
            return str(a["incomplete"])
        if a["outcome"] in ("ERROR", "ABORTED"):
            return f"the run ended {a['outcome']} ({a.get('end_reason', '')})"
        return None

    def step_span(self, step: str) -> tuple[float | None, float | None]:
        """Bench times at which a step started and ended (None where the log has no such row)."""
        start = end = None
        for r in self.log():
            kind, _, name = str(r.get("msg", "")).partition(" ")
            if r.get("level") != "STEP" or name != step:
                continue
            if kind == "step_started":
                start, end = r["t_sim_s"], None
            else:
                end = r["t_sim_s"]
        return start, end

    def pauses(self) -> list[tuple[float, float]]:
        """The run's pauses as (bench time paused, bench time resumed), from the log's PAUSE rows
        (a pause the run never resumed from runs to the last row's time)."""
        spans, start, last = [], None, None
        for r in self.log():
            last = r.get("t_sim_s", last)
            if r.get("level") != PAUSE_LEVEL:
                continue
            if str(r.get("msg", "")).startswith("paused"):
                start = r["t_sim_s"]
            elif start is not None:
                spans.append((float(start), float(r["t_sim_s"])))
                start = None
        if start is not None and last is not None:
            spans.append((float(start), float(last)))
        return spans

    @property
    def params(self) -> dict[str, Any]:
        return dict(self.attrs.get("params", {}))

    @property
    def truth(self) -> dict[str, float] | None:
        return self.attrs.get("truth")

    def streams(self) -> list[str]:
        return list(self.f["streams"].keys())

    def _stream(self, stream: str) -> h5py.Dataset:
        if stream not in self.f["streams"]:
            why = self.incomplete
            raise MissingStream(
                f"{self.path.name} has no stream {stream!r} (it has: {', '.join(self.streams()) or 'none'})"
                + (f"; {why}" if why else "")
            )
        return self.f["streams"][stream]

    def columns(self, stream: str) -> list[str]:
        return json.loads(self._stream(stream).attrs["columns"])

    def units(self, stream: str) -> dict[str, str]:
        """Each column's unit, from the stream's declaration ("" where a file predates them)."""
        units = self._stream(stream).attrs.get("units")
        names = self.columns(stream)
        if units is None:
            return dict.fromkeys(names, "")
        return {c: u.decode() if isinstance(u, bytes) else str(u) for c, u in zip(names, units, strict=True)}

    def declared(self, source: str) -> dict[str, tuple[str, str]]:
        """(quantity, unit) of each column of a stream, or each curve of a fit, as the run declared
        it (quantity: the column's name where none is declared; unit: "" where a file predates them)."""
        def text(v: Any) -> str:
            return v.decode() if isinstance(v, bytes) else str(v)

        if source in self.f["streams"]:
            attrs, names = self._stream(source).attrs, self.columns(source)
            quantities = attrs.get("quantities")
            quantities = [text(q) for q in quantities] if quantities is not None else names
            return {c: (q or c, u) for c, q, u in zip(names, quantities, self.units(source).values(), strict=True)}
        if source in self.f["fits"]:
            return {c: (text(ds.attrs.get("quantity", c)), text(ds.attrs.get("units", "")))
                    for c, ds in self.f["fits"][source].items()}
        raise MissingStream(f"{self.path.name} has no stream or fit {source!r}")

    def legends(self, stream: str) -> dict[str, dict[int, str]]:
        """The coded columns' legends (code -> meaning), from the stream's declaration."""
        return stored_legends(self.f, stream, self._stream(stream).attrs)

    def _rows(self, name: str, ds: h5py.Dataset) -> np.ndarray:
        """A dataset's rows that are data: in a file read from disk, up to its `rows_flushed`
        when a writer killed mid-flush left it longer (the module's docstring), said in `notes`.
        The recorder's own open file (a run's ctx.data()) holds every row it wrote."""
        if not self._own:
            return ds[...]
        rows, left_out = data_rows(ds)
        if left_out:
            note = (f"{name}: its last {left_out} of {ds.shape[0]} rows are past the last flush that completed "
                    f"(the writer was stopped mid-flush): not read, they may not be data")
            if note not in self.notes:
                self.notes.append(note)
        return rows

    def array(self, stream: str) -> np.ndarray:
        """The stream's rows (a copy the caller may change).  A file this object opened read-only
        is read and decompressed once per stream: a report's figures read the FPGA stream twice."""
        if not self._own:  # a file someone else holds (it may still be written)
            return self._stream(stream)[...]
        cached = self._arrays.get(stream)
        if cached is None:
            cached = self._arrays[stream] = self._rows(stream, self._stream(stream))
        return cached.copy()

    def read_streams(self) -> None:
        """Read and decompress every stream once now (a file this object opened): processes forked
        after this share the rows instead of each decompressing them again."""
        if self._own:
            for stream in self.streams():
                if stream not in self._arrays:
                    self._arrays[stream] = self._rows(stream, self._stream(stream))

    def reopen(self) -> None:
        """A handle of this process's own on the same file (in a forked process: HDF5's state and
        the file's descriptor are not shared with the parent's)."""
        if self._own:
            self.f = h5py.File(self.path, "r", locking=False)

    def table(self, stream: str) -> dict[str, np.ndarray]:
        """Columns of a stream by name: `data.table("fpga")["cx"]`."""
        arr = self.array(stream)
        return {c: arr[:, i] for i, c in enumerate(self.columns(stream))}

    def __contains__(self, stream: str) -> bool:
        return stream in self.f["streams"]

    def log(self) -> list[dict[str, Any]]:
        return [json.loads(x) for x in self._text("log")]

    def measurements(self) -> list[dict[str, Any]]:
        return [json.loads(x) for x in self._text("measurements")]

    def _text(self, name: str) -> list[str]:
        return [x.decode() if isinstance(x, bytes) else x for x in self._rows(name, self.f[name])]

    def fits(self) -> dict[str, dict[str, np.ndarray]]:
        return {k: {c: g[c][...] for c in g} for k, g in self.f["fits"].items()}

    def close(self) -> None:
        if self._own:
            self.f.close()

    def __enter__(self) -> RunData:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _fit_columns(name: str) -> dict[str, Any]:
    """The declared columns of a fit's curves (a StreamSchema declared under the fit's name), by
    curve name; {} for a fit declared nowhere (its curves' units then come from their names)."""
    try:
        return {c.name: c for c in schema_of(name).columns}
    except KeyError:
        return {}


def stored_legends(f: h5py.File, stream: str, attrs: Any) -> dict[str, dict[int, str]]:
    """A stream's legends (column -> code -> meaning) from the enum types under /legends/<stream>,
    or, in a file written before those, from its dataset's `legend_<column>` JSON attributes."""
    out: dict[str, dict[int, str]] = {}
    grp = f.get("legends")
    if grp is not None and stream in grp:
        for col, typ in grp[stream].items():
            mapping = h5py.check_enum_dtype(typ.dtype)
            if mapping:
                out[col] = {int(code): meaning for meaning, code in sorted(mapping.items(), key=lambda kv: kv[1])}
    for key in attrs:
        if key.startswith("legend_") and key[len("legend_"):] not in out:
            value = attrs[key]
            value = value.decode() if isinstance(value, bytes) else str(value)
            out[key[len("legend_"):]] = {int(k): v for k, v in json.loads(value).items()}
    return out


class NotARunFile(ValueError):
    """An HDF5 file that is not a gyrobench raw file (another program's), or whose run attributes
    cannot be read (params that are not JSON)."""


#: what every raw file holds from its first flush (Recorder.__init__)
RUN_PARTS = ("streams", "fits", "log", "measurements")


def check_run_file(data: RunData) -> RunData:
    """data if it is a gyrobench raw file, else NotARunFile saying what it lacks."""
    missing = [part for part in RUN_PARTS if part not in data.f]
    if missing:
        raise NotARunFile(f"{data.path}: not a gyrobench raw file (it has no {', '.join(missing)})")
    for key in ("params", "station", "truth"):
        if key in data.attrs and not isinstance(data.attrs[key], dict):
            raise NotARunFile(f"{data.path}: attribute {key!r} is not a JSON object: {str(data.attrs[key])[:60]!r}")
    return data


def open_run(path: str | Path) -> RunData:
    """A raw file opened for reading; NotARunFile if it is HDF5 but not a gyrobench run."""
    data = RunData(path)
    try:
        return check_run_file(data)
    except NotARunFile:
        data.close()
        raise
