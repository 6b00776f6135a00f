"""Replay a recorded run (the recorder's HDF5 file) as the same events a live run sends, so it
lands in the same plots, with its fit.

The reader is tolerant of layout: every 2-D dataset that carries a `columns` attribute (on
itself or its group) is a stream named after the dataset (or its group); root attributes give
the run id, procedure, station and parameters; stored fits (`fits/<name>/<curve>`) are used when
present, else the E(t) decay is fitted here (log-linear, the same model the live plot draws).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from bench.analysis.slow_model import orbit_elements
from bench.engine import events as ev
from bench.recorder import data_rows, stored_legends
from bench.streams import StreamSchema, schema_from_attrs

CHUNK_ROWS = 20_000


def _text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _text(value.item())
    return str(value)


def _json_row(raw: Any) -> dict[str, Any]:
    try:
        row = json.loads(_text(raw))
    except json.JSONDecodeError:
        return {"message": _text(raw)}
    return row if isinstance(row, dict) else {"message": str(row)}


def _columns(obj: h5py.Dataset) -> tuple[str, ...] | None:
    for holder in (obj, obj.parent):
        if "columns" in holder.attrs:
            raw = holder.attrs["columns"]
            if isinstance(raw, (str, bytes)):
                text = _text(raw)
                try:
                    return tuple(json.loads(text))
                except json.JSONDecodeError:
                    return tuple(c.strip() for c in text.split(","))
            return tuple(_text(c) for c in raw)
    if obj.dtype.names:  # a compound dataset names its own columns
        return tuple(obj.dtype.names)
    return None


def _streams(f: h5py.File) -> list[tuple[str, tuple[str, ...], np.ndarray, StreamSchema | None]]:
    found: list[tuple[str, tuple[str, ...], np.ndarray, StreamSchema | None]] = []

    def visit(name: str, obj: Any) -> None:
        if not isinstance(obj, h5py.Dataset) or name.startswith("fits/"):
            return
        cols = _columns(obj)
        if cols is None:
            return
        data = data_rows(obj)[0]  # a writer stopped mid-flush: only the rows it wrote
        if data.dtype.names:
            data = np.column_stack([data[c].astype(float) for c in data.dtype.names]) if len(data) else \
                np.empty((0, len(cols)))
        if data.ndim != 2 or data.shape[1] != len(cols):
            return
        parts = name.split("/")
        stream = parts[-1] if parts[-1] not in ("data", "rows") or len(parts) == 1 else parts[-2]
        stream = _text(obj.attrs.get("stream", stream))
        legends = stored_legends(f, stream, obj.attrs)
        found.append((stream, cols, np.asarray(data, dtype=float), schema_from_attrs(stream, cols, obj.attrs, legends)))

    f.visititems(visit)
    return found


def _stored_fits(f: h5py.File) -> dict[str, dict[str, np.ndarray]]:
    fits: dict[str, dict[str, np.ndarray]] = {}
    if "fits" in f:
        for name, group in f["fits"].items():
            if isinstance(group, h5py.Group):
                fits[name] = {k: np.asarray(v[()], dtype=float) for k, v in group.items()}
    return fits


def decay_fit(t_s: np.ndarray, q: np.ndarray, n_points: int = 200) -> dict[str, np.ndarray] | None:
    """E(t) = E0 exp(-2 t / tau) fitted log-linearly to recorded cx, sx, cy, sy; None when the
    record is too short or E is not positive."""
    if len(t_s) < 3:
        return None
    e = orbit_elements(q)["E"]
    ok = e > 0
    if ok.sum() < 3:
        return None
    slope, icept = np.polyfit(t_s[ok], np.log(e[ok]), 1)
    t_fit = np.linspace(t_s[ok][0], t_s[ok][-1], n_points)
    tau_s = -2.0 / slope if slope < 0 else np.inf
    return {"t_s": t_fit, "E": np.exp(icept + slope * t_fit), "tau_s": np.array([tau_s])}


def replay_events(path: str | Path) -> list[ev.Event]:
    """The events of a recorded run, in order: RunStarted, its sample blocks, fits,
    measurements, RunFinished."""
    path = Path(path)
    with h5py.File(path, "r") as f:
        attrs = {k: f.attrs[k] for k in f.attrs}
        run_id = _text(attrs.get("run_id", path.stem))
        params_raw = attrs.get("params", attrs.get("parameters", "{}"))
        try:
            params = json.loads(_text(params_raw))
        except json.JSONDecodeError:
            params = {"params": _text(params_raw)}
        streams = _streams(f)
        fits = _stored_fits(f)
        rows = {k: [_json_row(r) for r in data_rows(f[k])[0]] for k in ("measurements", "log") if k in f}
    if not streams:
        raise ValueError(f"{path} has no stream with a 'columns' attribute")
    t_start = run_start_s(attrs, streams, rows.get("log", []))
    t_end = t_start
    out: list[ev.Event] = [ev.RunStarted(run_id, t_start, procedure=_text(attrs.get("procedure", "replay")),
                                         params=params, station=_text(attrs.get("station", "")),
                                         simulated=bool(attrs.get("simulated", False)), steps=("replay",))]
    for stream, cols, data, schema in streams:
        if schema is not None:  # the declaration the file stored, announced as a live run does
            out.append(ev.StreamDeclared(run_id, t_end, schema=schema))
        t_col = cols.index("t_s") if "t_s" in cols else None
        for i in range(0, len(data), CHUNK_ROWS):
            chunk = data[i:i + CHUNK_ROWS]
            t = float(chunk[-1, t_col]) if t_col is not None and len(chunk) else t_end
            t_end = max(t_end, t)
            out.append(ev.SampleBlock(run_id, t, stream=stream, columns=cols, data=chunk))
        if not fits and all(c in cols for c in ("t_s", "cx", "sx", "cy", "sy")):
            idx = [cols.index(c) for c in ("cx", "sx", "cy", "sy")]
            fit = decay_fit(data[:, t_col], data[:, idx])
            if fit is not None:
                fits["E decay (replay fit)"] = fit
                out.append(ev.Log(run_id, t_end, message=f"replay fit: tau = {float(fit['tau_s'][0]):.3f} s"))
    for name, curves in fits.items():
        out.append(ev.FitUpdate(run_id, t_end, name=name, curves=curves))
    for row in rows.get("log", []):
        out.append(ev.Log(run_id, float(row.get("t_sim_s", t_end)), level=str(row.get("level", "INFO")),
                          message=str(row.get("msg", row.get("message", "")))))
    for row in rows.get("measurements", []):
        out.append(ev.Measurement(run_id, float(row.get("t_sim_s", t_end)), name=str(row.get("name", "?")),
                                  value=float(row.get("value", float("nan"))), unit=str(row.get("unit", "")),
                                  low=row.get("low"), high=row.get("high"),
                                  outcome=str(row.get("outcome", "COMPLETE")), dut=row.get("dut"),
                                  ci95=_interval(row.get("ci95"))))
    out.append(ev.StepFinished(run_id, t_end, name="replay", index=0))
    out.append(ev.RunFinished(run_id, t_end, outcome=_text(attrs.get("outcome", "COMPLETE")),
                              end_reason=f"replay of {path.name}", safe_state=bool(attrs.get("safe_state", False)),
                              raw_file=str(path)))
    return out


def run_start_s(attrs: dict[str, Any], streams: list, log_rows: list[dict[str, Any]]) -> float:
    """The run's start in bench time: the file's `t_start_s`, else the earliest time it recorded
    (any stream's first t_s, the first log row), never one stream chosen by its name."""
    if "t_start_s" in attrs:
        return float(attrs["t_start_s"])
    times = [float(data[0, cols.index("t_s")]) for _s, cols, data, _schema in streams if "t_s" in cols and len(data)]
    times += [float(r["t_sim_s"]) for r in log_rows[:1] if "t_sim_s" in r]
    return min(times) if times else 0.0


def _interval(value: Any) -> tuple[float, float] | None:
    """A recorded 95 % interval as (low, high), or None when the row has none."""
    try:
        lo, hi = value
        return float(lo), float(hi)
    except (TypeError, ValueError):
        return None
