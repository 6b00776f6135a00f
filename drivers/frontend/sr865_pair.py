"""A two-channel front end made of two SR860-series lock-ins (SR865), through PyMeasure's SR860
driver: each lock-in's sine output drives one electrode channel and its input reads one pickoff;
channel 1's lock-in is the reference master, channel 2's locks to it (docs/frontend_sr865.md).

It serves the front-end role the procedures use (`set_drive`, `set_frequency_hz`, `lockin_tc_s`,
`lockin_xy`, `lockin_all`, `safe_state`) in the same units and conventions as the SCPI front end:
drive v = A cos(wt + phase) with A in peak volts, readings (X, Y) = peak volts of the pickoff's
cos(wt) and sin(wt) parts.  The lock-ins work in rms volts against sin(wt + PHAS); the conversion
is here.  The two channels are read one after the other: the skew is measured on each read.
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

log = logging.getLogger(__name__)
SR860_CLASS = "pymeasure.instruments.srs.SR860"
SQRT2 = math.sqrt(2.0)
#: the sine output's range (rms 1 nV .. 2 V) as peak volts
MAX_AMPLITUDE_V = 2.0 * SQRT2
#: the frequency range PyMeasure's SR860 driver accepts (Hz)
FREQUENCY_RANGE_HZ = (1e-3, 500_000.0)
PHASE_RANGE_DEG = (-360.0, 360.0)
CHANNELS = (1, 2)


@dataclass(frozen=True)
class Sr865Limits:
    """The bench's own limits, within the instruments'."""

    max_amplitude_v: float = MAX_AMPLITUDE_V
    frequency_range_hz: tuple[float, float] = FREQUENCY_RANGE_HZ

    def __post_init__(self) -> None:
        if not 0.0 <= self.max_amplitude_v <= MAX_AMPLITUDE_V:
            raise LimitError("max_amplitude_v", self.max_amplitude_v, f"[0, {MAX_AMPLITUDE_V:.4f}]", "V")


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
        timeout_s: float = 2.0,
        instrument_class: str = SR860_CLASS,
    ) -> None:
        self.clock = clock
        self.limits = limits or Sr865Limits()
        self.devices = {
            1: PyMeasureDevice(instrument_class, master_resource, timeout_s=timeout_s, name="SR865 #1 (master)"),
            2: PyMeasureDevice(instrument_class, slave_resource, timeout_s=timeout_s, name="SR865 #2 (locked)"),
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
        m.call(lambda i: setattr(i, "reference_source", "INT"), "RSRC")
        s.call(lambda i: setattr(i, "reference_source", "EXT"), "RSRC")
        for ch, dev in self.devices.items():
            dev.call(lambda i: setattr(i, "filter_slope", 0), "OFSL")  # 6 dB/oct: one first-order stage
            dev.call(lambda i: setattr(i, "sine_voltage", 0.0), "SLVL")
            self._write_phase(ch)
        self._check(m, s)
        return self

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
            if esr & 0b0011_1100:
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

    def set_frequency_hz(self, frequency_hz: float) -> None:
        """Both channels' frequency: the master's internal reference (the other lock-in follows)."""
        self._check_frequency(frequency_hz)
        # PyMeasure's `frequency` setter writes "%0.6e": 7 digits, 1.6 mHz steps at 13.6 kHz, enough
        # to spoil a resonance fit (sigma 6x, docs/frontend_sr865.md); the same command, full precision
        self.devices[1].write(f"FREQ {float(frequency_hz):.12g}")
        self._check(self.devices[1])
        self.frequency_hz = float(frequency_hz)

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

    # --- safety --------------------------------------------------------------------------------------------
    def safe_state(self) -> bool:
        """Both sine outputs to their minimum; True only when read back as such."""
        ok = True
        for ch, dev in self.devices.items():
            self.channels[ch].output_on = False
            try:
                dev.call(lambda i: setattr(i, "sine_voltage", 0.0), "SLVL")
                ok = ok and float(dev.call(lambda i: i.sine_voltage, "SLVL?")) <= 1e-8
            except (LinkLostError, DeviceError):
                ok = False
        return ok
