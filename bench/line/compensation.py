"""A unit's compensation file (TOML, docs/compensation_file.md): the coefficients its calibration
identified, each with unit and expanded uncertainty, the trims they become in the FPGA's NVM, and
where they came from (serial, date, software version, run ids).

Built from a unit record (`from_record`) or from run rows (`from_runs`); `trims()` gives the
register values `gyrobench fpga load` writes and commits."""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

SCHEMA = "gyrobench-compensation/1"


@dataclass(frozen=True)
class CoefficientSpec:
    """One coefficient the line identifies: its unit, the trim register it loads, the procedures
    that measure it (first preferred) and the range the register accepts."""

    name: str
    unit: str
    register: str
    procedures: tuple[str, ...]
    low: float
    high: float
    doc: str


COEFFICIENTS: dict[str, CoefficientSpec] = {
    c.name: c
    for c in (
        CoefficientSpec("delta_inv_tau_per_s", "1/s", "TRIM_DRIFT_D_PER_S", ("hrg-damping", "hrg-free-decay"),
                        0.0, 1e3, "damping anisotropy D = 1/tau1 - 1/tau2 (drift trim)"),
        CoefficientSpec("theta_tau_deg", "deg", "TRIM_DRIFT_THETA_TAU_DEG", ("hrg-damping", "hrg-free-decay"),
                        -360.0, 360.0, "damping axis theta_tau (drift trim)"),
        CoefficientSpec("split_hz", "Hz", "TRIM_SPLIT_HZ", ("hrg-free-decay",),
                        0.0, 10.0, "frequency split (quadrature loop's feed-forward)"),
        CoefficientSpec("theta_w_deg", "deg", "TRIM_SPLIT_THETA_DEG", ("hrg-free-decay",),
                        -360.0, 360.0, "frequency axis theta_w (quadrature loop's feed-forward)"),
        CoefficientSpec("bryan_factor", "", "TRIM_BRYAN_FACTOR", ("hrg-free-decay",),
                        0.0, 1.0, "Bryan factor K (scale factor: output rate = wave rate / K)"),
        CoefficientSpec("thermal_bias_dph", "deg/h", "TRIM_BIAS_DPH", ("thermal-ramp", "thermal-soak"), -1e6, 1e6,
                        "bias at the FPGA's REF_FREQ_HZ (thermal trim, the resonator frequency as thermometer)"),
        CoefficientSpec("thermal_bias_dph_per_hz", "deg/h/Hz", "TRIM_BIAS_DPH_PER_HZ", ("thermal-ramp", "thermal-soak"),
                        -1e6, 1e6,
                        "bias's slope against the PLL frequency's offset from REF_FREQ_HZ (thermal trim)"),
        CoefficientSpec("thermal_sf_ppm", "ppm", "TRIM_SF_PPM", ("thermal-ramp",), -1e5, 1e5,
                        "scale factor's error against the nominal at the FPGA's REF_FREQ_HZ (thermal trim)"),
        CoefficientSpec("thermal_sf_ppm_per_hz", "ppm/Hz", "TRIM_SF_PPM_PER_HZ", ("thermal-ramp",), -1e5, 1e5,
                        "scale factor error's slope against the PLL frequency's offset (thermal trim)"),
        CoefficientSpec("thermal_hyst_hz", "Hz", "TRIM_HYST_HZ", ("thermal-ramp",), -1e3, 1e3,
                        "the hysteresis play's half-width on the PLL frequency, signed as df/dT (hysteresis trim)"),
        CoefficientSpec("thermal_bias_hyst_dph", "deg/h", "TRIM_BIAS_HYST_DPH", ("thermal-ramp",), -1e6, 1e6,
                        "bias on heating minus bias on cooling (hysteresis trim: state x half of it)"),
        CoefficientSpec("thermal_sf_hyst_ppm", "ppm", "TRIM_SF_HYST_PPM", ("thermal-ramp",), -1e5, 1e5,
                        "scale factor error on heating minus on cooling (hysteresis trim)"),
        CoefficientSpec("gain_x", "", "TRIM_GAIN_X", (), 0.5, 2.0, "pickoff x gain trim"),
        CoefficientSpec("gain_y", "", "TRIM_GAIN_Y", (), 0.5, 2.0, "pickoff y gain trim"),
    )
}
# TRIM_EN bits (drivers.fpga.protocol) a set of coefficients switches on
_TRIM_GROUPS = ((0x01, ("delta_inv_tau_per_s", "theta_tau_deg")), (0x02, ("split_hz", "theta_w_deg")),
                (0x04, ("gain_x", "gain_y")), (0x08, ("thermal_bias_dph", "thermal_bias_dph_per_hz")),
                (0x08, ("thermal_sf_ppm", "thermal_sf_ppm_per_hz")),
                (0x08, ("thermal_hyst_hz", "thermal_bias_hyst_dph")))  # fmt: skip


class CompensationError(ValueError):
    """A compensation file or its source that cannot be used; the message names the value and the limit."""


@dataclass(frozen=True)
class Coefficient:
    """An identified coefficient: value, unit and expanded uncertainty U (95 %), each side."""

    name: str
    value: float
    unit: str
    u_low: float | None = None
    u_high: float | None = None
    run_id: str = ""
    procedure: str = ""
    basis: str = ""  # why this estimate was taken (the narrowest 95 % interval, or the procedure's rank)

    @property
    def register(self) -> str:
        return COEFFICIENTS[self.name].register


@dataclass
class Compensation:
    """A unit's compensation: identity, provenance and the coefficients."""

    serial: str
    coefficients: dict[str, Coefficient]
    date: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    software_version: str = ""
    source_runs: list[str] = field(default_factory=list)
    sequence: str = ""

    # --- to the FPGA -----------------------------------------------------------------------------
    def trims(self) -> dict[str, float | int]:
        """Trim register values (drivers.fpga.protocol.TRIM_BLOCK names): the coefficients, TRIM_EN
        for each complete group and TRIM_FILE_ID; CompensationError names a value out of the range."""
        check(self)
        regs: dict[str, float | int] = {}
        en = 0
        for bit, names in _TRIM_GROUPS:
            if all(n in self.coefficients for n in names):
                en |= bit
        for c in self.coefficients.values():
            value = c.value
            if c.name in ("theta_tau_deg", "theta_w_deg"):
                value = math.remainder(value, 90.0)  # a 4 theta pattern: 90 deg periodic
            regs[c.register] = float(value)
        regs["TRIM_EN"] = en
        regs["TRIM_UNIT_ID"] = unit_id(self.serial)
        regs["TRIM_FILE_ID"] = self.file_id()
        return regs

    def file_id(self) -> int:
        """48 bits of the SHA-256 of the coefficients and serial (what TRIM_FILE_ID holds)."""
        text = self.serial + "".join(f"|{n}={c.value!r}" for n, c in sorted(self.coefficients.items()))
        return int.from_bytes(hashlib.sha256(text.encode()).digest()[:6], "big")

    # --- file ------------------------------------------------------------------------------------
    def to_toml(self) -> str:
        lines = [
            f"schema = {_q(SCHEMA)}",
            f"serial = {_q(self.serial)}",
            f"date = {_q(self.date)}",
            f"software_version = {_q(self.software_version)}",
            f"sequence = {_q(self.sequence)}",
            "source_runs = [" + ", ".join(_q(r) for r in self.source_runs) + "]",
        ]
        for name, c in self.coefficients.items():
            lines += ["", f"[coefficients.{name}]", f"value = {_num(c.value)}", f"unit = {_q(c.unit)}"]
            if c.u_low is not None:
                lines.append(f"u_low = {_num(c.u_low)}")
            if c.u_high is not None:
                lines.append(f"u_high = {_num(c.u_high)}")
            lines += [f"register = {_q(c.register)}", f"run_id = {_q(c.run_id)}", f"procedure = {_q(c.procedure)}"]
            if c.basis:
                lines.append(f"basis = {_q(c.basis)}")
        return "\n".join(lines) + "\n"

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(self.to_toml())
        return path


def unit_id(serial: str) -> int:
    """48 bits of the SHA-256 of a serial (what TRIM_UNIT_ID holds: NVM names the unit it trims)."""
    return int.from_bytes(hashlib.sha256(str(serial).encode()).digest()[:6], "big")


def _q(text: str) -> str:
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _num(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else ("nan" if x != x else ("inf" if x > 0 else "-inf"))


def check(comp: Compensation) -> None:
    """Every coefficient known, in its unit, finite and within its register's range."""
    if not comp.serial:
        raise CompensationError("compensation: serial is empty")
    for name, c in comp.coefficients.items():
        spec = COEFFICIENTS.get(name)
        if spec is None:
            raise CompensationError(f"compensation: unknown coefficient {name!r} (known: {', '.join(COEFFICIENTS)})")
        if c.unit != spec.unit:
            raise CompensationError(f"compensation: {name} in {c.unit!r}, expected {spec.unit!r}")
        if not math.isfinite(c.value):
            raise CompensationError(f"compensation: {name}={c.value!r} is not a finite number")
        if not spec.low <= c.value <= spec.high:
            side = "below" if c.value < spec.low else "above"
            limit = spec.low if c.value < spec.low else spec.high
            raise CompensationError(
                f"compensation: {name}={c.value:g} {spec.unit}".rstrip()
                + f" is {side} the limit {limit:g} of {spec.register}"
            )


def load(path: str | Path) -> Compensation:
    """Read a compensation file; CompensationError names what is wrong."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise CompensationError(f"compensation file {path} not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise CompensationError(f"compensation file {path}: not TOML ({exc})") from None
    if doc.get("schema") != SCHEMA:
        raise CompensationError(f"compensation file {path}: schema={doc.get('schema')!r}, expected {SCHEMA!r}")
    coeffs = {}
    for name, c in (doc.get("coefficients") or {}).items():
        if not isinstance(c, dict) or "value" not in c:
            raise CompensationError(f"compensation file {path}: [coefficients.{name}] has no value")
        try:
            coeffs[name] = Coefficient(
                name, float(c["value"]), str(c.get("unit", "")),
                _opt(c.get("u_low")), _opt(c.get("u_high")), str(c.get("run_id", "")), str(c.get("procedure", "")),
                str(c.get("basis", "")),
            )  # fmt: skip
        except (TypeError, ValueError):
            raise CompensationError(f"compensation file {path}: {name} value={c['value']!r} is not a number") from None
    comp = Compensation(
        serial=str(doc.get("serial", "")), coefficients=coeffs, date=str(doc.get("date", "")),
        software_version=str(doc.get("software_version", "")), source_runs=[str(r) for r in doc.get("source_runs", [])],
        sequence=str(doc.get("sequence", "")),
    )  # fmt: skip
    try:
        check(comp)
    except CompensationError as exc:
        raise CompensationError(f"{path}: {exc}") from None
    return comp


def _opt(x: Any) -> float | None:
    return None if x is None else float(x)


def _bare(name: str) -> str:
    """A measurement's name without a procedure prefix ("hrg-damping.theta_tau_deg" -> "theta_tau_deg")."""
    for sep in (":", "/", "."):
        if sep in name:
            name = name.rsplit(sep, 1)[1]
    return name


def _u(value: float, interval: Any) -> tuple[float | None, float | None]:
    """Expanded uncertainty each side from a 95 % interval [lo, hi] (None without one)."""
    if not interval or interval[0] is None or interval[1] is None:
        return None, None
    return float(value) - float(interval[0]), float(interval[1]) - float(value)


def _width(c: Coefficient) -> float:
    """The 95 % interval's width of an estimate (inf without one)."""
    return math.inf if c.u_low is None or c.u_high is None else c.u_low + c.u_high


def _pick(candidates: Iterable[dict[str, Any]], serial: str, **kw: Any) -> Compensation:
    """The most precise estimate of every known coefficient among measurement dicts {name,
    procedure, run_id, value, unit, interval}: the narrowest 95 % interval; among estimates without
    one (or equally wide), the coefficient's preferred procedure, then the first given.  Each
    coefficient's `basis` says which was taken and what it was chosen over."""
    seen: dict[str, list[tuple[float, int, int, Coefficient]]] = {}
    for i, m in enumerate(candidates):
        name = _bare(str(m.get("name", "")))
        spec = COEFFICIENTS.get(name)
        value = m.get("value")
        if spec is None or value is None or not math.isfinite(float(value)):
            continue
        proc = str(m.get("procedure", ""))
        rank = spec.procedures.index(proc) if proc in spec.procedures else len(spec.procedures)
        lo, hi = _u(float(value), m.get("interval"))
        coef = Coefficient(name, float(value), str(m.get("unit", spec.unit)), lo, hi, str(m.get("run_id", "")), proc)
        seen.setdefault(name, []).append((_width(coef), rank, i, coef))
    coeffs: dict[str, Coefficient] = {}
    for name in COEFFICIENTS:
        if name not in seen:
            continue
        ranked = sorted(seen[name], key=lambda t: t[:3])
        width, _, _, best = ranked[0]
        others = [f"{c.procedure or '?'} {_wtext(w)}" for w, _, _, c in ranked[1:]]
        if math.isfinite(width):
            basis = f"narrowest 95 % interval: {best.procedure or '?'} {_wtext(width)}"
        else:
            basis = f"no interval; preferred procedure {best.procedure or '?'}"
        if others:
            basis += " (over " + ", ".join(others) + ")"
        coeffs[name] = Coefficient(best.name, best.value, best.unit, best.u_low, best.u_high, best.run_id,
                                   best.procedure, basis)
    runs: list[str] = []
    for c in coeffs.values():
        if c.run_id and c.run_id not in runs:
            runs.append(c.run_id)
    if not coeffs:
        need = ", ".join(COEFFICIENTS)
        raise CompensationError(f"unit {serial}: no calibration coefficient measured (need one of {need})")
    return Compensation(serial=serial, coefficients=coeffs, source_runs=runs, **kw)


def _wtext(width: float) -> str:
    return f"width {width:.3g}" if math.isfinite(width) else "no interval"


def from_record(record: Mapping[str, Any]) -> Compensation:
    """The compensation of a unit record (the line's schema: serial, software_version, sequence,
    ended_at, measurements [{name, procedure, run_id, value, unit, interval}])."""
    return _pick(
        record.get("measurements") or (), str(record.get("serial", "")),
        date=str(record.get("ended_at") or datetime.now(UTC).isoformat(timespec="seconds")),
        software_version=str(record.get("software_version", "")), sequence=str(record.get("sequence", "")),
    )  # fmt: skip


def from_runs(
    serial: str, runs: Iterable[Mapping[str, Any]], *, software_version: str = "", sequence: str = ""
) -> Compensation:
    """The compensation from run rows (`ResultsStore.get_run`: run_id, procedure, measurements
    with value, unit, ci95_low, ci95_high), the later runs of a procedure preferred."""
    runs = list(runs)
    cands = []
    for run in runs:
        for m in run.get("measurements") or ():
            lo, hi = m.get("ci95_low"), m.get("ci95_high")
            cands.append({**m, "procedure": run.get("procedure", ""), "run_id": run.get("run_id", ""),
                          "interval": None if lo is None or hi is None else [lo, hi]})
    if not software_version:
        software_version = next((str(r.get("software_version")) for r in runs if r.get("software_version")), "")
    return _pick(reversed(cands), serial, software_version=software_version, sequence=sequence)
