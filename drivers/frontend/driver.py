"""Driver for the two-channel DAC/ADC front end (drive outputs, pickoff inputs, lock-in, capture).

Speaks SCPI over any VISA resource (`TCPIP::host::port::SOCKET` through pyvisa-py for the
simulator).  Properties are declared once with their validators and units (`properties.control`);
every setting is sent together with `SYST:ERR?` in one compound message, so a refused setting
raises DeviceError at once.  Out-of-range values raise LimitError before anything is sent.
Every query has a wall-clock deadline of `timeout_s` from its start and carries a tag
(`*ESE <n>;<query>;*ESE?`), so a reply that is not its own is never returned: the input is then
cleared and the link confirmed before the next query.  Waits for the instrument (a capture
filling) go through the bench clock, so they are virtual time on a simulated bench.
"""

from __future__ import annotations

import logging
import math
import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError

from . import commands as cmd
from . import transport
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
        self._suspect = False  # an unexpected reply was seen: confirm the link before the next query
        self._tag = 0
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
                # each low-level read waits one slice; the query's deadline is ours (transport.py)
                self._res.timeout = transport.SLICE_S * 1000.0
                transport.return_partial_reads(self._res)
                self._res.chunk_size = 1 << 20
            except (pyvisa.errors.VisaIOError, OSError) as exc:
                self._res = None
                raise LinkLostError(f"front end {self.resource_name}: cannot open ({exc})") from exc
            self._lost = False
            self._suspect = False
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
        if isinstance(exc, transport.DeadlineExpired):
            detail = f"{len(exc.partial)} bytes came, no complete reply" if exc.partial else "nothing came"
        else:
            detail = str(exc)
        return LinkLostError(
            f"front end {self.resource_name}: no answer to {what!r} within {self.timeout_s:g} s ({detail})"
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
        """One query, its reply without the terminator, complete within timeout_s of wall time from
        the start (LinkLostError otherwise); ProtocolError for a reply that is not this query's."""
        import pyvisa

        with self._lock:
            res = self._resource()
            deadline = time.monotonic() + self.timeout_s
            try:
                if self._suspect:
                    self._confirm(res, command, deadline)
                return self._tagged(res, command, deadline)
            except (pyvisa.errors.VisaIOError, OSError, transport.DeadlineExpired) as exc:
                raise self._link_lost(exc, command) from exc

    def _next_tag(self) -> int:
        lo, hi = cmd.TAG_RANGE
        self._tag = lo if not lo <= self._tag < hi else self._tag + 1
        return self._tag

    def _tagged(self, res: Any, command: str, deadline: float) -> str:
        """Send `*ESE <tag>;<command>;*ESE?` and read its one reply line; the tag at its end proves
        that the line answers this message and no other."""
        tag = self._next_tag()
        res.write(f"{cmd.ESE} {tag}{cmd.SEPARATOR}{command}{cmd.SEPARATOR}{cmd.ESE}?")
        try:
            line = transport.read_line(res, deadline)
        except transport.ReplyTooLong as exc:
            raise self._out_of_step(res, command, b"", deadline, str(exc)) from None
        body, sep, tail = line.rpartition(cmd.SEPARATOR.encode())
        if tail.strip().lstrip(b"+") != str(tag).encode():
            raise self._out_of_step(res, command, line, deadline, f"no tag {tag} at its end")
        try:
            text = body.decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError(f"{command!r}: reply {body!r} is not text") from None
        if not sep:  # only the tag came back: the instrument refused the query itself
            raise DeviceError(f"front end gave no reply to {command!r}: instrument errors {self.check_errors()}")
        return text

    def _out_of_step(self, res: Any, command: str, line: bytes, deadline: float, why: str) -> Exception:
        """A reply that may belong to another query: clear the input, mark the link suspect (the
        error to raise; LinkLostError when the device is still sending at the deadline)."""
        import pyvisa

        self._suspect = True
        try:
            transport.drain(res, deadline)
        except (pyvisa.errors.VisaIOError, OSError, transport.DeadlineExpired) as exc:
            return self._link_lost(exc, command)
        return ProtocolError(
            f"front end {self.resource_name}: {command!r} answered {line[:80]!r} ({why}): not its own reply; "
            "input cleared, the link is confirmed before the next query"
        )

    def _confirm(self, res: Any, command: str, deadline: float) -> None:
        """Clear the input and prove the link in step with a tagged *OPC? before `command`."""
        transport.drain(res, deadline)
        try:
            reply = self._tagged(res, cmd.OPC, deadline)
        except ProtocolError as exc:
            raise ProtocolError(f"front end {self.resource_name}: link out of step before {command!r}: {exc}") from None
        if reply.strip() != "1":
            raise ProtocolError(f"front end {self.resource_name}: link check *OPC? answered {reply!r}")
        self._suspect = False

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

    def probe(self) -> None:
        """The station's link check at every lockstep grid point: the tagged `*IDN?` of `idn`, sent
        and read on pyvisa-py's own TCP socket when that is the transport and nothing is pending
        in its input (pyvisa's write and sliced reads cost twice the round trip itself).  The reply
        is checked as `idn` checks it (its tag, four fields); anything else (another transport, a
        suspect link, no full line within timeout_s, a foreign or extra reply) goes to `idn`, with
        its input clearing, confirmation and errors."""
        with self._lock:
            res = self._resource()
            session = getattr(getattr(res, "visalib", None), "sessions", {}).get(getattr(res, "session", None))
            sock = getattr(session, "interface", None)
            if self._suspect or not isinstance(sock, socket.socket) or getattr(session, "_pending_buffer", b"?"):
                self.idn  # noqa: B018 - the full query path
                return
            tag = self._next_tag()
            message = f"{cmd.ESE} {tag}{cmd.SEPARATOR}{cmd.IDN}{cmd.SEPARATOR}{cmd.ESE}?{cmd.TERMINATION}"
            line = None
            try:
                sock.sendall(message.encode("ascii"))
                line = _recv_line(sock, time.monotonic() + self.timeout_s)
            except OSError:
                pass
            if line is not None:
                body, sep, tail = line.rpartition(cmd.SEPARATOR.encode())
                if sep and tail.strip().lstrip(b"+") == str(tag).encode() and body.count(b",") == 3:
                    return
            self._suspect = True  # the full path clears the input and confirms the link first
            self.idn  # noqa: B018

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
        0x0A byte inside the data must not end the read: see TRANSPORTS.md); the tag follows it."""
        import pyvisa

        ch = self.channel(channel).channel_id
        query = cmd.CAPTURE_FETCH.format(ch=ch)
        with self._lock:
            res = self._resource()
            # a block may be large: its deadline is the timeout plus its transfer at 10 MB/s
            n_max = 4 * (expected_samples or cmd.CAPTURE_POINTS_RANGE[1])
            deadline = time.monotonic() + self.timeout_s + n_max / 10e6
            try:
                if self._suspect:
                    self._confirm(res, query, deadline)
                tag = self._next_tag()
                res.write(f"{cmd.ESE} {tag}{cmd.SEPARATOR}{query}{cmd.SEPARATOR}{cmd.ESE}?")
                with res.read_termination_context(None):
                    head = transport.read_exact(res, 2, deadline)
                    if head[:1] != b"#" or not head[1:2].isdigit() or head[1:2] == b"0":
                        raise self._out_of_step(res, query, head, deadline, "not a definite-length block")
                    n_digits = int(head[1:2])
                    count_text = transport.read_exact(res, n_digits, deadline)
                    if not count_text.isdigit():
                        raise self._out_of_step(res, query, head + count_text, deadline, "bad block length")
                    n_bytes = int(count_text)
                    if n_bytes > n_max:
                        raise self._out_of_step(res, query, head + count_text, deadline, f"over {n_max} bytes")
                    payload = transport.read_exact(res, n_bytes, deadline)
                trailer = transport.read_line(res, deadline, max_bytes=16)
            except transport.ReplyTooLong:
                raise self._out_of_step(res, query, b"", deadline, "no terminator after the block") from None
            except (pyvisa.errors.VisaIOError, OSError, transport.DeadlineExpired) as exc:
                raise self._link_lost(exc, query) from exc
            if trailer != f"{cmd.SEPARATOR}{tag}".encode():
                raise self._out_of_step(res, query, trailer, deadline, f"block not followed by tag {tag}")
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

    def select_slot(self, slot: int) -> None:
        """ROUT:SLOT: switch a front end shared by several gyros on one table to `slot` (1-based);
        the engine does it while the slot holds the front end's lock."""
        lo, hi = cmd.SLOT_RANGE
        if not (isinstance(slot, int) and lo <= slot <= hi):
            raise ValueError(f"front-end slot={slot!r} is not an integer in [{lo}, {hi}]")
        self._set(f"ROUT:SLOT {slot}")

    def selected_slot(self) -> int:
        return int(self._query("ROUT:SLOT?"))

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


def _recv_line(sock: socket.socket, deadline: float) -> bytes | None:
    """One reply line read straight from the socket, without its terminator, before `deadline`;
    None when it did not come whole in time or more than the one line came (the caller then
    takes the full query path, whose input clearing discards the rest)."""
    buf = b""
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or len(buf) > transport.MAX_LINE_BYTES:
            return None
        ready, _, _ = select.select([sock], [], [], left)
        if not ready:
            return None
        chunk = sock.recv(4096)
        if not chunk:
            return None
        buf += chunk
        end = buf.find(transport.TERMINATOR)
        if end >= 0:
            return buf[:end] if end == len(buf) - len(transport.TERMINATOR) else None
