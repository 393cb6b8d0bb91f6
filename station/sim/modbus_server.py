"""A simulated device's register model served by a pymodbus server on a background thread.

:class:`ThreadedModbusServer` holds what the simulated rig and chamber share: the event loop on its
own thread and its lifetime (:meth:`~ThreadedModbusServer.start` returns once the server listens,
:meth:`~ThreadedModbusServer.stop` is idempotent, both as a context manager), the pymodbus device
over the register map (coils unused, holding and input register blocks) and the datastore hook that
hands every access to the model, with the fault switches every device has: no answer (requests
received and ignored, nothing acted on) and exception replies.
"""

from __future__ import annotations

import asyncio
import threading
from types import ModuleType
from typing import Any, ClassVar, Generic, Protocol, Self, TypeVar, cast

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

_WRITE_CODES = frozenset({6, 16, 23})


class ServedModel(Protocol):
    """What the server needs of a device model (``faults`` has ``no_answer`` and ``exception_replies``)."""

    faults: Any
    holding: list[int]

    def input_registers(self) -> dict[int, int]: ...

    def write_holding(self, address: int, values: list[int]) -> ExcCodes | None: ...


#: The device model a server serves.
M = TypeVar("M", bound=ServedModel)


class ThreadedModbusServer(Generic[M]):
    """Base of the simulated Modbus devices; subclasses set :attr:`_role` and :attr:`_map` (the
    register map module: HOLDING/STATE/IDENT start and count), :attr:`model` and :attr:`unit`, call
    :meth:`_init_server` and implement :meth:`_open_server`."""

    #: the device named in the thread name and errors ('rig', 'chamber')
    _role: ClassVar[str]
    #: the register map module
    _map: ClassVar[ModuleType]

    model: M
    unit: int

    def _init_server(self) -> None:
        self.accesses = 0  # datastore accesses (a write single register counts twice)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stop_event: asyncio.Event | None = None
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._start_error: BaseException | None = None

    # ------------------------------------------------------------------ pymodbus glue

    def _device(self) -> SimDevice:
        m = self._map
        bits = [SimData(0, count=16, values=False, datatype=DataType.BITS, readonly=True)]
        holding = [SimData(m.HOLDING_START, count=m.HOLDING_COUNT, values=0, datatype=DataType.REGISTERS)]
        inputs = [
            SimData(m.STATE_START, count=m.STATE_COUNT, values=0, datatype=DataType.REGISTERS),
            SimData(m.IDENT_START, count=m.IDENT_COUNT, values=0, datatype=DataType.REGISTERS),
        ]
        return SimDevice(id=self.unit, simdata=(bits, list(bits), holding, inputs), action=self._action)

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """pymodbus datastore hook: runs before every register access (on the server loop)."""
        self.accesses += 1
        faults = self.model.faults
        if faults.exception_replies:
            return ExcCodes(faults.exception_replies)
        if faults.no_answer:
            if set_values is not None:  # a device that does not answer does not act either
                # a register write (the hook runs for registers only: the model has no coils to write)
                cast(list[int], set_values)[:] = registers[address - start_address : address - start_address + count]
            return None
        if function_code == 4:
            for addr, value in self.model.input_registers().items():
                registers[addr - start_address] = value
        elif function_code in (3, 23) and set_values is None:
            first = self._map.HOLDING_START - start_address
            registers[first : first + self._map.HOLDING_COUNT] = self.model.holding
        if set_values is not None and function_code in _WRITE_CODES:
            rc = self.model.write_holding(address, [int(v) for v in set_values])
            if rc is not None:
                return rc
        self._after_access()
        return None

    def _after_access(self) -> None:
        """Called (on the server loop) after an access the model answered without an exception."""

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if sending and self.model.faults.no_answer:
            return b""
        return data

    async def _open_server(self) -> ModbusTcpServer | ModbusSerialServer:
        """Create the server and start it serving in the background (on the server loop)."""
        raise NotImplementedError

    async def _closed(self) -> None:
        """Called on the server loop after the server shut down."""

    async def _serve(self) -> None:
        self._stop_event = asyncio.Event()
        server = await self._open_server()
        self._server = server
        self._ready.set()
        await self._stop_event.wait()
        await server.shutdown()
        await self._closed()

    def _run(self) -> None:
        assert self._loop is not None
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as exc:  # reported to start()
            self._start_error = exc
        finally:
            self._ready.set()
            self._loop.close()

    # ------------------------------------------------------------------ lifetime

    def _thread_name(self) -> str:
        return f"sim-{self._role}"

    def start(self) -> Self:
        """Start serving; returns self once the server listens."""
        if self._thread is not None:
            return self
        self._ready.clear()
        self._start_error = None
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name=self._thread_name(), daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout=10.0) or self._start_error is not None:
            self.stop()
            raise RuntimeError(f"simulated {self._role} did not start: {self._start_error!r}")
        return self

    def stop(self) -> None:
        """Stop the server and its thread (idempotent)."""
        loop, thread = self._loop, self._thread
        if loop is not None and thread is not None and thread.is_alive():
            if self._stop_event is not None:
                loop.call_soon_threadsafe(self._stop_event.set)
            thread.join(timeout=10.0)
        self._thread = None
        self._server = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


__all__ = ["ServedModel", "ThreadedModbusServer"]
