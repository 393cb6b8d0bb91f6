"""An emulated serial EEPROM (like a 24C32: 4 KiB, 32-byte pages), in memory only.

Behaviour:
- Reads of any range inside the device; a range outside it raises :class:`EepromAddressError`.
- A page write programs 1..page_size bytes that must not cross a page boundary
  (:class:`EepromPageBoundaryError`). It starts a write cycle of ``write_cycle_s``
  seconds on the given clock; until it ends every access raises :class:`EepromBusyError`
  (a real part NACKs its address while busy).
- With ``write_protect`` set, writes raise :class:`EepromWriteProtectedError` and
  change nothing.
- Fault hook :meth:`Eeprom.power_loss_after`: power fails during a later page write
  after ``n_bytes`` of it are programmed. Those first bytes hold the new data, the
  rest of the written range reads 0xFF (erased, never programmed), bytes of the page
  outside the written range keep their old content. The write reports how many bytes
  it programmed; the owner (the simulated sensor) then loses power.

Content survives power cycles of the sensor (the object lives on); nothing goes to disk.
"""

from __future__ import annotations

import threading

from station.kernel.clock import Clock, WallClock
from station.kernel.errors import HardwareError

ERASED = 0xFF


class EepromError(HardwareError):
    """An EEPROM access the device refuses."""


class EepromAddressError(EepromError):
    """The address range lies (partly) outside the device."""


class EepromPageBoundaryError(EepromError):
    """A page write would cross a page boundary."""


class EepromWriteProtectedError(EepromError):
    """The write-protect pin is asserted."""


class EepromBusyError(EepromError):
    """A write cycle is still in progress."""


class Eeprom:
    """An in-memory EEPROM with page writes, write-cycle time, write protect and a power-loss fault.

    Args:
        size: capacity (bytes).
        page_size: page size (bytes); must divide ``size``.
        write_cycle_s: duration of one page write cycle (s, on ``clock``).
        clock: time source for the write cycle; default wall clock.
        image: initial content (``size`` bytes); default all 0xFF.
    """

    def __init__(
        self,
        size: int = 4096,
        page_size: int = 32,
        write_cycle_s: float = 0.005,
        clock: Clock | None = None,
        image: bytes | None = None,
    ) -> None:
        if size <= 0 or page_size <= 0 or size % page_size:
            raise ValueError("EEPROM size must be a positive multiple of the page size")
        if image is not None and len(image) != size:
            raise ValueError(f"EEPROM image must be {size} bytes, got {len(image)}")
        self.size = size
        self.page_size = page_size
        self.write_cycle_s = float(write_cycle_s)
        self.write_protect = False
        self.page_writes = 0
        self._clock: Clock = clock if clock is not None else WallClock()
        self._mem = bytearray(image) if image is not None else bytearray([ERASED]) * size
        self._busy_until = -float("inf")
        self._loss: tuple[int, int] | None = None  # (page writes to let through, bytes programmed in the next)
        self._lock = threading.Lock()

    @property
    def busy_until(self) -> float:
        """Clock time (s) at which the current write cycle ends."""
        return self._busy_until

    def is_busy(self) -> bool:
        """A write cycle is in progress."""
        return self._clock.now() < self._busy_until

    def _check_range(self, addr: int, n: int) -> None:
        if addr < 0 or n < 0 or addr + n > self.size:
            raise EepromAddressError(f"EEPROM range {addr}+{n} outside 0..{self.size}")

    def read(self, addr: int, n: int) -> bytes:
        """``n`` bytes from ``addr``."""
        with self._lock:
            if self.is_busy():
                raise EepromBusyError("EEPROM write cycle in progress")
            self._check_range(addr, n)
            return bytes(self._mem[addr : addr + n])

    def write_page(self, addr: int, data: bytes) -> int:
        """Program ``data`` at ``addr`` (within one page) and start a write cycle.

        Returns:
            Bytes programmed: ``len(data)``, or fewer if the armed power-loss fault fired.
        """
        with self._lock:
            if self.is_busy():
                raise EepromBusyError("EEPROM write cycle in progress")
            n = len(data)
            if n == 0:
                raise EepromAddressError("EEPROM page write of zero bytes")
            self._check_range(addr, n)
            if addr // self.page_size != (addr + n - 1) // self.page_size:
                raise EepromPageBoundaryError(f"EEPROM write {addr}+{n} crosses a {self.page_size}-byte page boundary")
            if self.write_protect:
                raise EepromWriteProtectedError("EEPROM is write protected")
            programmed = n
            if self._loss is not None:
                pages_left, n_bytes = self._loss
                if pages_left > 0:
                    self._loss = (pages_left - 1, n_bytes)
                else:
                    self._loss = None
                    programmed = min(n_bytes, n)
            self._mem[addr : addr + programmed] = data[:programmed]
            if programmed < n:
                self._mem[addr + programmed : addr + n] = bytes([ERASED]) * (n - programmed)
                self._busy_until = -float("inf")  # the power is gone, so is the write cycle
            else:
                self._busy_until = self._clock.now() + self.write_cycle_s
            self.page_writes += 1
            return programmed

    def power_loss_after(self, n_bytes: int, pages_before: int = 0) -> None:
        """Arm a power failure: ``pages_before`` page writes complete, the next stops after ``n_bytes``.

        ``n_bytes`` >= the length of that write means it completes (and nothing fails).
        """
        if n_bytes < 0 or pages_before < 0:
            raise ValueError("n_bytes and pages_before must be >= 0")
        with self._lock:
            self._loss = (pages_before, n_bytes)

    def disarm(self) -> None:
        """Cancel an armed power-loss fault."""
        with self._lock:
            self._loss = None

    def power_reset(self) -> None:
        """Power came back: any write cycle is over (content is kept)."""
        with self._lock:
            self._busy_until = -float("inf")

    def image(self) -> bytes:
        """A copy of the whole content."""
        with self._lock:
            return bytes(self._mem)
