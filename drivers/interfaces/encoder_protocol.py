"""The grating encoder's serial protocol: framing and checksum, shared by driver and twin.

An ASCII query/response protocol in the style of serial read-head interfaces, with an
NMEA-like XOR checksum (docs/encoder-protocol.md is the human-readable copy):

    host:    ?P<CR>                                   position query
    reply:   P+0000123456 S01 *2E<CR><LF>             counts, status (hex), checksum

    host:    ?I<CR>                                   identity query
    reply:   I GRT-005 V1.3 *4A<CR><LF>

    reply to anything else:  E01 *64<CR><LF>          (error code 01: unknown command)

The checksum is the XOR of every byte before ``*``, written as two upper-case hex
digits.  ASCII was chosen over a binary frame because a technician can read it on a
terminal, and every frame starts with a letter and ends with CR LF, so a reader that
has lost sync finds the next frame boundary by itself.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

POSITION_QUERY = b"?P\r"
IDENTITY_QUERY = b"?I\r"
#: every reply ends with this
TERMINATOR = b"\r\n"
#: a reply is never longer; a longer run without terminator is garbage
MAX_REPLY_BYTES = 64

#: counts are 10 decimal digits with a sign: +-9 999 999 999 counts
POSITION_DIGITS = 10


class EncoderStatusBit(enum.IntFlag):
    REFERENCED = 0x01  #: the reference mark has been passed since power-on
    SIGNAL_LOW = 0x02  #: grating signal amplitude below limit (dirt, misalignment)
    OVERSPEED = 0x04  #: the head moved faster than the interpolator can count
    HARDWARE_ERROR = 0x08


class EncoderErrorCode(enum.IntEnum):
    UNKNOWN_COMMAND = 0x01
    BUSY = 0x02


def checksum(body: bytes) -> int:
    """XOR of all bytes of ``body`` (everything before ``*``)."""
    c = 0
    for b in body:
        c ^= b
    return c


def seal(body: bytes) -> bytes:
    """``body`` + ``*CS`` + CR LF: a complete reply frame."""
    return body + b"*" + f"{checksum(body):02X}".encode("ascii") + TERMINATOR


def position_reply(counts: int, status: int) -> bytes:
    sign = b"+" if counts >= 0 else b"-"
    digits = f"{abs(int(counts)):0{POSITION_DIGITS}d}".encode("ascii")
    if len(digits) > POSITION_DIGITS:
        raise OverflowError(f"{counts} counts do not fit the position field")
    return seal(b"P" + sign + digits + b" S" + f"{status & 0xFF:02X}".encode("ascii") + b" ")


def identity_reply(model: str, version: str) -> bytes:
    return seal(f"I {model} {version} ".encode("ascii"))


def error_reply(code: int) -> bytes:
    return seal(f"E{code:02X} ".encode("ascii"))


class FrameError(ValueError):
    """A complete frame that is not valid (bad checksum or layout)."""


@dataclass(frozen=True)
class Reply:
    kind: str  #: "P", "I" or "E"
    counts: int = 0
    status: int = 0
    text: str = ""
    error_code: int = 0


_FRAME_RE = re.compile(rb"^(?P<body>[PIE][ -~]*?)\*(?P<cs>[0-9A-F]{2})$")
_POSITION_RE = re.compile(rb"^P(?P<sign>[+-])(?P<digits>\d{%d}) S(?P<status>[0-9A-F]{2}) $" % POSITION_DIGITS)
_ERROR_RE = re.compile(rb"^E(?P<code>[0-9A-F]{2}) $")


def parse_frame(frame: bytes) -> Reply:
    """Parse one frame *without* its CR LF; raise FrameError if it is not a valid reply."""
    m = _FRAME_RE.match(frame)
    if not m:
        raise FrameError(f"malformed frame {frame!r}")
    body = m.group("body")
    if checksum(body) != int(m.group("cs"), 16):
        raise FrameError(f"checksum mismatch in {frame!r} (computed {checksum(body):02X})")
    if body[:1] == b"P":
        p = _POSITION_RE.match(body)
        if not p:
            raise FrameError(f"malformed position frame {frame!r}")
        counts = int(p.group("digits"))
        if p.group("sign") == b"-":
            counts = -counts
        return Reply("P", counts=counts, status=int(p.group("status"), 16))
    if body[:1] == b"E":
        e = _ERROR_RE.match(body)
        if not e:
            raise FrameError(f"malformed error frame {frame!r}")
        return Reply("E", error_code=int(e.group("code"), 16))
    return Reply("I", text=body[1:].decode("ascii").strip())
