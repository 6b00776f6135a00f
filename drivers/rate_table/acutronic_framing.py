"""The two ways an Acutrol3000 frames its answers (TM-8004 section 2), shared by the driver and the
simulator (docs/rate_table_acutronic.md, "Answers: two framings").

- **gpib** (IEEE-488): only a message with a query is answered, one line ending in LF; a command
  message gets no answer, so the driver appends `*ESR?` to learn whether it was refused.
- **tcp** (Ethernet port 9878, and every other non-GPIB link): every message is answered.  The
  answer is an 8-byte header, a 32-bit error code then a 32-bit length of the text, little endian
  (TM-9374A 3.4.2 gives this layout for the ACL channel; TM-8004 5.1.1: Intel byte order), then
  that many ASCII characters with no terminator.  A command's text is `OK` (Acutronic's own
  client strips 8 bytes and compares with "OK"); a refused command's text is empty.

Host messages end in LF on both (a CR before it is allowed, a CR alone ends nothing: TM-8004 2.4)
and may hold up to 32,768 characters (TM-8004 2.5); longer ones are lost by the controller.
"""

from __future__ import annotations

import struct

FRAMINGS = ("tcp", "gpib")
HEADER = struct.Struct("<iI")  # error code (0: none), length of the text that follows
HEADER_SIZE = HEADER.size
COMMAND_OK = "OK"
MAX_MESSAGE_CHARS = 32768  # TM-8004 2.5, the message without its terminator
TERMINATOR = b"\n"


def framing_for(resource: str, framing: str = "auto") -> str:
    """The framing a link uses: "tcp" or "gpib" as given, or chosen by the transport ("auto"):
    a GPIB resource speaks lines, a TCP socket (host/port or a VISA socket) the header."""
    f = framing.strip().lower()
    if f == "auto":
        return "gpib" if resource.strip().upper().startswith("GPIB") else "tcp"
    if f not in FRAMINGS:
        raise ValueError(f"framing {framing!r}: expected 'auto', 'tcp' or 'gpib'")
    return f


def message_bytes(message: str) -> bytes:
    """One host message as sent: ASCII, LF-terminated; ValueError when it cannot be one message."""
    if "\n" in message or "\r" in message:
        raise ValueError(f"message {message[:60]!r} holds a line break")
    if len(message) > MAX_MESSAGE_CHARS:
        raise ValueError(f"message of {len(message)} characters: the controller takes {MAX_MESSAGE_CHARS} at most")
    return message.encode("ascii") + TERMINATOR


def message_text(raw: str) -> str | None:
    """A received line -> the message (its LF and a CR before it removed); None when it is not a
    whole message (no LF: a CR alone ends nothing) or is too long, which the controller loses
    (TM-8004 2.5)."""
    if not raw.endswith("\n"):
        return None
    body = raw[:-1]
    if body.endswith("\r"):
        body = body[:-1]
    if len(body) > MAX_MESSAGE_CHARS:
        return None
    return body


def tcp_answer(error_code: int, text: str) -> bytes:
    """The tcp framing's answer: header then text."""
    data = text.encode("ascii", "replace")
    return HEADER.pack(int(error_code), len(data)) + data


def parse_tcp_header(raw: bytes) -> tuple[int, int]:
    """8 header bytes -> (error code, text length); ValueError when not 8 bytes or the length is absurd."""
    if len(raw) != HEADER_SIZE:
        raise ValueError(f"answer header of {len(raw)} bytes, expected {HEADER_SIZE}")
    code, length = HEADER.unpack(raw)
    if length > MAX_MESSAGE_CHARS:
        raise ValueError(f"answer header gives a length of {length}, above the controller's {MAX_MESSAGE_CHARS}")
    return code, length


def gpib_answer(text: str) -> bytes:
    """The gpib framing's answer: one line."""
    return text.encode("ascii", "replace") + TERMINATOR
