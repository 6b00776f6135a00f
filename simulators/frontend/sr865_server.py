"""Two simulated SR865 lock-in amplifiers on loopback sockets (VISA `TCPIP::...::SOCKET`), each a
World device: its sine output drives one electrode channel, its input reads one pickoff
(docs/frontend_sr865.md).  The second one's reference is the first one's (RSRC 1, external).

Conventions (the SR86x's, see the doc): sine out = sqrt(2) SLVL sin(wt + PHAS), on the master's
oscillator timebase; the demodulator reference is sin(wt + PHAS), and X, Y are rms volts.  The
world's carrier is cos(wt): a sine out is the world drive phase PHAS - 90 deg, and a pickoff
c cos wt + s sin wt reads X + iY = (s + i c) / sqrt(2) * exp(-i PHAS).  The output filter is
OFSL + 1 first-order stages of time constant OFLT, run in virtual time like simulators/frontend.
"""

from __future__ import annotations

import cmath
import math
from typing import Any

import numpy as np
from scipy.signal import lfilter

from simulators.line_server import TextLineServer

#: OFLT index -> time constant (s), the SR86x table (1 us .. 30 ks, 1-3-10 steps)
TIME_CONSTANTS_S = tuple(m * 10.0**e for e in range(-6, 5) for m in (1.0, 3.0))
SLVL_RANGE_V = (1e-9, 2.0)  # sine out amplitude, rms
FREQ_RANGE_HZ = (1e-3, 4e6)
RSRC_INTERNAL, RSRC_EXTERNAL = 0, 1
ESR_QUERY_ERROR, ESR_EXECUTION_ERROR, ESR_COMMAND_ERROR = 1 << 2, 1 << 4, 1 << 5
#: SNAP?/OUTP? parameter names -> index (X, Y, R, THeta)
OUTPUTS = {"X": 0, "Y": 1, "R": 2, "THETA": 3, "TH": 3}


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
        self.esr = 0
        self.reset()

    def reset(self) -> None:
        self.freq_int_hz = 1000.0
        self.slvl_v = SLVL_RANGE_V[0]
        self.phas_deg = 0.0
        self.rsrc = RSRC_INTERNAL
        self.oflt = 10  # 100 ms, the instrument's default-ish
        self.ofsl = 1
        self._zi: np.ndarray | None = None
        self.cs = np.zeros(2)  # filtered (c, s) of the pickoff, model units

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
        stages = self.ofsl + 1
        a = 1.0 - math.exp(-world.sample_period_s / TIME_CONSTANTS_S[self.oflt])
        if self._zi is None or self._zi.shape[0] != stages:
            self._zi = np.repeat(x[:1], stages, axis=0) * (1.0 - a)  # start settled on the first sample
        y = x
        for k in range(stages):
            y, zf = lfilter([a], [1.0, -(1.0 - a)], y, axis=0, zi=self._zi[k][None, :])
            self._zi[k] = zf[0]
        self.cs = y[-1].copy()

    # --- readings ---------------------------------------------------------------------------------
    def xy_rms(self) -> tuple[float, float]:
        """(X, Y) rms volts against sin(wt + PHAS)."""
        if self.reference_hz() is None:
            return 0.0, 0.0
        c, s = self.pickoff_gain_v * self.cs
        z = complex(s, c) / math.sqrt(2.0) * cmath.exp(-1j * math.radians(self.phas_deg))
        return z.real, z.imag

    def output(self, index: int) -> float:
        x, y = self.xy_rms()
        return (x, y, math.hypot(x, y), math.degrees(math.atan2(y, x)))[index]

    # --- SCPI subset ----------------------------------------------------------------------------------
    def execute(self, line: str) -> str | None:
        """One message (';'-separated commands); the answers joined by ';', None if none."""
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
    def _float(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise _Err(ESR_COMMAND_ERROR, f"{text!r} is not a number") from None
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
        if t in OUTPUTS:
            return OUTPUTS[t]
        return self._int(t, 0, 3)

    def _unit(self, unit: str) -> str | None:
        head, _, arg = unit.partition(" ")
        head, arg = head.upper(), arg.strip()
        query = head.endswith("?")
        key = head.rstrip("?")
        args = [a.strip() for a in arg.split(",")] if arg else []
        if key == "*IDN" and query:
            return f"Stanford_Research_Systems,SR865,{self.serial},v1.0-gyrobench-sim"
        if key == "*CLS":
            self.esr = 0
            return None
        if key == "*ESR" and query:
            esr, self.esr = self.esr, 0
            return str(esr)
        if key == "*OPC":
            return "1" if query else None
        if key == "*RST":
            self.reset()
            return None
        if key in ("SNAP",) and query:
            if not 2 <= len(args) <= 3:
                raise _Err(ESR_QUERY_ERROR, "SNAP? takes 2 or 3 parameters")
            return ",".join(f"{self.output(self._which(a)):.9e}" for a in args)
        if key == "OUTP" and query:
            return f"{self.output(self._which(arg)):.9e}"
        settings = {
            "FREQ": ("freq_int_hz", FREQ_RANGE_HZ),
            "FREQINT": ("freq_int_hz", FREQ_RANGE_HZ),
            "SLVL": ("slvl_v", SLVL_RANGE_V),
            "PHAS": ("phas_deg", (-360000.0, 360000.0)),
        }
        if key in settings:
            attr, (lo, hi) = settings[key]
            if query:
                if key == "FREQ":
                    ref = self.reference_hz()
                    return f"{(ref or 0.0):.9e}"
                if key == "PHAS":
                    return f"{(self.phas_deg + 180.0) % 360.0 - 180.0:.7f}"
                return f"{getattr(self, attr):.9e}"
            if len(args) != 1:
                raise _Err(ESR_COMMAND_ERROR, f"{key} takes one parameter")
            v = self._float(args[0])
            if key == "SLVL":
                v = min(max(v, lo), hi)  # the instrument clips to its range
            elif not lo <= v <= hi:
                raise _Err(ESR_EXECUTION_ERROR, f"{key} {v} outside [{lo}, {hi}]")
            setattr(self, attr, v)
            return None
        if key == "FREQEXT" and query:
            ref = self.master.reference_hz() if self.master is not None else None
            return f"{(ref or 0.0):.9e}"
        if key == "FREQDET" and query:
            return f"{(self.reference_hz() or 0.0):.9e}"
        ints = {"RSRC": ("rsrc", 0, 1), "OFLT": ("oflt", 0, len(TIME_CONSTANTS_S) - 1), "OFSL": ("ofsl", 0, 3)}
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
    """Handle of the two simulated lock-ins: `.resources` (master, slave), `.models`, `inject`, `stop`."""

    def __init__(self, world: Any, models: tuple[Sr865Model, Sr865Model], host: str = "127.0.0.1") -> None:
        self.world, self.models = world, models
        self.servers = [TextLineServer(world, m.execute, host, name="sr865-sim") for m in models]

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
    world: Any, *, host: str = "127.0.0.1", drive_gain: float = 50.0, pickoff_gain_v: float = 1.0
) -> Sr865PairServer:
    """Attach two SR865 models (channel 1 = reference master, channel 2 wired to its reference
    output) to the world and serve them on loopback."""
    master = Sr865Model(1, serial="SIM001", drive_gain=drive_gain, pickoff_gain_v=pickoff_gain_v)
    slave = Sr865Model(2, serial="SIM002", drive_gain=drive_gain, pickoff_gain_v=pickoff_gain_v)
    slave.master = master
    with world.lock:
        world.attach(master)
        world.attach(slave)
    return Sr865PairServer(world, (master, slave), host)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[Sr865PairServer, dict[str, Any]]:
    """A simulated station's `sr865-pair-frontend`; (handle, both lock-ins' VISA resources)."""
    handle = serve_sr865_pair(world)
    master, slave = handle.resources
    return handle, {"resource": master, "resource2": slave}
