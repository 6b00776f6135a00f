"""A two-channel front end made of two SR860-series lock-ins (SR865), through PyMeasure's SR860
driver: each lock-in's sine output drives one electrode channel and its input reads one pickoff;
channel 1's lock-in is the reference master, channel 2's locks to it (docs/frontend_sr865.md).

It serves the front-end role the procedures use (`set_drive`, `set_frequency_hz`, `lockin_tc_s`,
`lockin_xy`, `lockin_all`, `safe_state`) in the same units and conventions as the SCPI front end:
drive v = A cos(wt + phase) with A in peak volts, readings (X, Y) = peak volts of the pickoff's
cos(wt) and sin(wt) parts.  The lock-ins work in rms volts against sin(wt + PHAS); the conversion
is here.  The two channels are read one after the other: the skew is measured on each read.

At connect every setting the readings depend on is set and read back (reference source, trigger
and input impedance, harmonic, sine-out DC level, input range, sensitivity, filter slope); the
frequency recorded is the one the master reads back (`FREQ?`, 6 digits), and `lockin_overload`
reads the latched overload bits (`LIAS?`) so that a point taken in overload is refused.
"""

from __future__ import annotations

import cmath
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError
from drivers.instrument.pymeasure_adapter import PyMeasureDevice
from drivers.instrument.station_device import same

log = logging.getLogger(__name__)
SR860_CLASS = "pymeasure.instruments.srs.SR860"
SQRT2 = math.sqrt(2.0)
#: the sine output's range (rms 1 nV .. 2 V) as peak volts
MAX_AMPLITUDE_V = 2.0 * SQRT2
#: the frequency range PyMeasure's SR860 driver accepts (Hz)
FREQUENCY_RANGE_HZ = (1e-3, 500_000.0)
PHASE_RANGE_DEG = (-360.0, 360.0)
CHANNELS = (1, 2)
#: voltage input ranges (V peak) -> PyMeasure's `input_range` names (IRNG 0..4), largest first
INPUT_RANGES_V = {1.0: "1V", 0.3: "300M", 0.1: "100M", 0.03: "30M", 0.01: "10M"}
#: full-scale sensitivities (V rms, SCAL 0..27), largest first: PyMeasure's table, as the same
#: decimal literals (its setter truncates up: 5.000000000000001e-05 would be taken as 1e-4)
SENSITIVITIES_V = (1.0, *(float(f"{m}e-{e}") for e in range(1, 10) for m in (5, 2, 1)))
#: the locked lock-in's reference trigger (RTRG 0, 1, 2) and input impedance (REFZ 0, 1)
REF_TRIGGERS = ("SIN", "POS", "NEG")
REF_IMPEDANCES = ("50OHMS", "1MEG")
#: what to do when a point overloads: keep the ranges (the point is refused), or step the
#: overloaded range up one and take the point again (refused only at the largest range)
RANGE_POLICIES = ("fixed", "step-up")
#: LIAS? bits read at every point (SR86x LIA status register)
LIA_OVERLOADS = {1 << 0: "output X beyond full scale", 1 << 1: "output Y beyond full scale",
                 1 << 3: "reference unlocked", 1 << 4: "input beyond its range"}
LIA_OUTPUT, LIA_INPUT = (1 << 0) | (1 << 1), 1 << 4
#: *ESR? bits that mean the instrument refused something: query, execution, command error
ESR_ERRORS = (1 << 3) | (1 << 4) | (1 << 5)


@dataclass(frozen=True)
class Sr865Limits:
    """The bench's own limits, within the instruments'."""

    max_amplitude_v: float = MAX_AMPLITUDE_V
    frequency_range_hz: tuple[float, float] = FREQUENCY_RANGE_HZ

    def __post_init__(self) -> None:
        if not 0.0 <= self.max_amplitude_v <= MAX_AMPLITUDE_V:
            raise LimitError("max_amplitude_v", self.max_amplitude_v, f"[0, {MAX_AMPLITUDE_V:.4f}]", "V")


@dataclass(frozen=True)
class Sr865Setup:
    """The input and reference settings written and read back at connect."""

    input_range_v: float = 1.0
    sensitivity_v: float = 1.0
    range_policy: str = "step-up"
    ref_trigger: str = "POS"
    ref_impedance: str = "1MEG"

    def __post_init__(self) -> None:
        if self.input_range_v not in INPUT_RANGES_V:
            raise LimitError("input_range_v", self.input_range_v, "one of " + ", ".join(map(str, INPUT_RANGES_V)), "V")
        if not any(math.isclose(self.sensitivity_v, v, rel_tol=1e-9) for v in SENSITIVITIES_V):
            raise LimitError("sensitivity_v", self.sensitivity_v, "a 1-2-5 step from 1 nV to 1 V", "V")
        for name, value, allowed in (("range_policy", self.range_policy, RANGE_POLICIES),
                                     ("ref_trigger", self.ref_trigger, REF_TRIGGERS),
                                     ("ref_impedance", self.ref_impedance, REF_IMPEDANCES)):
            if value not in allowed:
                raise LimitError(name, value, "one of " + ", ".join(allowed))


@dataclass(frozen=True)
class Overload:
    """What `lockin_overload` found: the conditions latched, and the range steps it took."""

    conditions: tuple[str, ...] = ()
    changed: tuple[str, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.conditions)

    def __str__(self) -> str:
        return "; ".join(self.conditions) + (f" (then {'; '.join(self.changed)})" if self.changed else "")


@dataclass
class SkewStats:
    """Wall time between the two lock-ins' answers of one `lockin_all` (s)."""

    last_s: float = 0.0
    max_s: float = 0.0
    total_s: float = 0.0
    count: int = 0
    virtual_last_s: float = 0.0  # the same on the bench clock (0 on a lockstep simulation)
    samples: list[float] = field(default_factory=list, repr=False)

    def add(self, skew_s: float, virtual_s: float) -> None:
        self.last_s, self.virtual_last_s = skew_s, virtual_s
        self.max_s = max(self.max_s, skew_s)
        self.total_s += skew_s
        self.count += 1
        if len(self.samples) < 10_000:
            self.samples.append(skew_s)

    @property
    def mean_s(self) -> float:
        return self.total_s / self.count if self.count else 0.0


@dataclass
class _Channel:
    amplitude_v: float = 0.0  # peak
    phase_deg: float = 0.0  # world convention: v = A cos(wt + phase)
    output_on: bool = False
    phas_deg: float = 90.0  # the lock-in's PHAS as read back


class Sr865PairFrontEnd:
    """Two SR865s as the front-end role: `master` drives/reads channel 1, `slave` channel 2."""

    def __init__(
        self,
        master_resource: str,
        slave_resource: str,
        *,
        clock: Any,
        limits: Sr865Limits | None = None,
        setup: Sr865Setup | None = None,
        timeout_s: float = 2.0,
        instrument_class: str = SR860_CLASS,
        visa_library: str = "",
    ) -> None:
        self.clock = clock
        self.limits = limits or Sr865Limits()
        self.setup = setup or Sr865Setup()
        # each lock-in's input range and sensitivity in use (indices into the tables, 0 = largest)
        self.irng = {ch: list(INPUT_RANGES_V).index(self.setup.input_range_v) for ch in CHANNELS}
        self.scal = {ch: _sensitivity_index(self.setup.sensitivity_v) for ch in CHANNELS}
        visa = {"visa_library": visa_library} if visa_library else {}
        self.devices = {
            1: PyMeasureDevice(instrument_class, master_resource, timeout_s=timeout_s, name="SR865 #1 (master)",
                               status_query="*ESR?", **visa),
            2: PyMeasureDevice(instrument_class, slave_resource, timeout_s=timeout_s, name="SR865 #2 (locked)",
                               status_query="*ESR?", **visa),
        }
        self.channels = {ch: _Channel() for ch in CHANNELS}
        self.frequency_hz = 1000.0
        self.skew = SkewStats()
        self.resource_name = f"{master_resource} + {slave_resource}"

    # --- connection --------------------------------------------------------------------------------
    def connect(self) -> Sr865PairFrontEnd:
        try:
            return self._connect()
        except Exception:
            self.close()
            raise

    def _connect(self) -> Sr865PairFrontEnd:
        for dev in self.devices.values():
            dev.connect()
            idn = dev.idn
            if "SR86" not in idn.upper():
                raise ProtocolError(f"{dev.name} at {dev.resource}: *IDN? answered {idn!r}, not an SR86x")
            dev.write("*CLS")
        m, s = self.devices[1], self.devices[2]
        self._set(m, "reference_source", "INT", "RSRC")
        self._set(s, "reference_source", "EXT", "RSRC")
        self._set(s, "reference_triggermode", self.setup.ref_trigger, "RTRG")
        # PyMeasure's `reference_externalinput` setter writes "REFZ&d" (no value): its getter reads
        s.write(f"REFZ {REF_IMPEDANCES.index(self.setup.ref_impedance)}")
        self._verify(s, "reference_externalinput", self.setup.ref_impedance, "REFZ")
        for ch, dev in self.devices.items():
            self._set(dev, "harmonic", 1, "HARM")
            self._write_dc_level(dev)
            self._set(dev, "filter_slope", 0, "OFSL")  # 6 dB/oct: one first-order stage
            dev.call(lambda i: setattr(i, "sine_voltage", 0.0), "SLVL")
            self._write_ranges(ch)
            self._write_phase(ch)
        self._check(m, s)
        return self

    def _set(self, dev: PyMeasureDevice, prop: str, value: Any, what: str) -> None:
        """A PyMeasure property written, then read back and compared (DeviceError if it differs)."""
        dev.call(lambda i: setattr(i, prop, value), what)
        self._verify(dev, prop, value, what)

    def _verify(self, dev: PyMeasureDevice, prop: str, value: Any, what: str) -> None:
        read = dev.call(lambda i: getattr(i, prop), f"{what}?")
        if not same(value, read):
            raise DeviceError(f"{dev.name}: {what} reads back {read!r} after writing {value!r}")

    def _write_dc_level(self, dev: PyMeasureDevice) -> None:
        """Sine-out DC level 0 V (`SOFF`: PyMeasure's SR860 has no property for it), read back."""
        dev.write("SOFF 0")
        level = float(dev.ask("SOFF?"))
        if abs(level) > 1e-6:
            raise DeviceError(f"{dev.name}: SOFF reads back {level!r} V after writing 0")

    def _write_ranges(self, ch: int) -> None:
        """Input range (IRNG) and sensitivity (SCAL) of one lock-in as held in `irng`/`scal`."""
        dev = self.devices[ch]
        self._set(dev, "input_range", list(INPUT_RANGES_V.values())[self.irng[ch]], "IRNG")
        self._set(dev, "sensitivity", SENSITIVITIES_V[self.scal[ch]], "SCAL")

    def close(self) -> None:
        if self.skew.count:
            log.info(
                "SR865 pair: %d paired reads, skew between the two lock-ins mean %.3g ms, max %.3g ms (wall)",
                self.skew.count,
                1e3 * self.skew.mean_s,
                1e3 * self.skew.max_s,
            )
        for dev in self.devices.values():
            dev.close()

    @property
    def idn(self) -> str:
        return " | ".join(dev.idn for dev in self.devices.values())

    def _check(self, *devs: PyMeasureDevice) -> None:
        """*ESR? of each: an error bit means the instrument refused something just sent."""
        for dev in devs:
            esr = int(float(dev.ask("*ESR?")))
            if esr & ESR_ERRORS:
                raise DeviceError(f"{dev.name} refused a setting (*ESR?={esr})")

    # --- drive ----------------------------------------------------------------------------------------
    def _channel(self, channel: int) -> int:
        if channel not in CHANNELS:
            raise LimitError("channel", channel, "one of 1, 2")
        return channel

    def set_drive(
        self,
        channel: int,
        *,
        amplitude_v: float | None = None,
        frequency_hz: float | None = None,
        phase_deg: float | None = None,
        output_on: bool | None = None,
    ) -> None:
        """Drive settings of one channel, all checked before any is sent.  The frequency is the
        master's reference, so it is the frequency of both channels."""
        ch = self._channel(channel)
        if amplitude_v is not None and not (
            math.isfinite(amplitude_v) and 0.0 <= amplitude_v <= self.limits.max_amplitude_v
        ):
            raise LimitError("amplitude_v", amplitude_v, f"[0, {self.limits.max_amplitude_v:g}]", "V")
        if frequency_hz is not None:
            self._check_frequency(frequency_hz)
        if phase_deg is not None and not (math.isfinite(phase_deg) and -360.0 <= phase_deg <= 360.0):
            raise LimitError("phase_deg", phase_deg, "[-360, 360]", "deg")
        c = self.channels[ch]
        if frequency_hz is not None:
            self.set_frequency_hz(frequency_hz)
        if phase_deg is not None:
            c.phase_deg = float(phase_deg)
            self._write_phase(ch)
        if amplitude_v is not None:
            c.amplitude_v = float(amplitude_v)
        if output_on is not None:
            c.output_on = bool(output_on)
        if amplitude_v is not None or output_on is not None:
            self._write_amplitude(ch)
        self._check(self.devices[ch])

    def _check_frequency(self, frequency_hz: float) -> None:
        lo, hi = self.limits.frequency_range_hz
        if not (math.isfinite(frequency_hz) and lo <= frequency_hz <= hi):
            raise LimitError("frequency_hz", frequency_hz, f"[{lo:g}, {hi:g}]", "Hz")

    def set_frequency_hz(self, frequency_hz: float) -> float:
        """Both channels' frequency: the master's internal reference (the other lock-in follows).
        Returns the frequency in use as the master reads it back (`FREQ?`): the SR865 keeps 6
        digits (0.1 Hz at 13.6 kHz), and that, not the asked value, is what a point was taken at."""
        self._check_frequency(frequency_hz)
        m = self.devices[1]
        m.call(lambda i: setattr(i, "frequency", float(frequency_hz)), "FREQ")
        used = float(m.call(lambda i: i.frequency, "FREQ?"))
        self._check(m)
        if not (math.isfinite(used) and math.isclose(used, frequency_hz, rel_tol=1e-5, abs_tol=1e-4)):
            raise DeviceError(f"{m.name}: FREQ? reads {used!r} Hz after asking {frequency_hz!r} Hz")
        self.frequency_hz = used
        return used

    def _write_phase(self, ch: int) -> None:
        """PHAS = phase + 90: a sine output sin(wt + PHAS) is cos(wt + phase)."""
        c, dev = self.channels[ch], self.devices[ch]
        phas = (c.phase_deg + 90.0 + 180.0) % 360.0 - 180.0
        dev.call(lambda i: setattr(i, "phase", phas), "PHAS")
        c.phas_deg = float(dev.call(lambda i: i.phase, "PHAS?"))

    def _write_amplitude(self, ch: int) -> None:
        c = self.channels[ch]
        rms = c.amplitude_v / SQRT2 if c.output_on else 0.0
        self.devices[ch].call(lambda i: setattr(i, "sine_voltage", rms), "SLVL")

    # --- lock-in ----------------------------------------------------------------------------------------
    @property
    def lockin_tc_s(self) -> float:
        """The output filter's time constant (s): the instruments' next step at or above the request."""
        return float(self.devices[1].call(lambda i: i.time_constant, "OFLT?"))

    @lockin_tc_s.setter
    def lockin_tc_s(self, tc_s: float) -> None:
        if not (math.isfinite(tc_s) and 0.0 <= tc_s <= 30e3):
            raise LimitError("lockin_tc_s", tc_s, "[0, 30000]", "s")
        for dev in self.devices.values():
            dev.call(lambda i: setattr(i, "time_constant", max(float(tc_s), 1e-6)), "OFLT")

    def _xy(self, ch: int) -> tuple[float, float]:
        """(X, Y) of one pickoff in our convention (peak V of its cos and sin parts)."""
        values = self.devices[ch].call(lambda i: i.snap("X", "Y"), "SNAP? X, Y")
        if len(values) != 2 or not all(math.isfinite(v) for v in values):
            raise ProtocolError(f"{self.devices[ch].name}: SNAP? answered {values!r}, expected 2 numbers")
        z = SQRT2 * complex(values[0], values[1]) * cmath.exp(1j * math.radians(self.channels[ch].phas_deg))
        return z.imag, z.real

    def lockin_xy(self, channel: int) -> tuple[float, float]:
        return self._xy(self._channel(channel))

    def lockin_all(self) -> tuple[float, float, float, float]:
        """(X1, Y1, X2, Y2): two SNAP? queries, one per instrument, back to back; the wall time
        between their answers is recorded in `skew` (the readings are that far apart)."""
        v0 = self.clock.now()
        x1, y1 = self._xy(1)
        t1 = time.perf_counter()
        x2, y2 = self._xy(2)
        t2 = time.perf_counter()
        self.skew.add(t2 - t1, self.clock.now() - v0)
        return x1, y1, x2, y2

    def lockin_overload(self, act: bool = True) -> Overload:
        """The overloads either lock-in latched since the last call (`LIAS?`, which clears on
        reading): output beyond the sensitivity, input beyond its range, reference unlocked.
        With `act` under the step-up policy an overloaded input range or sensitivity is stepped
        up one (and read back); `changed` says so, and the caller takes the point again."""
        conditions: list[str] = []
        changed: list[str] = []
        for ch, dev in self.devices.items():
            bits = int(float(dev.ask("LIAS?")))
            conditions += [f"#{ch} {name}" for bit, name in LIA_OVERLOADS.items() if bits & bit]
            if not act or self.setup.range_policy != "step-up":
                continue
            if bits & LIA_INPUT and self.irng[ch] > 0:
                self.irng[ch] -= 1
                changed.append(f"#{ch} input range {list(INPUT_RANGES_V)[self.irng[ch]]:g} V")
            if bits & LIA_OUTPUT and self.scal[ch] > 0:
                self.scal[ch] -= 1
                changed.append(f"#{ch} sensitivity {SENSITIVITIES_V[self.scal[ch]]:g} V")
            if bits & (LIA_INPUT | LIA_OUTPUT):
                self._write_ranges(ch)
        if changed:
            log.warning("SR865 pair: %s; ranges stepped up: %s", "; ".join(conditions), "; ".join(changed))
        return Overload(tuple(conditions), tuple(changed))

    # --- safety --------------------------------------------------------------------------------------------
    def safe_state(self) -> bool:
        """Both sine outputs to their minimum and their DC level to 0 V (a DC offset left on
        the electrodes too); True only when both read back as such on both lock-ins."""
        ok = True
        for ch, dev in self.devices.items():
            self.channels[ch].output_on = False
            try:
                dev.call(lambda i: setattr(i, "sine_voltage", 0.0), "SLVL")
                dev.write("SOFF 0")
                ok = float(dev.call(lambda i: i.sine_voltage, "SLVL?")) <= 1e-8 and ok
                ok = abs(float(dev.ask("SOFF?"))) <= 1e-6 and ok
            except (LinkLostError, DeviceError, ProtocolError, ValueError):
                ok = False
        return ok


def _sensitivity_index(sensitivity_v: float) -> int:
    """SCAL index of a full-scale sensitivity in the table."""
    return min(range(len(SENSITIVITIES_V)), key=lambda k: abs(math.log(SENSITIVITIES_V[k] / sensitivity_v)))
