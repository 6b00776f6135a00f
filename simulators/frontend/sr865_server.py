"""Two simulated SR865 lock-in amplifiers on loopback sockets (VISA `TCPIP::...::SOCKET`) or over
VXI-11 (`TCPIP::host,port::inst0::INSTR`), each a World device: its sine output drives one
electrode channel, its input reads one pickoff (docs/frontend_sr865.md).  The second one's
reference is the first one's (RSRC 1, external).  As the instrument: 6-digit frequencies, unit
suffixes, status registers (*ESR/*STB, LIAS, CUROVLDSTAT), an unknown query answered by a status
bit and silence, an input beyond its range clipped.

Conventions (the SR86x's, see the doc): sine out = sqrt(2) SLVL sin(wt + PHAS), on the master's
oscillator timebase; the demodulator reference is sin(wt + PHAS), and X, Y are rms volts.  The
world's carrier is cos(wt): a sine out is the world drive phase PHAS - 90 deg, and a pickoff
c cos wt + s sin wt reads X + iY = (s + i c) / sqrt(2) * exp(-i PHAS).  The output filter is
OFSL + 1 first-order stages of time constant OFLT, run in virtual time like simulators/frontend.
"""

from __future__ import annotations

import cmath
import math
import re
from typing import Any

import numpy as np
from scipy.signal import lfilter

from simulators.line_server import TextLineServer
from simulators.vxi11 import Vxi11Server

#: OFLT index -> time constant (s), the SR86x table (1 us .. 30 ks, 1-3-10 steps)
TIME_CONSTANTS_S = tuple(m * 10.0**e for e in range(-6, 5) for m in (1.0, 3.0))
#: SCAL index -> full-scale sensitivity (V rms): 1 V, 500 mV, 200 mV, 100 mV .. 1 nV
SENSITIVITIES_V = (1.0, *(m * 10.0**-e for e in range(1, 10) for m in (5.0, 2.0, 1.0)))
#: IRNG index -> voltage input range (V peak): 1 V, 300 mV, 100 mV, 30 mV, 10 mV
INPUT_RANGES_V = (1.0, 0.3, 0.1, 0.03, 0.01)
SLVL_RANGE_V = (1e-9, 2.0)  # sine out amplitude, rms
SOFF_RANGE_V = (-5.0, 5.0)  # sine out DC level
FREQ_RANGE_HZ = (1e-3, 4e6)
RSRC_INTERNAL, RSRC_EXTERNAL = 0, 1
#: *ESR bits (IEEE 488.2, the SR86x manual's table): query error, execution error, command error
ESR_QUERY_ERROR, ESR_EXECUTION_ERROR, ESR_COMMAND_ERROR = 1 << 3, 1 << 4, 1 << 5
#: *STB bits: error-register summary, LIA-register summary, message available, *ESR summary, MSS
STB_ERR, STB_LIA, STB_MAV, STB_ESB, STB_MSS = 1 << 2, 1 << 3, 1 << 4, 1 << 5, 1 << 6
#: LIA status (LIAS?, latched) and current overload (CUROVLDSTAT?) bits that the model sets:
#: output CH1 (X) and CH2 (Y) beyond the sensitivity's full scale, external reference unlocked,
#: input beyond its range
OVLD_CH1, OVLD_CH2, OVLD_UNLOCK, OVLD_INPUT = 1 << 0, 1 << 1, 1 << 3, 1 << 4
#: SNAP?/OUTP? parameters: index, long name and the short form a client may send (manual's table)
PARAMETERS = (
    (0, "X", "X"), (1, "Y", "Y"), (2, "R", "R"), (3, "THETA", "TH"), (4, "IN1", "IN1"), (5, "IN2", "IN2"),
    (6, "IN3", "IN3"), (7, "IN4", "IN4"), (8, "XNOISE", "XNO"), (9, "YNOISE", "YNO"), (10, "OUT1", "OUT1"),
    (11, "OUT2", "OUT2"), (12, "PHASE", "PHA"), (13, "SAMP", "SAM"), (14, "LEVEL", "LEV"), (15, "FINT", "FI"),
    (16, "FEXT", "FE"),
)
#: unit suffixes a numeric parameter may carry, by the command's unit (SI multipliers)
UNITS = {
    "HZ": {"HZ": 1.0, "KHZ": 1e3, "MHZ": 1e6},
    "V": {"V": 1.0, "MV": 1e-3, "UV": 1e-6, "NV": 1e-9},
    "DEG": {"DEG": 1.0},
}
_NUMBER = re.compile(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z]*)$")


def rounded_frequency_hz(frequency_hz: float) -> float:
    """The frequency the SR865 takes for an asked one: 6 significant digits, or 0.1 mHz below
    10 Hz (13646.637 -> 13646.6; docs/frontend_sr865.md)."""
    f = float(frequency_hz)
    return float(f"{f:.6g}") if f >= 10.0 else round(f, 4)


def clipped_fundamental(ratio: np.ndarray) -> np.ndarray:
    """Fundamental of a sine clipped at `ratio` of its peak (ratio < 1), over the unclipped one."""
    r = np.clip(ratio, 0.0, 1.0)
    return (2.0 / math.pi) * (np.arcsin(r) + r * np.sqrt(1.0 - r * r))


class _Err(Exception):
    def __init__(self, bit: int, text: str) -> None:
        super().__init__(text)
        self.bit = bit


class Sr865Model:
    """One SR865 wired to electrode/pickoff `channel` (1 = x, 2 = y).  Call under world.lock."""

    def __init__(self, channel: int, *, serial: str, drive_gain: float = 50.0, pickoff_gain_v: float = 1.0) -> None:
        self.channel, self.serial = int(channel), serial
        self.drive_gain, self.pickoff_gain_v = float(drive_gain), float(pickoff_gain_v)
        self.master: Sr865Model | None = None  # where an external reference comes from
        self.force_source = f"sr865-ch{self.channel}"
        self.esr = self.ese = self.sre = 0
        self.lias = self.liae = 0
        self.errs = self.erre = 0
        self.reset()

    def reset(self) -> None:
        self.freq_int_hz = 1000.0
        self.slvl_v = SLVL_RANGE_V[0]
        self.soff_v = 0.0
        self.phas_deg = 0.0
        self.rsrc = RSRC_INTERNAL
        self.harm = 1
        self.rtrg = 0  # external reference trigger: 0 sine, 1 positive TTL, 2 negative TTL
        self.refz = 1  # external reference input: 0 50 ohm, 1 1 Mohm
        self.scal = 0  # 1 V full scale
        self.irng = 0  # 1 V input range
        self.oflt = 10  # 100 ms, the instrument's default-ish
        self.ofsl = 1
        self.cdsp = [0, 1, 2, 3]  # data channels 1-4 show X, Y, R, theta
        self._zi: np.ndarray | None = None
        self.cs = np.zeros(2)  # filtered (c, s) of the pickoff, model units
        self.input_peak_v = 0.0  # largest input of the last block

    # --- reference -----------------------------------------------------------------------------
    def reference_hz(self) -> float | None:
        """The frequency this instrument demodulates at (None: external and nothing to lock to)."""
        if self.rsrc == RSRC_INTERNAL:
            return self.freq_int_hz
        if self.master is not None and self.master.rsrc == RSRC_INTERNAL:
            return self.master.freq_int_hz
        return None

    def drive_on(self) -> bool:
        return self.slvl_v > SLVL_RANGE_V[0] and self.reference_hz() is not None

    # --- World device -------------------------------------------------------------------------------
    def before_block(self, world: Any, t_s: float, n: int, dt_s: float) -> None:
        ref = self.reference_hz()
        if not self.drive_on() or ref is None:
            world.set_force(self.force_source, None)
            return
        phi = math.radians(self.phas_deg - 90.0)
        amp = math.sqrt(2.0) * self.slvl_v * self.drive_gain
        u = np.zeros(4)
        i = 2 * (self.channel - 1)
        u[i], u[i + 1] = amp * math.sin(phi), amp * math.cos(phi)
        world.set_force(self.force_source, u)
        world.ref_freq_hz = ref

    def after_block(self, world: Any, block: Any) -> None:
        i = 2 * (self.channel - 1)
        x = np.asarray(block.q_meas[:, i : i + 2], dtype=float)
        peak_v = self.pickoff_gain_v * np.hypot(x[:, 0], x[:, 1])
        self.input_peak_v = float(peak_v.max()) if len(peak_v) else 0.0
        range_v = INPUT_RANGES_V[self.irng]
        if self.input_peak_v > range_v:  # the input stage clips: the fundamental shrinks
            self.lias |= OVLD_INPUT
            with np.errstate(divide="ignore"):
                x = x * clipped_fundamental(range_v / np.maximum(peak_v, 1e-300))[:, None]
        stages = self.ofsl + 1
        a = 1.0 - math.exp(-world.sample_period_s / TIME_CONSTANTS_S[self.oflt])
        if self._zi is None or self._zi.shape[0] != stages:
            self._zi = np.repeat(x[:1], stages, axis=0) * (1.0 - a)  # start settled on the first sample
        y = x
        for k in range(stages):
            y, zf = lfilter([a], [1.0, -(1.0 - a)], y, axis=0, zi=self._zi[k][None, :])
            self._zi[k] = zf[0]
        self.cs = y[-1].copy()
        self.lias |= self.overload_bits()

    # --- readings and status ------------------------------------------------------------------------
    def xy_rms(self) -> tuple[float, float]:
        """(X, Y) rms volts against sin(wt + PHAS) at the detection harmonic (the pickoff is a
        pure carrier: nothing at HARM > 1)."""
        if self.reference_hz() is None or self.harm != 1:
            return 0.0, 0.0
        c, s = self.pickoff_gain_v * self.cs
        z = complex(s, c) / math.sqrt(2.0) * cmath.exp(-1j * math.radians(self.phas_deg))
        return z.real, z.imag

    def output(self, index: int) -> float:
        x, y = self.xy_rms()
        ref = self.reference_hz() or 0.0
        values = {0: x, 1: y, 2: math.hypot(x, y), 3: math.degrees(math.atan2(y, x)),
                  12: self.phas_deg, 13: self.slvl_v, 14: self.soff_v, 15: self.freq_int_hz,
                  16: ref if self.rsrc == RSRC_EXTERNAL else 0.0}
        return values.get(index, 0.0)  # aux inputs, noise, aux outputs: 0 (nothing wired)

    def overload_bits(self) -> int:
        """CUROVLDSTAT?: the conditions now (outputs beyond full scale, reference, input range)."""
        bits = 0
        x, y = self.xy_rms()
        full_scale_v = SENSITIVITIES_V[self.scal]
        bits |= OVLD_CH1 if abs(x) > full_scale_v else 0
        bits |= OVLD_CH2 if abs(y) > full_scale_v else 0
        bits |= OVLD_UNLOCK if self.reference_hz() is None else 0
        bits |= OVLD_INPUT if self.input_peak_v > INPUT_RANGES_V[self.irng] else 0
        return bits

    def stb(self) -> int:
        """*STB?: the summary bits of the three registers (each through its enable mask)."""
        bits = STB_ERR if self.errs & self.erre else 0
        bits |= STB_LIA if self.lias & self.liae else 0
        bits |= STB_ESB if self.esr & self.ese else 0
        return bits | (STB_MSS if bits & self.sre else 0)

    # --- SCPI subset ----------------------------------------------------------------------------------
    def execute(self, line: str) -> str | None:
        """One message (';'-separated commands); the answers joined by ';', None if none.  An
        unknown or malformed command sets its *ESR? bit and is not answered, as the instrument."""
        answers: list[str] = []
        for unit in line.strip().split(";"):
            unit = unit.strip()
            if not unit:
                continue
            try:
                out = self._unit(unit)
            except _Err as exc:
                self.esr |= exc.bit
                continue
            if out is not None:
                answers.append(out)
        return ";".join(answers) if answers else None

    @staticmethod
    def _float(text: str, unit: str = "") -> float:
        """A number, with a unit suffix of `unit`'s family (`13.6 KHZ`, `100 MV`)."""
        m = _NUMBER.match(text.strip())
        if m is None:
            raise _Err(ESR_COMMAND_ERROR, f"{text!r} is not a number")
        v, suffix = float(m.group(1)), m.group(2).upper()
        if suffix:
            scale = UNITS.get(unit, {}).get(suffix)
            if scale is None:
                raise _Err(ESR_COMMAND_ERROR, f"{text!r}: suffix {suffix!r} not allowed here")
            v *= scale
        if not math.isfinite(v):
            raise _Err(ESR_EXECUTION_ERROR, f"{text!r} is not finite")
        return v

    def _int(self, text: str, lo: int, hi: int) -> int:
        v = self._float(text)
        if v != int(v) or not lo <= v <= hi:
            raise _Err(ESR_EXECUTION_ERROR, f"{text!r} not an integer in [{lo}, {hi}]")
        return int(v)

    def _which(self, text: str) -> int:
        t = text.strip().upper()
        for index, long, short in PARAMETERS:
            if t.startswith(short) and long.startswith(t):
                return index
        return self._int(t, 0, len(PARAMETERS) - 1)

    def _register(self, name: str, args: list[str], width: int) -> str:
        """`LIAS? [j]`, `ERRS? [j]`: the register (reading it clears it) or bit j (clears that bit)."""
        value = getattr(self, name)
        if args:
            j = self._int(args[0], 0, width - 1)
            setattr(self, name, value & ~(1 << j))
            return str((value >> j) & 1)
        setattr(self, name, 0)
        return str(value)

    def _unit(self, unit: str) -> str | None:
        head, _, arg = unit.partition(" ")
        head, arg = head.upper(), arg.strip()
        query = head.endswith("?")
        key = head.rstrip("?")
        args = [a.strip() for a in arg.split(",")] if arg else []
        if key == "*IDN" and query:
            return f"Stanford_Research_Systems,SR865,{self.serial},v1.0-gyrobench-sim"
        if key == "*CLS":
            self.esr = self.lias = self.errs = 0
            return None
        if key == "*ESR" and query:
            esr, self.esr = self.esr, 0
            return str(esr)
        if key == "*STB" and query:
            return str(self.stb())
        masks = {"*ESE": "ese", "*SRE": "sre", "LIAE": "liae", "ERRE": "erre"}
        if key in masks:
            if query:
                return str(getattr(self, masks[key]))
            setattr(self, masks[key], self._int(args[0] if args else "", 0, 0xFFFF))
            return None
        if key == "LIAS" and query:
            return self._register("lias", args, 16)
        if key == "ERRS" and query:
            return self._register("errs", args, 8)
        if key == "CUROVLDSTAT" and query:
            return str(self.overload_bits())
        if key == "ILVL" and query:  # signal strength 0..4, 4 = input overload
            ratio = self.input_peak_v / INPUT_RANGES_V[self.irng]
            return str(4 if ratio > 1.0 else min(3, int(4.0 * ratio)))
        if key == "*OPC":
            return "1" if query else None
        if key == "*RST":
            self.reset()
            return None
        if key == "SNAP" and query:
            if not 2 <= len(args) <= 3:
                raise _Err(ESR_EXECUTION_ERROR, "SNAP? takes 2 or 3 parameters")
            return ",".join(f"{self.output(self._which(a)):.9e}" for a in args)
        if key == "SNAPD" and query:
            return ",".join(f"{self.output(i):.9e}" for i in self.cdsp)
        if key == "OUTP" and query:
            return f"{self.output(self._which(arg)):.9e}"
        if key == "CDSP":
            j = self._int(args[0] if args else "", 0, 3)
            if query:
                return str(self.cdsp[j])
            if len(args) != 2:
                raise _Err(ESR_EXECUTION_ERROR, "CDSP takes two parameters")
            self.cdsp[j] = self._which(args[1])
            return None
        settings = {
            "FREQ": ("freq_int_hz", FREQ_RANGE_HZ, "HZ"),
            "FREQINT": ("freq_int_hz", FREQ_RANGE_HZ, "HZ"),
            "SLVL": ("slvl_v", SLVL_RANGE_V, "V"),
            "SOFF": ("soff_v", SOFF_RANGE_V, "V"),
            "PHAS": ("phas_deg", (-360000.0, 360000.0), "DEG"),
        }
        if key in settings:
            attr, (lo, hi), unit_name = settings[key]
            if query:
                if key == "FREQ":
                    ref = self.reference_hz()
                    return f"{(ref or 0.0):.9e}"
                if key == "PHAS":
                    return f"{(self.phas_deg + 180.0) % 360.0 - 180.0:.7f}"
                return f"{getattr(self, attr):.9e}"
            if len(args) != 1:
                raise _Err(ESR_COMMAND_ERROR, f"{key} takes one parameter")
            v = self._float(args[0], unit_name)
            if key in ("SLVL", "SOFF"):
                v = min(max(v, lo), hi)  # the instrument clips to its range
            elif not lo <= v <= hi:
                raise _Err(ESR_EXECUTION_ERROR, f"{key} {v} outside [{lo}, {hi}]")
            if key in ("FREQ", "FREQINT"):
                v = rounded_frequency_hz(v)
            setattr(self, attr, v)
            return None
        if key == "FREQEXT" and query:
            ref = self.master.reference_hz() if self.master is not None else None
            return f"{(ref or 0.0):.9e}"
        if key == "FREQDET" and query:
            return f"{self.harm * (self.reference_hz() or 0.0):.9e}"
        ints = {
            "RSRC": ("rsrc", 0, 1), "OFLT": ("oflt", 0, len(TIME_CONSTANTS_S) - 1), "OFSL": ("ofsl", 0, 3),
            "HARM": ("harm", 1, 99), "RTRG": ("rtrg", 0, 2), "REFZ": ("refz", 0, 1),
            "SCAL": ("scal", 0, len(SENSITIVITIES_V) - 1), "IRNG": ("irng", 0, len(INPUT_RANGES_V) - 1),
        }
        if key in ints:
            attr, lo, hi = ints[key]
            if query:
                return str(getattr(self, attr))
            if len(args) != 1:
                raise _Err(ESR_COMMAND_ERROR, f"{key} takes one parameter")
            setattr(self, attr, self._int(args[0], lo, hi))
            return None
        raise _Err(ESR_COMMAND_ERROR, f"unknown or unsupported command {unit!r}")


class Sr865PairServer:
    """Handle of the two simulated lock-ins: `.resources` (master, slave), `.models`, `inject`, `stop`.
    `visa`: "socket" (raw LF lines, `TCPIP::host::port::SOCKET`) or "vxi11" (the VXI-11 core
    channel, `TCPIP::host,port::inst0::INSTR`); `host` one for both, or one each."""

    def __init__(self, world: Any, models: tuple[Sr865Model, Sr865Model], host: str | tuple[str, str] = "127.0.0.1",
                 visa: str = "socket") -> None:
        self.world, self.models = world, models
        hosts = (host, host) if isinstance(host, str) else tuple(host)
        if visa == "socket":
            self.servers: list[Any] = [TextLineServer(world, m.execute, h, name="sr865-sim")
                                       for m, h in zip(models, hosts, strict=True)]
        elif visa == "vxi11":
            self.servers = [Vxi11Server(world, m.execute, host=h, status_byte=m.stb)
                            for m, h in zip(models, hosts, strict=True)]
        else:
            raise ValueError(f"unknown simulated VISA transport {visa!r}; known: socket, vxi11")

    @property
    def resources(self) -> tuple[str, str]:
        return self.servers[0].resource_name, self.servers[1].resource_name

    def inject(self, fault: str | None) -> None:
        """ "hang": both stop answering (the station's frontend-hang); "garble": both spoil every
        answer; "none"/None: clear."""
        fault = "none" if fault is None else fault
        if fault not in ("none", "hang", "garble"):
            raise ValueError(f"unknown SR865 fault {fault!r}; known: none, hang, garble")
        for s in self.servers:
            s.hang, s.garble = fault == "hang", fault == "garble"

    def stop(self) -> None:
        for s in self.servers:
            s.stop()
        with self.world.lock:
            for m in self.models:
                self.world.set_force(m.force_source, None)
                self.world.detach(m)


def serve_sr865_pair(
    world: Any, *, host: str | tuple[str, str] = "127.0.0.1", drive_gain: float = 50.0,
    pickoff_gain_v: float = 1.0, visa: str = "socket",
) -> Sr865PairServer:
    """Attach two SR865 models (channel 1 = reference master, channel 2 wired to its reference
    output) to the world and serve them on loopback."""
    master = Sr865Model(1, serial="SIM001", drive_gain=drive_gain, pickoff_gain_v=pickoff_gain_v)
    slave = Sr865Model(2, serial="SIM002", drive_gain=drive_gain, pickoff_gain_v=pickoff_gain_v)
    slave.master = master
    with world.lock:
        world.attach(master)
        world.attach(slave)
    try:
        return Sr865PairServer(world, (master, slave), host, visa)
    except Exception:
        with world.lock:
            world.detach(master)
            world.detach(slave)
        raise


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[Sr865PairServer, dict[str, Any]]:
    """A simulated station's `sr865-pair-frontend`; (handle, both lock-ins' VISA resources),
    over the transport its `simulated_visa` names."""
    handle = serve_sr865_pair(world, visa=cfg.get("simulated_visa") or "socket")
    master, slave = handle.resources
    return handle, {"resource": master, "resource2": slave}
