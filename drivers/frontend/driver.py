"""Driver for the two-channel DAC/ADC front end (drive outputs, pickoff inputs, lock-in, capture).

Speaks SCPI over any VISA resource (`TCPIP::host::port::SOCKET` through pyvisa-py for the
simulator).  Properties are declared once with their validators and units (`properties.control`);
every setting is sent together with `SYST:ERR?` in one compound message, so a refused setting
raises DeviceError at once.  Out-of-range values raise LimitError before anything is sent.
Transport timeouts are wall time (`timeout_s`); waits for the instrument (a capture filling) go
through the bench clock, so they are virtual time on a simulated bench.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError

from . import commands as cmd
from .properties import (
    boolean,
    control,
    parse_bool,
    strict_discrete_set,
    strict_int_range,
    strict_range,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FrontEndLimits:
    """A bench's own limits, at most the instrument's ranges (checked at construction)."""

    max_amplitude_v: float = cmd.AMPLITUDE_RANGE_V[1]
    frequency_range_hz: tuple[float, float] = cmd.FREQUENCY_RANGE_HZ
    bias_range_v: tuple[float, float] = cmd.BIAS_RANGE_V

    def __post_init__(self) -> None:
        strict_range("max_amplitude_v", self.max_amplitude_v, cmd.AMPLITUDE_RANGE_V, "V")
        for name, (lo, hi), dev, unit in (
            ("frequency_range_hz", self.frequency_range_hz, cmd.FREQUENCY_RANGE_HZ, "Hz"),
            ("bias_range_v", self.bias_range_v, cmd.BIAS_RANGE_V, "V"),
        ):
            strict_range(f"{name}[0]", lo, dev, unit)
            strict_range(f"{name}[1]", hi, dev, unit)
            if lo > hi:
                raise LimitError(name, (lo, hi), "lo <= hi", unit)


def _on_off(value: bool) -> str:
    return "ON" if value else "OFF"


class FrontEndChannel:
    """One drive output and its pickoff input (1 = x coordinate, 2 = y coordinate)."""

    amplitude_v = control(
        cmd.DRIVE_AMPLITUDE + "?", cmd.DRIVE_AMPLITUDE + " {value}", "Drive amplitude (peak)",
        values=lambda c: (cmd.AMPLITUDE_RANGE_V[0], c.parent.limits.max_amplitude_v), unit="V",
    )
    frequency_hz = control(
        cmd.DRIVE_FREQUENCY + "?", cmd.DRIVE_FREQUENCY + " {value}", "Drive (and lock-in reference) frequency",
        values=lambda c: c.parent.limits.frequency_range_hz, unit="Hz",
    )
    phase_deg = control(
        cmd.DRIVE_PHASE + "?", cmd.DRIVE_PHASE + " {value}", "Drive phase: v = A cos(wt + phase)",
        values=cmd.PHASE_RANGE_DEG, unit="deg",
    )
    bias_v = control(
        cmd.DRIVE_BIAS + "?", cmd.DRIVE_BIAS + " {value}", "Electrode DC bias",
        values=lambda c: c.parent.limits.bias_range_v, unit="V",
    )
    output_on = control(
        cmd.OUTPUT + "?", cmd.OUTPUT + " {value}", "Drive output relay on/off",
        validator=boolean, get_parser=parse_bool, set_formatter=_on_off,
    )
    input_range_v = control(
        cmd.INPUT_RANGE + "?", cmd.INPUT_RANGE + " {value}", "Pickoff input range (full scale, +/-)",
        validator=strict_discrete_set, values=cmd.INPUT_RANGES_V, unit="V",
    )

    def __init__(self, parent: ScpiFrontEnd, channel_id: int) -> None:
        self.parent = parent
        self.channel_id = channel_id
        self.label = f"ch{channel_id}"

    def _query(self, command: str) -> str:
        return self.parent._query(command)

    def _set(self, command: str) -> None:
        self.parent._set(command)

    def lockin_xy(self) -> tuple[float, float]:
        """Lock-in (X, Y) of this pickoff against the drive reference [V]."""
        return self.parent.lockin_xy(self.channel_id)


class ScpiFrontEnd:
    """The front end over VISA.  Thread-safe: one transaction at a time."""

    sample_rate_hz = control(
        cmd.SAMPLE_RATE + "?", cmd.SAMPLE_RATE + " {value}", "ADC sample rate of raw captures",
        values=cmd.SAMPLE_RATE_RANGE_HZ, unit="Hz",
    )
    lockin_tc_s = control(
        cmd.LOCKIN_TC + "?", cmd.LOCKIN_TC + " {value}", "Lock-in low-pass time constant (first order)",
        values=cmd.TIME_CONSTANT_RANGE_S, unit="s",
    )
    capture_points = control(
        cmd.CAPTURE_POINTS + "?", cmd.CAPTURE_POINTS + " {value}", "Samples per raw capture",
        validator=strict_int_range, values=cmd.CAPTURE_POINTS_RANGE,
        get_parser=lambda r: int(float(r)), set_formatter=lambda n: str(int(n)),
    )

    def __init__(
        self,
        resource_name: str,
        *,
        clock: Any,
        limits: FrontEndLimits | None = None,
        timeout_s: float = 2.0,
        resource_manager: Any = None,
    ) -> None:
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise LimitError("timeout_s", timeout_s, "> 0", "s")
        self.resource_name = resource_name
        self.clock = clock
        self.limits = limits or FrontEndLimits()
        self.timeout_s = float(timeout_s)
        self._rm = resource_manager
        self._own_rm = resource_manager is None
        self._res: Any = None
        self._lost = False
        self._lock = threading.RLock()
        self.channels = {ch: FrontEndChannel(self, ch) for ch in cmd.CHANNELS}
        self.ch1, self.ch2 = self.channels[1], self.channels[2]

    # --- connection ---------------------------------------------------------------------------
    def connect(self) -> ScpiFrontEnd:
        """Open the resource, set terminations and timeout, clear the status and error queue."""
        import pyvisa

        with self._lock:
            self._close_resource()
            if self._rm is None:
                self._rm = pyvisa.ResourceManager("@py")
            try:
                self._res = self._rm.open_resource(
                    self.resource_name,
                    read_termination=cmd.TERMINATION,
                    write_termination=cmd.TERMINATION,
                    timeout=int(round(self.timeout_s * 1000)),
                )
                self._res.chunk_size = 1 << 20
            except (pyvisa.errors.VisaIOError, OSError) as exc:
                self._res = None
                raise LinkLostError(f"front end {self.resource_name}: cannot open ({exc})") from exc
            self._lost = False
            self._write(cmd.CLS)
            self.idn  # noqa: B018 - the first query proves the link
        return self

    def close(self) -> None:
        with self._lock:
            self._close_resource()
            if self._own_rm and self._rm is not None:
                try:
                    self._rm.close()
                except Exception:  # noqa: BLE001 - closing must not raise
                    pass
                self._rm = None

    def _close_resource(self) -> None:
        if self._res is not None:
            try:
                self._res.close()
            except Exception:  # noqa: BLE001
                pass
            self._res = None

    def __enter__(self) -> ScpiFrontEnd:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- transactions -------------------------------------------------------------------------
    def _resource(self) -> Any:
        if self._res is None:
            raise LinkLostError(f"front end {self.resource_name}: not connected (call connect())")
        if self._lost:
            raise LinkLostError(f"front end {self.resource_name}: link lost earlier; call connect() again")
        return self._res

    def _link_lost(self, exc: Exception, what: str) -> LinkLostError:
        self._lost = True
        return LinkLostError(
            f"front end {self.resource_name}: no answer to {what!r} within {self.timeout_s:g} s ({exc})"
        )

    def _write(self, command: str) -> None:
        import pyvisa

        with self._lock:
            res = self._resource()
            try:
                res.write(command)
            except (pyvisa.errors.VisaIOError, OSError) as exc:
                raise self._link_lost(exc, command) from exc

    def _query(self, command: str) -> str:
        """One query, its reply without the terminator; LinkLostError on timeout."""
        import pyvisa

        with self._lock:
            res = self._resource()
            try:
                return res.query(command)
            except (pyvisa.errors.VisaIOError, OSError) as exc:
                raise self._link_lost(exc, command) from exc
            except UnicodeDecodeError as exc:
                raise ProtocolError(f"{command!r}: reply is not text ({exc})") from exc

    def _set(self, command: str) -> None:
        """Send a setting with SYST:ERR? in one message; DeviceError if the instrument refused it."""
        reply = self._query(f"{command}{cmd.SEPARATOR}:{cmd.SYST_ERR}")
        try:
            code, message = cmd.parse_error(reply)
        except ValueError:
            raise ProtocolError(f"{command!r}: error queue answered {reply!r}") from None
        if code != 0:
            raise DeviceError(f"front end refused {command!r}: {code} {message}")

    # --- common commands ----------------------------------------------------------------------
    @property
    def idn(self) -> str:
        """*IDN? reply: manufacturer, model, serial, firmware."""
        reply = self._query(cmd.IDN)
        if reply.count(",") != 3:
            raise ProtocolError(f"*IDN? answered {reply!r}: expected four comma-separated fields")
        return reply

    def reset(self) -> None:
        """*RST: outputs off, amplitudes zero, every setting to its default; then *CLS."""
        self._set(cmd.RST)
        self._write(cmd.CLS)
        self.wait_complete()

    def wait_complete(self) -> None:
        """*OPC?: returns once every pending operation has finished."""
        reply = self._query(cmd.OPC)
        if reply.strip() != "1":
            raise ProtocolError(f"*OPC? answered {reply!r}")

    def event_status(self) -> int:
        """*ESR? (reading clears it): bit 5 command error, 4 execution, 3 device, 2 query."""
        reply = self._query(cmd.ESR)
        try:
            return int(reply)
        except ValueError:
            raise ProtocolError(f"*ESR? answered {reply!r}") from None

    def check_errors(self) -> list[tuple[int, str]]:
        """Drain the error queue; the (code, message) pairs found, [] when clean."""
        errors: list[tuple[int, str]] = []
        for _ in range(cmd.ERROR_QUEUE_DEPTH + 1):
            reply = self._query(cmd.SYST_ERR)
            try:
                code, message = cmd.parse_error(reply)
            except ValueError:
                raise ProtocolError(f"SYST:ERR? answered {reply!r}") from None
            if code == 0:
                return errors
            errors.append((code, message))
        return errors

    # --- channels -----------------------------------------------------------------------------
    def channel(self, channel: int) -> FrontEndChannel:
        """Channel 1 (x) or 2 (y); LimitError for any other number."""
        ch = strict_discrete_set("channel", channel, cmd.CHANNELS)
        return self.channels[ch]

    def set_drive(
        self,
        channel: int,
        *,
        amplitude_v: float | None = None,
        frequency_hz: float | None = None,
        phase_deg: float | None = None,
        output_on: bool | None = None,
    ) -> None:
        """Set several drive settings of one channel; all are validated before any is sent."""
        c = self.channel(channel)
        given = {"frequency_hz": frequency_hz, "phase_deg": phase_deg, "amplitude_v": amplitude_v}
        given["output_on"] = output_on
        todo = {k: v for k, v in given.items() if v is not None}
        for name, value in todo.items():
            type(c).__dict__[name].validate(c, value)
        for name, value in todo.items():
            setattr(c, name, value)

    def set_frequency_hz(self, frequency_hz: float) -> None:
        """Both channels' drive frequency (the sweep step); validated before anything is sent."""
        for c in self.channels.values():
            FrontEndChannel.frequency_hz.validate(c, frequency_hz)
        for c in self.channels.values():
            c.frequency_hz = frequency_hz

    # --- lock-in ------------------------------------------------------------------------------
    def _floats(self, command: str, n: int) -> tuple[float, ...]:
        reply = self._query(command)
        try:
            values = tuple(float(v) for v in reply.split(","))
        except ValueError:
            values = ()
        if len(values) != n or not all(math.isfinite(v) for v in values):
            raise ProtocolError(f"{command!r} answered {reply!r}: expected {n} finite numbers")
        return values

    def lockin_xy(self, channel: int) -> tuple[float, float]:
        """Lock-in (X, Y) of one pickoff channel [V]: X in phase with cos(wt), Y with sin(wt)."""
        ch = self.channel(channel).channel_id
        x, y = self._floats(cmd.LOCKIN_XY.format(ch=ch), 2)
        return x, y

    def lockin_all(self) -> tuple[float, float, float, float]:
        """(X1, Y1, X2, Y2) of both pickoffs in one query, taken at the same instant [V]."""
        x1, y1, x2, y2 = self._floats(cmd.LOCKIN_ALL, 4)
        return x1, y1, x2, y2

    # --- raw capture --------------------------------------------------------------------------
    def capture(self, channel: int, n_samples: int) -> np.ndarray:
        """Acquire n_samples of both pickoffs at sample_rate_hz and return one channel [V].

        The wait for the acquisition goes through the bench clock (virtual time on a simulator),
        bounded by twice the record length plus one second."""
        ch = self.channel(channel).channel_id
        n = type(self).__dict__["capture_points"].validate(self, n_samples)
        rate_hz = self.sample_rate_hz
        self._set(f"{cmd.CAPTURE_POINTS} {n}{cmd.SEPARATOR}:{cmd.CAPTURE_START}")
        duration_s = n / rate_hz
        timeout_s = 2.0 * duration_s + 1.0
        done = self.clock.wait_until(self.capture_done, timeout_s=timeout_s, poll_s=max(duration_s, 1e-3))
        if not done:
            raise DeviceError(f"capture of {n} samples at {rate_hz:g} Hz did not complete within {timeout_s:g} s")
        return self.fetch_capture(ch, expected_samples=n)

    def capture_done(self) -> bool:
        """True once the armed capture has filled."""
        reply = self._query(cmd.CAPTURE_DONE)
        try:
            return parse_bool(reply)
        except ValueError:
            raise ProtocolError(f"{cmd.CAPTURE_DONE!r} answered {reply!r}") from None

    def fetch_capture(self, channel: int, *, expected_samples: int | None = None) -> np.ndarray:
        """Read the last capture of one channel as an IEEE 488.2 definite-length block [V].

        The read termination is switched off for the block and exact byte counts are read (a
        0x0A byte inside the data must not end the read: see TRANSPORTS.md)."""
        import pyvisa

        ch = self.channel(channel).channel_id
        query = cmd.CAPTURE_FETCH.format(ch=ch)
        with self._lock:
            res = self._resource()
            try:
                res.write(query)
                with res.read_termination_context(None):
                    head = res.read_bytes(2)
                    if head[:1] != b"#" or not head[1:2].isdigit() or head[1:2] == b"0":
                        self._lost = True  # the rest of the reply is still in flight: resynchronise
                        raise ProtocolError(f"{query!r}: expected a definite-length block, got {head!r}")
                    n_digits = int(head[1:2])
                    count_text = res.read_bytes(n_digits)
                    if not count_text.isdigit():
                        self._lost = True
                        raise ProtocolError(f"{query!r}: bad block length {count_text!r}")
                    n_bytes = int(count_text)
                    payload = res.read_bytes(n_bytes + 1, chunk_size=n_bytes + 1)
            except (pyvisa.errors.VisaIOError, OSError) as exc:
                raise self._link_lost(exc, query) from exc
        if payload[-1:] != cmd.TERMINATION.encode():
            self._lost = True  # the stream is out of step: reconnect before trusting it again
            raise ProtocolError(f"{query!r}: block of {n_bytes} bytes not followed by the terminator")
        if n_bytes == 0:
            errors = self.check_errors()
            raise DeviceError(f"{query!r}: empty block; instrument errors {errors}")
        itemsize = np.dtype(cmd.BLOCK_DTYPE).itemsize
        if n_bytes % itemsize:
            raise ProtocolError(f"{query!r}: block of {n_bytes} bytes is not whole float32 samples")
        data = np.frombuffer(payload, dtype=cmd.BLOCK_DTYPE, count=n_bytes // itemsize).astype(np.float64)
        if expected_samples is not None and data.size != expected_samples:
            raise ProtocolError(f"{query!r}: {data.size} samples, expected {expected_samples}")
        return data

    # --- safety -------------------------------------------------------------------------------
    def safe_state(self) -> bool:
        """Outputs off, amplitudes zero on every channel; True only when read back as such."""
        failures: list[str] = []
        # every channel's output, then every amplitude, each on its own: one refusal must not
        # leave the other channel driving
        for action in ("output_on", "amplitude_v"):
            for n, c in self.channels.items():
                try:
                    setattr(c, action, False if action == "output_on" else 0.0)
                except Exception as exc:  # noqa: BLE001 - a safe-state attempt reports, it does not raise
                    failures.append(f"ch{n} {action}: {exc}")
        try:
            confirmed = all((not c.output_on) and c.amplitude_v == 0.0 for c in self.channels.values())
        except Exception as exc:  # noqa: BLE001
            failures.append(f"read-back: {exc}")
            confirmed = False
        if failures:
            log.warning("front end %s: safe state trouble: %s", self.resource_name, "; ".join(failures))
        return confirmed and not failures
