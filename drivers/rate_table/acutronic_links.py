"""The Acutrol's links: a TCP socket or a VISA resource carrying raw bytes, and `AclLink`, which
sends one ACL message and reads its answer in the link's framing (acutronic_protocol: GPIB lines
or the TCP header).  Stale input is dropped before each request, so an answer that came after
its timeout is never taken for the answer to a later one."""

from __future__ import annotations

import socket
import time

from . import acutronic_protocol as ap


class AnswerTimeout(OSError):
    """No whole answer within the timeout (what came is in `.partial`)."""

    def __init__(self, message: str, partial: bytes = b"") -> None:
        super().__init__(message)
        self.partial = partial


class SocketBytes:
    """One TCP connection: raw bytes with a deadline."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        self.host, self.port, self.timeout_s = host, int(port), float(timeout_s)
        self._sock: socket.socket | None = None
        self._buf = b""

    def open(self) -> None:
        self._sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def flush(self) -> None:
        """Drop whatever is waiting (a late answer)."""
        self._buf = b""
        sock = self._require()
        sock.setblocking(False)
        try:
            while sock.recv(65536):
                pass
        except (BlockingIOError, InterruptedError):
            pass
        finally:
            sock.settimeout(self.timeout_s)

    def write(self, data: bytes) -> None:
        self._require().sendall(data)

    def read_exact(self, n: int, deadline: float) -> bytes:
        while len(self._buf) < n:
            self._fill(deadline)
        out, self._buf = self._buf[:n], self._buf[n:]
        return out

    def read_line(self, deadline: float) -> bytes:
        while b"\n" not in self._buf:
            self._fill(deadline)
        line, _, self._buf = self._buf.partition(b"\n")
        return line + b"\n"

    def _fill(self, deadline: float) -> None:
        sock = self._require()
        left = deadline - time.monotonic()
        if left <= 0:
            raise AnswerTimeout("no whole answer in time", self._buf)
        sock.settimeout(left)
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            raise AnswerTimeout("no whole answer in time", self._buf) from None
        if not chunk:
            raise OSError("connection closed by the controller")
        self._buf += chunk

    def _require(self) -> socket.socket:
        if self._sock is None:
            raise OSError("not connected")
        return self._sock


class VisaBytes:
    """A VISA resource (GPIB0::1::INSTR, or TCPIP::host::port::SOCKET) through pyvisa."""

    def __init__(self, resource: str, timeout_s: float, *, lines: bool, visa_library: str = "") -> None:
        """lines: answers are LF-terminated lines (the gpib framing), else counted bytes;
        visa_library: pyvisa's library ("@py", a vendor VISA's path, "file.yaml@sim"); "" = pyvisa-py
        for a socket resource, pyvisa's default otherwise."""
        self.resource, self.timeout_s, self.lines = resource, float(timeout_s), lines
        self.visa_library = visa_library
        self._inst = None
        self._stale = False  # an answer timed out: it may still come, drain it before the next request

    def open(self) -> None:
        import pyvisa

        library = self.visa_library or ("@py" if "::SOCKET" in self.resource.upper() else "")
        rm = pyvisa.ResourceManager(library) if library else pyvisa.ResourceManager()
        inst = rm.open_resource(self.resource)
        inst.timeout = int(self.timeout_s * 1000)
        inst.read_termination = "\n" if self.lines else None
        inst.write_termination = ""  # AclLink's bytes carry their LF
        self._inst = inst

    @property
    def instrument(self):
        """The pyvisa resource (None when closed)."""
        return self._inst

    def close(self) -> None:
        if self._inst is not None:
            self._inst.close()
            self._inst = None

    def flush(self) -> None:
        if self._stale:
            self._drain()

    def write(self, data: bytes) -> None:
        self._require().write_raw(data)

    def read_exact(self, n: int, deadline: float) -> bytes:
        return self._timed(deadline, lambda inst: inst.read_bytes(n))

    def read_line(self, deadline: float) -> bytes:
        return self._timed(deadline, lambda inst: inst.read_raw())

    def _timed(self, deadline: float, read) -> bytes:
        import pyvisa

        inst = self._require()
        left_ms = int((deadline - time.monotonic()) * 1000)
        if left_ms <= 0:
            self._stale = True
            raise AnswerTimeout("no whole answer in time")
        inst.timeout = left_ms
        try:
            return bytes(read(inst))
        except pyvisa.errors.VisaIOError as exc:
            if exc.error_code == pyvisa.constants.StatusCode.error_timeout:
                self._stale = True
                raise AnswerTimeout("no whole answer in time") from None
            raise OSError(str(exc)) from exc
        finally:
            inst.timeout = int(self.timeout_s * 1000)

    def _drain(self) -> None:
        """Read and drop a late answer with a short timeout."""
        import pyvisa

        inst = self._require()
        inst.timeout = 50
        try:
            while True:
                inst.read_raw() if self.lines else inst.read_bytes(1 << 16)
        except pyvisa.errors.VisaIOError:
            pass
        finally:
            inst.timeout = int(self.timeout_s * 1000)
            self._stale = False

    def _require(self):
        if self._inst is None:
            raise OSError("not connected")
        return self._inst


class AclLink:
    """One message out, its answer in: `transact(message) -> (error code, text)`.  In the gpib
    framing only messages with a query are answered (the code is then always 0)."""

    def __init__(self, io: SocketBytes | VisaBytes, framing: str, timeout_s: float) -> None:
        if framing not in ap.FRAMINGS:
            raise ValueError(f"framing {framing!r}: expected one of {ap.FRAMINGS}")
        self.io, self.framing, self.timeout_s = io, framing, float(timeout_s)

    def open(self) -> None:
        self.io.open()

    def close(self) -> None:
        self.io.close()

    def transact(self, message: str) -> tuple[int, str]:
        """Send one message and read its answer; AnswerTimeout or OSError when none comes,
        ValueError when the bytes are not an answer (a bad header, non-ASCII text)."""
        data = ap.message_bytes(message)
        self.io.flush()
        self.io.write(data)
        deadline = time.monotonic() + self.timeout_s
        if self.framing == "gpib":
            return 0, self.io.read_line(deadline).decode("ascii").strip()
        code, length = ap.parse_tcp_header(self.io.read_exact(ap.HEADER_SIZE, deadline))
        text = self.io.read_exact(length, deadline) if length else b""
        return code, text.decode("ascii").strip()
