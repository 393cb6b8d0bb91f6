"""A text file read in bounded pieces: single lines for a preamble, then blocks of whole lines.

What the session reader streams from (:mod:`station.session.csv_v1`). It holds at most one read
(:data:`READ_BYTES`) plus one partial line, counts the bytes it has read against a limit, and refuses a
line longer than :data:`MAX_LINE_BYTES` (a file with no line ends, e.g. a sparse file of zero bytes or
one with CR-only line ends, is one endless line), so memory stays bounded whatever the input.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["MAX_LINE_BYTES", "READ_BYTES", "LineSource", "LineTooLong", "TooManyBytes"]

#: Bytes per read (and about the size of each block of lines handed to the parser).
READ_BYTES = 4 * 2**20
#: The longest line taken (bytes): a CSV v1 data line is about 140 bytes, a metadata line rarely 100.
MAX_LINE_BYTES = 64 * 2**10


class LineTooLong(Exception):
    """The next line is longer than :data:`MAX_LINE_BYTES`; ``head`` holds its first bytes."""

    def __init__(self, head: bytes) -> None:
        super().__init__(f"line longer than {MAX_LINE_BYTES} bytes")
        self.head = head


class TooManyBytes(Exception):
    """More than ``limit`` bytes were read."""

    def __init__(self, limit: int) -> None:
        super().__init__(f"more than {limit} bytes")
        self.limit = limit


class LineSource:
    """Lines (``\\n``-terminated) from ``read(n) -> bytes`` (b"" at the end), at most ``max_bytes`` in total."""

    def __init__(self, read: Callable[[int], bytes], max_bytes: int, *, read_bytes: int = READ_BYTES) -> None:
        self._read = read
        self._max_bytes = max_bytes
        self._read_bytes = read_bytes
        self._buf = b""
        self._pos = 0
        self._eof = False
        self.bytes_read = 0

    def _fill(self) -> bool:
        """Append one more read to the unread bytes; False at the end of the input."""
        if self._eof:
            return False
        data = self._read(self._read_bytes)
        if not data:
            self._eof = True
            return False
        self.bytes_read += len(data)
        if self.bytes_read > self._max_bytes:
            raise TooManyBytes(self._max_bytes)
        self._buf = self._buf[self._pos:] + data
        self._pos = 0
        return True

    def peek(self) -> bytes:
        """The unread bytes held now (reading once if none are): empty only at the end of the input."""
        if self._pos == len(self._buf):
            self._fill()
        return self._buf[self._pos:]

    def skip(self, n: int) -> None:
        """Drop ``n`` held bytes (at most what :meth:`peek` returned)."""
        self._pos += n

    def discard(self) -> bytes:
        """Drop every held byte and read the next piece: the piece (b"" at the end)."""
        self._buf, self._pos = b"", 0
        return self.peek()

    def line(self) -> bytes | None:
        """The next line with its ``\\n`` (the input's last line may lack it); None at the end of the input.
        Raises :class:`LineTooLong`."""
        while True:
            end = self._buf.find(b"\n", self._pos)
            if end >= 0:
                if end - self._pos > MAX_LINE_BYTES:
                    raise LineTooLong(self._buf[self._pos:self._pos + 200])
                out = self._buf[self._pos:end + 1]
                self._pos = end + 1
                return out
            if len(self._buf) - self._pos > MAX_LINE_BYTES:
                raise LineTooLong(self._buf[self._pos:self._pos + 200])
            if not self._fill():
                if self._pos == len(self._buf):
                    return None
                out = self._buf[self._pos:]
                self._pos = len(self._buf)
                return out

    def block(self) -> bytes | None:
        """The held whole lines (about one read's worth, with their ``\\n``; the last line of the input may lack
        it); None at the end. Raises :class:`LineTooLong` when no line end comes within the line limit."""
        if self._pos == len(self._buf) and not self._fill():
            return None
        while True:
            end = self._buf.rfind(b"\n", self._pos)
            if end >= 0:
                out = self._buf[self._pos:end + 1]
                self._pos = end + 1
                return out
            if len(self._buf) - self._pos > MAX_LINE_BYTES:
                raise LineTooLong(self._buf[self._pos:self._pos + 200])
            if not self._fill():
                out = self._buf[self._pos:]
                self._pos = len(self._buf)
                return out
