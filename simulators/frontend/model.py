"""The simulated front end: its settings, SCPI interpreter, and its part in the World's advance.

Physics mapping (docs/frontend_scpi.md): drive channel k outputs v_k(t) = A_k cos(wt + phi_k);
the carrier equations force x with w (u2 cos wt - u1 sin wt) and y with w (u4 cos wt - u3 sin wt),
so a drive of A, phi on channel 1 is u1 = g A sin phi, u2 = g A cos phi (channel 2: u3, u4), with
g = drive_gain (model units per volt).  While an output is on, the world's reference frequency is
that channel's drive frequency.  The lock-in reads (X1, Y1, X2, Y2) = pickoff_gain (cx, sx, cy,
sy), first-order low-passed in virtual time; raw captures are synthesised at carrier level from
the interpolated slow state, with seeded noise, clipping to the input range and 16-bit ADC codes.
"""

from __future__ import annotations

import math
import re
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from drivers.frontend import commands as cmd

from .kernels import lockin_fold

FORCE_SOURCE = "frontend"


class ScpiError(Exception):
    """An error the instrument queues (code from commands)."""

    def __init__(self, code: int, detail: str = "") -> None:
        super().__init__(code, detail)
        self.code, self.detail = code, detail


@dataclass
class ChannelState:
    """One drive output and its pickoff input."""

    amplitude_v: float = 0.0
    frequency_hz: float = cmd.RST_FREQUENCY_HZ
    phase_deg: float = 0.0
    bias_v: float = 0.0
    output_on: bool = False
    input_range_v: float = cmd.RST_INPUT_RANGE_V


@dataclass
class CaptureState:
    """An armed acquisition: the slow states seen since it started."""

    t0_s: float
    n: int
    rate_hz: float
    t_s: list[np.ndarray] = field(default_factory=list)
    q: list[np.ndarray] = field(default_factory=list)

    @property
    def t_end_s(self) -> float:
        return self.t0_s + (self.n - 1) / self.rate_hz


_NODE = re.compile(r"^([A-Z*]+?)(\d*)$")
#: headers already parsed (a pure function of the text): the link check's `*ESE n;*IDN?;*ESE?`
#: is parsed thousands of times a run; bounded, since a client may send any text
_HEADERS: dict[str, tuple[str, int]] = {}
_HEADER_CACHE_SIZE = 4096


class FrontEndModel:
    """Instrument state and behaviour.  Call `execute` and the World hooks under `world.lock`."""

    def __init__(
        self,
        *,
        drive_gain: float = 50.0,
        pickoff_gain_v: float = 1.0,
        adc_noise_v: float = 1e-4,
        seed: int = 0,
    ) -> None:
        self.drive_gain = float(drive_gain)
        self.pickoff_gain_v = float(pickoff_gain_v)
        self.adc_noise_v = float(adc_noise_v)
        self.rng = np.random.default_rng(seed)
        self.errors: deque[tuple[int, str]] = deque()
        self.esr = 0
        self.ese = 0  # *ESE: kept over *RST and *CLS (IEEE 488.2)
        self.lockin = np.zeros(4)  # filtered (cx, sx, cy, sy), model units
        self._lockin_weights_key: tuple[int, float] | None = None
        self._lockin_weights = np.empty(0)
        self._lockin_carry = 1.0
        self.reset()

    def reset(self) -> None:
        """*RST: outputs off, amplitudes zero, every setting to its default."""
        self.channels = {ch: ChannelState() for ch in cmd.CHANNELS}
        self.sample_rate_hz = cmd.RST_SAMPLE_RATE_HZ
        self.lockin_tc_s = cmd.RST_TIME_CONSTANT_S
        self.capture_points = cmd.RST_CAPTURE_POINTS
        self.capture: CaptureState | None = None
        self.captured: dict[int, np.ndarray] = {}
        self.slot = 1  # ROUT:SLOT: the slot a switched front end is connected to (simulators.rig)

    # --- physics ----------------------------------------------------------------------------------
    def reference_hz(self) -> float | None:
        """The drive frequency of the first channel whose output is on (None when all are off)."""
        for st in self.channels.values():
            if st.output_on:
                return st.frequency_hz
        return None

    def force(self) -> np.ndarray | None:
        """u1..u4 from the drives that are on (a channel off the reference frequency averages out)."""
        ref = self.reference_hz()
        if ref is None:
            return None
        u = np.zeros(4)
        for ch, st in self.channels.items():
            if st.output_on and math.isclose(st.frequency_hz, ref, rel_tol=1e-12):
                phi = math.radians(st.phase_deg)
                i = 2 * (ch - 1)
                u[i] = self.drive_gain * st.amplitude_v * math.sin(phi)
                u[i + 1] = self.drive_gain * st.amplitude_v * math.cos(phi)
        return u

    def before_block(self, world, t_s: float, n: int, dt_s: float) -> None:
        u = self.force()
        world.set_force(FORCE_SOURCE, u)
        if u is not None:
            world.ref_freq_hz = self.reference_hz()

    def after_block(self, world, block) -> None:
        self._lockin_blocks(block.q_meas, block.n, world.sample_period_s)
        cap = self.capture
        if cap is not None:
            cap.t_s.append(block.t_s)
            cap.q.append(block.q_true)
            if block.t_s[-1] >= cap.t_end_s - 1e-12:
                self._synthesise(cap, world.ref_freq_hz)
                self.capture = None

    def _lockin_blocks(self, q: np.ndarray, n: int, dt_s: float) -> None:
        """The lock-in over blocks of n samples of q (m, 4): the first-order low-pass y_k = a q_k
        + (1 - a) y_(k-1), of which only each block's last output is kept: y_(n-1) = (1 - a)^n
        y_(-1) + sum_k a (1 - a)^(n-1-k) q_k (kernels.lockin_fold)."""
        if self.lockin_tc_s <= 0.0:
            self.lockin = q[-1].copy()
            return
        a = 1.0 - math.exp(-dt_s / self.lockin_tc_s)
        key = (n, a)
        if self._lockin_weights_key != key:
            self._lockin_weights = a * (1.0 - a) ** np.arange(n - 1, -1, -1, dtype=float)
            self._lockin_carry = (1.0 - a) ** n
            self._lockin_weights_key = key
        y = np.array(self.lockin, dtype=float)  # a fresh array: a reader may hold the old one
        lockin_fold(y, q, n, self._lockin_weights, self._lockin_carry)
        self.lockin = y

    def fused_after_blocks(self, q_meas: np.ndarray, n: int, dt_s: float) -> None:
        """`after_block` for consecutive blocks of n samples (q_meas (k n, 4)) of the world's fused
        path, which runs only while no capture is armed."""
        self._lockin_blocks(q_meas, n, dt_s)

    def _synthesise(self, cap: CaptureState, ref_hz: float) -> None:
        """Carrier-level samples of both pickoffs from the interpolated slow state."""
        t_slow = np.concatenate(cap.t_s)
        q_slow = np.concatenate(cap.q)
        t = cap.t0_s + np.arange(cap.n) / cap.rate_hz
        wt = 2.0 * math.pi * ref_hz * t
        cos_wt, sin_wt = np.cos(wt), np.sin(wt)
        for ch in cmd.CHANNELS:
            i = 2 * (ch - 1)
            c = np.interp(t, t_slow, q_slow[:, i])
            s = np.interp(t, t_slow, q_slow[:, i + 1])
            v = self.pickoff_gain_v * (c * cos_wt + s * sin_wt)
            if self.adc_noise_v > 0:
                v = v + self.rng.normal(0.0, self.adc_noise_v, size=cap.n)
            full_scale = self.channels[ch].input_range_v
            lsb = 2.0 * full_scale / (1 << cmd.ADC_BITS)
            codes = np.clip(np.round(v / lsb), -(1 << (cmd.ADC_BITS - 1)), (1 << (cmd.ADC_BITS - 1)) - 1)
            self.captured[ch] = (codes * lsb).astype(cmd.BLOCK_DTYPE)

    # --- SCPI -------------------------------------------------------------------------------------
    def queue_error(self, code: int, detail: str = "") -> None:
        self.esr |= cmd.esr_bit_for(code)
        if len(self.errors) >= cmd.ERROR_QUEUE_DEPTH:
            self.errors[-1] = (cmd.QUEUE_OVERFLOW, "")
            return
        self.errors.append((code, detail))

    def execute(self, message: str, world) -> bytes | None:
        """Run one program message (units separated by ';'); the reply bytes, None if silent."""
        replies: list[bytes] = []
        for unit in message.split(cmd.SEPARATOR):
            unit = unit.strip()
            if not unit:
                continue
            try:
                out = self._unit(unit.lstrip(":"), world)
            except ScpiError as exc:
                self.queue_error(exc.code, exc.detail)
                continue
            if out is not None:
                replies.append(out if isinstance(out, bytes) else out.encode("ascii"))
        return b";".join(replies) if replies else None

    def _unit(self, unit: str, world) -> str | bytes | None:
        header, _, arg = unit.partition(" ")
        header, arg = header.upper(), arg.strip()
        query = header.endswith("?")
        bare = header.rstrip("?")
        parsed = _HEADERS.get(bare)
        if parsed is None:
            parsed = self._parse_header(bare)  # raises for a header that is not the instrument's
            if len(_HEADERS) < _HEADER_CACHE_SIZE:
                _HEADERS[bare] = parsed
        key, ch = parsed
        if key.startswith("*"):
            return self._common(key, query, arg)
        handler = self._SETTINGS.get(key)
        if handler is not None:
            return self._setting(key, handler, ch, query, arg)
        if not query:
            if key == "INIT:CAPT":
                self._no_arg(arg)
                self._arm(world)
                return None
            raise ScpiError(cmd.UNDEFINED_HEADER, header)
        self._no_arg(arg)
        if key == "SYST:ERR":
            code, detail = self.errors.popleft() if self.errors else cmd.NO_ERROR[:1] + ("",)
            return cmd.format_error(code, detail)
        if key == "FETC:LOCK:ALL":
            return ",".join(repr(float(v)) for v in self.pickoff_gain_v * self.lockin)
        if key == "FETC:LOCK#":
            i = 2 * (ch - 1)
            return ",".join(repr(float(v)) for v in self.pickoff_gain_v * self.lockin[i : i + 2])
        if key == "CAPT:DONE":
            return "1" if self.capture is None and self.captured else "0"
        if key == "FETC:CAPT#":
            data = self.captured.get(ch)
            if data is None:
                self.queue_error(cmd.DATA_STALE, "no completed capture")
                return cmd.block_header(0)
            payload = data.tobytes()
            return cmd.block_header(len(payload)) + payload
        raise ScpiError(cmd.UNDEFINED_HEADER, header)

    def _parse_header(self, header: str) -> tuple[str, int]:
        """'SOUR2:VOLT' -> ('SOUR#:VOLT', 2); a missing suffix means 1, as in SCPI."""
        nodes: list[tuple[str, str]] = []
        for node in header.split(":"):
            m = _NODE.match(node)
            if m is None:
                raise ScpiError(cmd.SYNTAX_ERROR, header)
            nodes.append((cmd.LONG_FORMS.get(m.group(1), m.group(1)), m.group(2)))
        suffixes = [int(sfx) for _, sfx in nodes if sfx]
        if len(suffixes) > 1:
            raise ScpiError(cmd.SYNTAX_ERROR, header)
        ch = suffixes[0] if suffixes else 1
        key = ":".join(name + ("#" if sfx else "") for name, sfx in nodes)
        if key not in _KNOWN and not suffixes:
            for i in range(len(nodes)):
                guess = ":".join(name + ("#" if j == i else "") for j, (name, _) in enumerate(nodes))
                if guess in _KNOWN:
                    key = guess
                    break
        if key.startswith("*"):
            return key, ch
        if key not in _KNOWN:
            raise ScpiError(cmd.UNDEFINED_HEADER, header)
        if ch not in cmd.CHANNELS:
            raise ScpiError(cmd.HEADER_SUFFIX_OUT_OF_RANGE, header)
        return key, ch

    @staticmethod
    def _no_arg(arg: str) -> None:
        if arg:
            raise ScpiError(cmd.PARAMETER_NOT_ALLOWED, arg)

    def _common(self, key: str, query: bool, arg: str) -> str | None:
        if key == "*ESE" and not query:
            value = self._parse_value("int", arg, (0, 255), key) if arg else None
            if value is None:
                raise ScpiError(cmd.MISSING_PARAMETER, key)
            self.ese = int(value)
            return None
        self._no_arg(arg)
        if key == "*ESE" and query:
            return str(self.ese)
        if key == "*IDN" and query:
            return ",".join(cmd.IDN_FIELDS)
        if key == "*RST" and not query:
            self.reset()
            return None
        if key == "*CLS" and not query:
            self.errors.clear()
            self.esr = 0
            return None
        if key == "*OPC":
            if query:
                return "1"
            self.esr |= cmd.ESR_OPC
            return None
        if key == "*ESR" and query:
            esr, self.esr = self.esr, 0
            return str(esr)
        if key == "*WAI" and not query:
            return None
        raise ScpiError(cmd.UNDEFINED_HEADER, key)

    # key -> (attribute, per-channel, kind, allowed)
    _SETTINGS: dict[str, tuple[str, bool, str, object]] = {
        "SOUR#:VOLT": ("amplitude_v", True, "float", cmd.AMPLITUDE_RANGE_V),
        "SOUR#:FREQ": ("frequency_hz", True, "float", cmd.FREQUENCY_RANGE_HZ),
        "SOUR#:PHAS": ("phase_deg", True, "float", cmd.PHASE_RANGE_DEG),
        "SOUR#:BIAS": ("bias_v", True, "float", cmd.BIAS_RANGE_V),
        "OUTP#": ("output_on", True, "bool", None),
        "SENS#:RANG": ("input_range_v", True, "set", cmd.INPUT_RANGES_V),
        "SENS:SRAT": ("sample_rate_hz", False, "float", cmd.SAMPLE_RATE_RANGE_HZ),
        "SENS:LOCK:TC": ("lockin_tc_s", False, "float", cmd.TIME_CONSTANT_RANGE_S),
        "CAPT:POIN": ("capture_points", False, "int", cmd.CAPTURE_POINTS_RANGE),
        "ROUT:SLOT": ("slot", False, "int", cmd.SLOT_RANGE),  # the output switch of a shared front end
    }

    def _setting(self, key: str, handler: tuple, ch: int, query: bool, arg: str) -> str | None:
        attr, per_channel, kind, allowed = handler
        target = self.channels[ch] if per_channel else self
        if query:
            self._no_arg(arg)
            value = getattr(target, attr)
            if kind == "bool":
                return "1" if value else "0"
            if kind == "int":
                return str(int(value))
            return repr(float(value))
        if not arg:
            raise ScpiError(cmd.MISSING_PARAMETER, key)
        setattr(target, attr, self._parse_value(kind, arg, allowed, key))
        return None

    @staticmethod
    def _parse_value(kind: str, arg: str, allowed: object, key: str) -> object:
        if kind == "bool":
            text = arg.upper()
            if text in ("ON", "1"):
                return True
            if text in ("OFF", "0"):
                return False
            raise ScpiError(cmd.ILLEGAL_PARAMETER_VALUE, f"{key} {arg}")
        try:
            x = float(arg)
        except ValueError:
            raise ScpiError(cmd.DATA_TYPE_ERROR, f"{key} {arg}") from None
        if not math.isfinite(x):
            raise ScpiError(cmd.DATA_OUT_OF_RANGE, f"{key} {arg}")
        if kind == "set":
            for v in allowed:  # type: ignore[attr-defined]
                if math.isclose(x, v, rel_tol=1e-9):
                    return float(v)
            raise ScpiError(cmd.ILLEGAL_PARAMETER_VALUE, f"{key} {arg} not one of {list(allowed)}")  # type: ignore[call-overload]
        lo, hi = allowed  # type: ignore[misc]
        if not lo <= x <= hi:
            raise ScpiError(cmd.DATA_OUT_OF_RANGE, f"{key} {arg} outside [{lo:g}, {hi:g}]")
        if kind == "int":
            if x != int(x):
                raise ScpiError(cmd.DATA_TYPE_ERROR, f"{key} {arg} is not an integer")
            return int(x)
        return x

    def _arm(self, world) -> None:
        self.captured = {}
        t0 = world.t_s
        self.capture = CaptureState(t0_s=t0, n=self.capture_points, rate_hz=self.sample_rate_hz)
        self.capture.t_s.append(np.array([t0]))
        self.capture.q.append(world.state()[None, :])


_KNOWN = frozenset(FrontEndModel._SETTINGS) | {
    "SYST:ERR",
    "FETC:LOCK:ALL",
    "FETC:LOCK#",
    "CAPT:DONE",
    "FETC:CAPT#",
    "INIT:CAPT",
}
