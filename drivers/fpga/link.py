"""FpgaLink: the FPGA register link driver (framed serial via pyserial `serial_for_url`).

One reader thread owns the port's input: it parses every frame, answers waiting register
commands (matched by sequence number) and hands stream blocks to subscribers.  Commands write
from the caller's thread under a lock and wait (wall time) for their ACK; reads and writes are
retried (every register write is an absolute value, so it is idempotent).  Callbacks run on the
reader thread: they must be quick and must not call the link's commands.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import serial

from bench.validation import check_limit
from drivers.errors import DeviceError, LimitError, LinkLostError, ProtocolError

from . import protocol as p

StreamCallback = Callable[[np.ndarray], None]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LinkStats:
    """Stream counters: frames delivered, dropped (sequence gaps, whatever the cause), corrupt
    (frames rejected by CRC or malformed), resyncs (times garbage was skipped)."""

    frames: int
    dropped: int
    corrupt: int
    resyncs: int
    bytes_received: int
    reader_cpu_s: float
    callback_errors: int = 0


def _check_register(reg: p.Register, value: Any, name: str = "") -> None:
    """A register write's value: finite, within [lo, hi], an integer for 'u' (bench.validation's words)."""
    check_limit(name or reg.name, value, int if reg.kind == "u" else float, low=reg.lo, high=reg.hi, unit=reg.unit)


#: wall seconds between closing a lost link and opening it again (pyserial's socket:// close waits
#: this long for every close "in case of quick reconnects"; only a reconnect needs it)
RECONNECT_SETTLE_S = 0.3


def _close_port(ser: serial.SerialBase) -> None:
    """Close a port; a socket:// port's socket is shut and closed here, without the 0.3 s sleep its
    close() adds for a quick reconnect (0.3 s of every station's close; issue 36)."""
    sock = getattr(ser, "_socket", None)
    if sock is None or not ser.is_open:
        ser.close()
        return
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
    sock.close()
    ser._socket = None
    ser.is_open = False


class FpgaLink:
    """Driver of the FPGA register link; the same code runs on a real port, socket:// and a pty."""

    def __init__(self, url: str, *, clock=None, timeout_s: float = 1.0, retries: int = 2) -> None:
        check_limit("timeout_s", timeout_s, low=0.0, low_open=True, unit="s")
        check_limit("retries", retries, int, low=0)
        self.url = url
        self.clock = clock
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self._ser: serial.SerialBase | None = None
        self._write_lock = threading.Lock()
        self._cmd_lock = threading.Lock()  # one command in flight at a time
        self._cond = threading.Condition()
        self._replies: dict[int, p.Frame] = {}
        self._seq = itertools.count(1)
        self._reader: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake: tuple[int, int] | None = None  # close() wakes the reader's select through this pipe
        self._link_error: str | None = None
        self._subscribers: list[StreamCallback] = []
        self._parser = p.FrameParser()
        self._frames = 0
        self._dropped = 0
        self._bytes = 0
        self._reader_cpu_s = 0.0
        self._callback_errors = 0
        self._expected_seq: int | None = None
        self._last_index = -1
        self._stream_start_index = 0
        self._decimation = 1
        self._streaming = False
        self.sample_period_s = float("nan")

    # --- connection ----------------------------------------------------------------------------
    def connect(self) -> FpgaLink:
        """Open the port, start the reader and check the device's identity (after a lost link,
        reopen it)."""
        if self._ser is not None:
            if self._link_error is None:
                return self
            self.close()
            time.sleep(RECONNECT_SETTLE_S)  # what pyserial's socket:// close waits before a quick reconnect
        try:
            self._ser = serial.serial_for_url(self.url, timeout=0, write_timeout=self.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkLostError(f"FPGA link {self.url}: cannot open ({exc})") from exc
        self._stop.clear()
        self._link_error = None
        self._wake = os.pipe()
        self._reader = threading.Thread(target=self._read_loop, name="fpga-link-reader", daemon=True)
        self._reader.start()
        try:
            ident = self.read_register("ID")
            if ident != p.FPGA_ID:
                raise ProtocolError(f"FPGA link {self.url}: ID register is {ident:#x}, expected {p.FPGA_ID:#x}")
            version = int(self.read_register("VERSION"))
            if version != p.PROTOCOL_VERSION:
                raise ProtocolError(
                    f"FPGA link {self.url}: protocol VERSION is {version}, this driver speaks {p.PROTOCOL_VERSION} "
                    f"(stream frames of {p.STREAM_FRAME_SIZE} bytes); update the FPGA image or the bench software"
                )
            self.sample_period_s = float(self.read_register("SAMPLE_PERIOD_S"))
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        self._stop.set()
        wake, self._wake = self._wake, None
        if wake is not None:
            os.write(wake[1], b"\0")  # the reader sees the stop now, not at its next 50 ms poll (issue 36)
        if self._reader is not None:
            self._reader.join(timeout=2.0)
            self._reader = None
        if wake is not None:
            for fd in wake:
                os.close(fd)
        if self._ser is not None:
            try:
                _close_port(self._ser)
            except (serial.SerialException, OSError):
                pass
            self._ser = None

    def __enter__(self) -> FpgaLink:
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        return self._ser is not None and self._link_error is None

    # --- registers -----------------------------------------------------------------------------
    def read_register(self, name_or_addr: str | int) -> float | int:
        """Read one register (retried on timeout or a corrupted reply)."""
        reg = p.register(name_or_addr)
        if reg.access == "wo":
            raise DeviceError(f"FPGA register {reg.name} is write-only")
        reply = self._command(p.READ, reg.addr, b"", f"read {reg.name}")
        return p.decode_value(reg, reply.payload)

    def write_register(self, name_or_addr: str | int, value: float) -> float | int:
        """Write one register after checking its limits; returns the value the device stored."""
        reg = p.register(name_or_addr)
        if reg.access == "ro":
            raise LimitError(reg.name, value, "read-only", message=f"{reg.name}: a read-only register, not written")
        _check_register(reg, value)
        reply = self._command(p.WRITE, reg.addr, p.encode_value(reg, value), f"write {reg.name}={value!r}")
        return p.decode_value(reg, reply.payload)

    def _command(self, ftype: int, addr: int, payload: bytes, what: str) -> p.Frame:
        with self._cmd_lock:
            attempts = self.retries + 1
            for _ in range(attempts):
                self._check_link(what)
                seq = next(self._seq) % p.SEQ_MOD
                self._send(p.encode_frame(ftype, seq, addr, payload), what)
                reply = self._await_reply(seq)
                if reply is None:
                    continue
                if reply.type == p.NACK:
                    code = int.from_bytes(reply.payload[:8], "little") if reply.payload else 0
                    raise DeviceError(f"FPGA {what}: NACK {code} ({p.NACK_REASONS.get(code, 'unknown')})")
                if reply.addr != addr or len(reply.payload) != 8:
                    raise ProtocolError(f"FPGA {what}: reply for address {reply.addr:#x}, {len(reply.payload)} bytes")
                return reply
            self._check_link(what)
            raise LinkLostError(
                f"FPGA link {self.url}: no answer to {what} in {attempts} attempts of {self.timeout_s:g} s"
            )

    def _send(self, data: bytes, what: str) -> None:
        ser = self._ser
        if ser is None:
            raise LinkLostError(f"FPGA link {self.url}: not connected ({what})")
        try:
            with self._write_lock:
                ser.write(data)
        except (serial.SerialException, serial.SerialTimeoutException, OSError) as exc:
            self._fail(f"write failed: {exc}")
            raise LinkLostError(f"FPGA link {self.url}: {what}: write failed ({exc})") from exc

    def _await_reply(self, seq: int) -> p.Frame | None:
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            while seq not in self._replies:
                left = deadline - time.monotonic()
                if left <= 0 or self._link_error is not None:
                    return None
                self._cond.wait(left)
            reply = self._replies.pop(seq)
            self._replies.clear()  # anything else is a stale reply to an abandoned attempt
            return reply

    def _check_link(self, what: str) -> None:
        if self._ser is None:
            raise LinkLostError(f"FPGA link {self.url}: not connected ({what})")
        if self._link_error is not None:
            raise LinkLostError(f"FPGA link {self.url} lost: {self._link_error} ({what})")

    # --- trims in NVM (docs/fpga_link.md) ------------------------------------------------------
    def write_trims(self, values: dict[str, float]) -> dict[str, float]:
        """Write trim registers (names of protocol.TRIM_BLOCK); every value is checked before the
        first write.  Returns what the device stored.  Not in NVM until `commit_trims()`."""
        for name, value in values.items():
            if name not in p.TRIM_BLOCK:
                raise DeviceError(f"{name} is not a trim register (one of {', '.join(p.TRIM_BLOCK)})")
            _check_register(p.BY_NAME[name], value)
        return {name: self.write_register(name, value) for name, value in values.items()}

    def read_trims(self) -> dict[str, float]:
        """Every trim register as the firmware applies it now."""
        return {name: self.read_register(name) for name in p.TRIM_BLOCK}

    def commit_trims(self) -> int:
        """Commit the trim registers to NVM; returns the stored block's CRC once NVM_STATUS says
        valid and equal to the registers (DeviceError otherwise)."""
        self.write_register("NVM_CMD", p.NVM_COMMIT)
        status = int(self.read_register("NVM_STATUS"))
        if status & (p.NVM_VALID | p.NVM_MATCH) != p.NVM_VALID | p.NVM_MATCH:
            raise DeviceError(f"FPGA NVM commit not confirmed: NVM_STATUS={status:#x} (expected valid and matching)")
        return int(self.read_register("NVM_CRC"))

    def set_readout_phase_trim(self, phase_x_deg: float, phase_y_deg: float) -> None:
        """Turn each chain's demodulation reference later by its readout phase (deg at the carrier:
        TRIM_PHASE_X_DEG, TRIM_PHASE_Y_DEG) and switch the trim on (TRIM_EN's TRIM_PHASE bit; the
        other trims as they are).  RAM only, as write_trims; both values are checked first."""
        for name, value in (("TRIM_PHASE_X_DEG", phase_x_deg), ("TRIM_PHASE_Y_DEG", phase_y_deg)):
            _check_register(p.BY_NAME[name], value)
        self.write_register("TRIM_PHASE_X_DEG", phase_x_deg)
        self.write_register("TRIM_PHASE_Y_DEG", phase_y_deg)
        self.write_register("TRIM_EN", int(self.read_register("TRIM_EN")) | p.TRIM_PHASE)

    def reload_trims(self) -> None:
        """Trim registers back from NVM (as at power-up)."""
        self.write_register("NVM_CMD", p.NVM_RELOAD)

    def nvm_status(self) -> dict[str, Any]:
        """NVM state: valid, matching the registers, CRC bad, its CRC and commit count."""
        status = int(self.read_register("NVM_STATUS"))
        return {
            "valid": bool(status & p.NVM_VALID),
            "match": bool(status & p.NVM_MATCH),
            "crc_bad": bool(status & p.NVM_CRC_BAD),
            "crc": int(self.read_register("NVM_CRC")),
            "commits": int(self.read_register("NVM_COMMITS")),
        }

    # --- typed helpers -------------------------------------------------------------------------
    def _set_bits(self, bits: int, on: bool) -> None:
        self.write_register("CTRL_SET" if on else "CTRL_CLR", bits)

    def set_drive_enabled(self, enabled: bool) -> None:
        """Drive enable; False is "cut drive" (every force to zero at the next block)."""
        self._set_bits(p.DRIVE_EN, enabled)

    def set_agc(self, enabled: bool, setpoint: float | None = None) -> None:
        """Amplitude loop on or off, optionally with a new amplitude setpoint."""
        if setpoint is not None:
            self.write_register("AGC_SETPOINT", setpoint)
        self._set_bits(p.AGC_EN, enabled)

    def set_pll(self, enabled: bool, ref_freq_hz: float | None = None) -> None:
        """PLL on or off; ref_freq_hz sets the centre (starting) reference frequency first."""
        if ref_freq_hz is not None:
            self.write_register("REF_FREQ_HZ", ref_freq_hz)
        self._set_bits(p.PLL_EN, enabled)

    def set_quadrature_loop(self, enabled: bool) -> None:
        self._set_bits(p.QUAD_EN, enabled)

    def set_whole_angle(
        self, enabled: bool, precession_cmd_dps: float = 0.0, fm_amplitude_hz: float = 0.0, fm_rate_hz: float = 0.0
    ) -> None:
        """Whole-angle mode with a precession command (wave angle rate, deg/s) and a frequency
        modulation of the reference (amplitude and rate, Hz).  Every value is checked first."""
        for name, value in (
            ("PRECESSION_RATE_DPS", precession_cmd_dps),
            ("FM_AMPLITUDE_HZ", fm_amplitude_hz),
            ("FM_RATE_HZ", fm_rate_hz),
        ):
            _check_register(p.BY_NAME[name], value)
        self.write_register("PRECESSION_RATE_DPS", precession_cmd_dps)
        self.write_register("FM_AMPLITUDE_HZ", fm_amplitude_hz)
        self.write_register("FM_RATE_HZ", fm_rate_hz)
        self._set_bits(p.WHOLE_ANGLE, enabled)

    def set_drift_compensation(self, enabled: bool, d_per_s: float = 0.0, theta_tau_deg: float = 0.0) -> None:
        """Cancel the damping drift (D/4) sin 4(theta - theta_tau) with a precession force
        (whole-angle mode); D and theta_tau as identified by the bench."""
        for name, value in (("DRIFT_D_PER_S", d_per_s), ("DRIFT_THETA_TAU_DEG", theta_tau_deg)):
            _check_register(p.BY_NAME[name], value)
        self.write_register("DRIFT_D_PER_S", d_per_s)
        self.write_register("DRIFT_THETA_TAU_DEG", theta_tau_deg)
        self._set_bits(p.DRIFT_COMP_EN, enabled)

    def set_output_mode(self, mode: str, *, ftr_angle_deg: float | None = None, ftr_gain: float | None = None) -> None:
        """Output mode: "whole-angle" (the wave turns freely; the output is its angle) or
        "force-to-rebalance" (the wave is held at ftr_angle_deg; the output is the rebalance force
        through the gain ftr_gain).  Every value is checked before anything is written."""
        if mode not in p.OUTPUT_MODES:
            raise LimitError("output_mode", mode, "choices",
                             message=f"output_mode={mode!r} is not one of {', '.join(p.OUTPUT_MODES)}")
        writes = [(n, v) for n, v in (("FTR_ANGLE_DEG", ftr_angle_deg), ("FTR_GAIN", ftr_gain)) if v is not None]
        for name, value in writes:
            _check_register(p.BY_NAME[name], value)
        for name, value in writes:
            self.write_register(name, value)
        self.write_register("OUTPUT_MODE", p.OUTPUT_MODES[mode])

    def output_mode(self) -> str:
        """The output mode the FPGA runs ("whole-angle" or "force-to-rebalance")."""
        code = int(self.read_register("OUTPUT_MODE"))
        return {v: k for k, v in p.OUTPUT_MODES.items()}[code]

    def safe_state(self) -> bool:
        """Cut drive and switch every loop off; True only when the read-back confirms it."""
        try:
            self.write_register("CTRL_CLR", p.DRIVE_EN | p.LOOP_BITS)
            ctrl = int(self.read_register("CTRL"))
            status = int(self.read_register("STATUS"))
        except (LinkLostError, DeviceError):
            return False
        return (ctrl & (p.DRIVE_EN | p.LOOP_BITS)) == 0 and not status & p.ST_DRIVE_ON

    # --- stream --------------------------------------------------------------------------------
    def start_stream(self, decimation: int = 1) -> None:
        """Stream every `decimation`-th sample; counters restart from this point."""
        _check_register(p.BY_NAME["STREAM_DECIMATION"], decimation, "decimation")
        self._set_bits(p.STREAM_EN, False)
        self.write_register("STREAM_DECIMATION", decimation)
        with self._cond:
            self._expected_seq = 0
            self._last_index = -1
            self._decimation = int(decimation)
        self._set_bits(p.STREAM_EN, True)
        self._streaming = True
        start = int(self.read_register("STREAM_START_INDEX"))
        with self._cond:
            self._stream_start_index = start
            self._last_index = max(self._last_index, start)

    def stop_stream(self) -> None:
        """Stop the stream; every frame sent before it has been delivered when this returns."""
        self._set_bits(p.STREAM_EN, False)
        self._streaming = False

    def subscribe(self, callback: StreamCallback) -> Callable[[], None]:
        """callback(block) for every parsed block, shape (n, 13) in STREAM_COLUMNS order;
        returns the function that unsubscribes it."""
        with self._cond:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._cond:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    def wait_for_sample(self, index_or_time: int | float, timeout_wall_s: float = 5.0) -> None:
        """Block until every stream frame up to a sample index (int) or a time in seconds (float)
        has been delivered to every subscriber (or counted dropped); LinkLostError if the stream
        makes no progress for timeout_wall_s (a starved host that still delivers frames is slow,
        not lost: the deadline restarts with every frame delivered).
        Returns at once when this link has no stream running (nothing more will come)."""
        if not self._streaming:
            return
        if isinstance(index_or_time, (int, np.integer)):
            target = int(index_or_time)
        else:
            target = int(round(float(index_or_time) / self.sample_period_s))
        deadline = time.monotonic() + timeout_wall_s
        with self._cond:
            need = target - target % self._decimation
            seen = self._last_index
            while self._last_index < need:
                if self._link_error is not None:
                    raise LinkLostError(f"FPGA link {self.url} lost: {self._link_error} (waiting for sample {target})")
                if self._last_index != seen:  # frames still arriving: slow, not lost
                    seen = self._last_index
                    deadline = time.monotonic() + timeout_wall_s
                left = deadline - time.monotonic()
                if left <= 0:
                    raise LinkLostError(
                        f"FPGA link {self.url}: stream stopped at sample {self._last_index}, not {need}: "
                        f"no frame for {timeout_wall_s:g} s"
                    )
                self._cond.wait(min(left, 0.1))

    def sync(self, timeout_wall_s: float = 5.0) -> None:
        """Lockstep helper: wait until every frame up to the bench clock's now is delivered."""
        if self.clock is None:
            raise DeviceError("FpgaLink.sync() needs the bench clock (FpgaLink(url, clock=...))")
        self.wait_for_sample(float(self.clock.now()), timeout_wall_s)

    @property
    def last_index(self) -> int:
        return self._last_index

    @property
    def stats(self) -> LinkStats:
        return LinkStats(
            frames=self._frames,
            dropped=self._dropped,
            corrupt=self._parser.corrupt,
            resyncs=self._parser.resyncs,
            bytes_received=self._bytes,
            reader_cpu_s=self._reader_cpu_s,
            callback_errors=self._callback_errors,
        )

    # --- reader thread -------------------------------------------------------------------------
    def _fail(self, why: str) -> None:
        with self._cond:
            if self._link_error is None:
                self._link_error = why
            self._cond.notify_all()

    def _read_loop(self) -> None:
        ser = self._ser
        assert ser is not None
        try:
            fd = ser.fileno()
        except (AttributeError, NotImplementedError, serial.SerialException, OSError):
            fd = None
        cpu0 = time.thread_time()
        wake = self._wake
        watched = [fd] if wake is None else [fd, wake[0]]
        while not self._stop.is_set():
            try:
                if fd is not None:
                    ready, _, _ = select.select(watched, [], [], 0.05)
                    if fd not in ready:
                        continue
                    # one read of what is there (ser.read would select twice more around its recv)
                    try:
                        data = os.read(fd, 1 << 16)
                    except BlockingIOError:  # a spurious wake-up on a non-blocking port
                        continue
                    if not data:  # readable yet empty: the other end closed
                        raise OSError("link closed by the other end")
                else:
                    ser.timeout = 0.05
                    data = ser.read(max(1, ser.in_waiting))
            except (serial.SerialException, OSError, TypeError, ValueError) as exc:
                if not self._stop.is_set():
                    self._fail(f"read failed: {exc}")
                break
            if not data:
                continue
            self._bytes += len(data)
            self._dispatch(*self._parser.feed(data))
            self._reader_cpu_s = time.thread_time() - cpu0
        self._reader_cpu_s = time.thread_time() - cpu0

    def _dispatch(self, streams: list[np.ndarray], frames: list[p.Frame]) -> None:
        # streams first: a reply is seen only after every frame that came before it was delivered
        for arr in streams:
            self._deliver(arr)
        if frames:
            with self._cond:
                for f in frames:
                    if f.type in (p.ACK, p.NACK):
                        self._replies[f.seq] = f
                self._cond.notify_all()

    def _deliver(self, arr: np.ndarray) -> None:
        seq = arr["seq"]
        first, last = int(seq[0]), int(seq[-1])
        with self._cond:
            expected = self._expected_seq
            if expected is None:
                expected = first
            if first == expected and last - first == len(seq) - 1:
                pass  # the usual run: consecutive from the expected number, nothing lost
            else:
                seq = seq.astype(np.int64)
                prev = np.empty_like(seq)
                prev[0] = expected - 1
                prev[1:] = seq[:-1]
                gaps = (seq - prev - 1) % p.SEQ_MOD
                self._dropped += int(gaps.sum())
            self._expected_seq = (last + 1) % p.SEQ_MOD
            self._frames += len(arr)
            subscribers = list(self._subscribers)
        block = p.stream_rows(arr)
        for cb in subscribers:
            try:
                cb(block)
            except Exception:  # a subscriber's bug must not stop the reader (and every command)
                self._callback_errors += 1
                log.exception("FPGA stream subscriber %r failed", cb)
        # only now is the block "delivered": a wait_for_sample/sync that returns guarantees that
        # every subscriber (recorder, a procedure's tap) has seen it
        with self._cond:
            self._last_index = max(self._last_index, int(arr["index"][-1]))
            self._cond.notify_all()
