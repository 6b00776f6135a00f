"""Streams with a schema: each stream of a run is declared once (its source, and each column's
name, unit, type and, for a coded column, the legend of its codes), announced with a
`StreamDeclared` event before its first block, stored with the raw data, and read by name.

    WINDOWS = declare(StreamSchema("damping_windows", "hrg-damping", (
        Column("kind", "1", "i8", legend={0: "decay", 1: "verify_off", 2: "verify_on"}),
        Column("t_start_s", "s"), Column("t_end_s", "s"))))
    WINDOWS.column(block, "t_start_s");  WINDOWS.columns_of(block, "t_start_s", "t_end_s")

Blocks travel (and are stored) as float64 tables; `dtype` is the column's own type, to which a
reader casts (`RunData.table`).  A unit of "1" is dimensionless.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

DIMENSIONLESS = "1"


@dataclass(frozen=True)
class Column:
    """One column: its name, unit ("1" when dimensionless), numpy type code, for a coded column
    what each code means, and the quantity it holds in words (an axis names it: "table rate Ω")."""

    name: str
    unit: str
    dtype: str = "f8"
    legend: tuple[tuple[int, str], ...] = ()
    doc: str = ""
    quantity: str = ""

    def __init__(self, name: str, unit: str, dtype: str = "f8", legend: Mapping[int, str] | None = None,
                 doc: str = "", quantity: str = "") -> None:
        if not name.isidentifier():
            raise ValueError(f"column name {name!r} is not an identifier")
        np.dtype(dtype)  # a bad type code fails here, where it is declared
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "unit", unit or DIMENSIONLESS)
        object.__setattr__(self, "dtype", dtype)
        object.__setattr__(self, "legend", tuple(sorted((int(k), str(v)) for k, v in (legend or {}).items())))
        object.__setattr__(self, "doc", doc)
        object.__setattr__(self, "quantity", quantity)

    def code(self, meaning: str) -> int:
        """The code of a meaning in this column's legend."""
        for k, v in self.legend:
            if v == meaning:
                return k
        raise KeyError(f"column {self.name!r} has no code for {meaning!r} (legend: {dict(self.legend)})")


@dataclass(frozen=True)
class StreamSchema:
    """A stream's declaration: its name, where it comes from, its columns in order."""

    name: str
    source: str
    columns: tuple[Column, ...]
    _index: dict[str, int] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        names = [c.name for c in self.columns]
        if len(set(names)) != len(names):
            raise ValueError(f"stream {self.name!r}: a column name repeats in {names}")
        self._index.update({n: i for i, n in enumerate(names)})
        # computed once: every block on the stream path compares its columns with them
        object.__setattr__(self, "_names", tuple(names))
        object.__setattr__(self, "_units", tuple(c.unit for c in self.columns))

    @property
    def names(self) -> tuple[str, ...]:
        return self._names  # type: ignore[attr-defined]

    @property
    def units(self) -> tuple[str, ...]:
        return self._units  # type: ignore[attr-defined]

    @property
    def quantities(self) -> tuple[str, ...]:
        """Each column's quantity in words, or its name where none is declared."""
        return tuple(c.quantity or c.name for c in self.columns)

    def index(self, name: str) -> int:
        """Position of a column (KeyError naming the stream's columns if there is none)."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"stream {self.name!r} has no column {name!r} (it has: {', '.join(self.names)})") from None

    def indices(self, *names: str) -> list[int]:
        return [self.index(n) for n in names]

    def column(self, block: np.ndarray, name: str) -> np.ndarray:
        """One column of a block (rows x columns) by name."""
        return np.asarray(block)[..., self.index(name)]

    def columns_of(self, block: np.ndarray, *names: str) -> np.ndarray:
        """Some columns of a block by name, in the order given."""
        return np.asarray(block)[..., self.indices(*names)]

    def row(self, **values: float) -> np.ndarray:
        """One row (float64, in the declared order) from values by column name; every column
        must be given, and only those."""
        missing = [n for n in self.names if n not in values]
        extra = sorted(set(values) - set(self.names))
        if missing or extra:
            raise ValueError(f"stream {self.name!r}: row misses {missing} / has unknown columns {extra}")
        return np.array([float(values[n]) for n in self.names])

    def legends(self) -> dict[str, dict[int, str]]:
        return {c.name: dict(c.legend) for c in self.columns if c.legend}


def schema_from_attrs(name: str, columns: tuple[str, ...], attrs: Mapping,
                      legends: Mapping[str, Mapping[int, str]] | None = None) -> StreamSchema | None:
    """The declaration a raw file stored with a stream (its dataset's `units`, `dtypes`,
    `source` attributes; `legends` as bench.recorder.stored_legends reads them, else the
    `legend_<column>` attributes of older files); None for a file written before declarations."""
    import json

    def text(v) -> str:
        return v.decode() if isinstance(v, bytes) else str(v)

    units = attrs.get("units")
    if units is None or len(units) != len(columns):
        return None
    dtypes = attrs.get("dtypes")
    dtypes = [text(d) for d in dtypes] if dtypes is not None and len(dtypes) == len(columns) else ["f8"] * len(columns)
    quantities = attrs.get("quantities")
    quantities = [text(q) for q in quantities] if quantities is not None and len(quantities) == len(columns) else [
        ""] * len(columns)
    cols = []
    for c, u, d, q in zip(columns, units, dtypes, quantities, strict=True):
        if legends is not None:
            legend = legends.get(c)
        else:
            legend = attrs.get(f"legend_{c}")
            legend = {int(k): v for k, v in json.loads(text(legend)).items()} if legend is not None else None
        cols.append(Column(c, text(u), d, legend=legend, quantity=q if q != c else ""))
    return StreamSchema(name, text(attrs.get("source", name)), tuple(cols))


_REGISTRY: dict[str, StreamSchema] = {}
_LOCK = threading.Lock()


def declare(schema: StreamSchema) -> StreamSchema:
    """Register a stream's schema under its name (once: another schema by the same name is an
    error); returns it."""
    with _LOCK:
        old = _REGISTRY.get(schema.name)
        if old is not None and old != schema:
            raise ValueError(f"stream {schema.name!r} is declared twice, differently "
                             f"({old.source} and {schema.source})")
        _REGISTRY[schema.name] = schema
    return schema


def schema_of(name: str) -> StreamSchema:
    """The declared schema of a stream (KeyError with what to do if there is none)."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(
            f"stream {name!r} is not declared: declare it once with bench.streams.declare(StreamSchema(...))"
        ) from None


def declared() -> dict[str, StreamSchema]:
    return dict(_REGISTRY)


#: units of the curves of fits (and any other named value) by the suffix of their names (the
#: house rule: names carry their units), for arrays that have no declaration of their own
SUFFIX_UNITS: tuple[tuple[str, str], ...] = (
    ("_dps2", "deg/s^2"), ("_dps", "deg/s"), ("_dph", "deg/h"), ("_deg", "deg"), ("_rad", "rad"),
    ("_hz", "Hz"), ("_per_s", "1/s"), ("_s", "s"), ("_v", "V"),
)


def unit_from_name(name: str) -> str:
    """A value's unit from its name's suffix (`tau_s` -> s, `drift_dph` -> deg/h); "1" otherwise."""
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return DIMENSIONLESS
