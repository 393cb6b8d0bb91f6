"""A simulated soak-rack relay board behind a real pymodbus server (``station/rack/register-map.md``).

:class:`RelayBoardModel` holds the relays; every switch calls ``on_switch(slot, on)`` (the simulated
rack powers its simulated sensors there). :class:`SimulatedRelayBoard` serves it over Modbus/TCP on
127.0.0.1 with the :class:`~station.sim.modbus_server.ThreadedModbusServer` the rig and chamber use, its
coils writable. Faults: no answer, exception replies, a board power loss (every relay off, its
power-on counter up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import ModuleType
from typing import ClassVar

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from station.rack import registers as reg
from station.sim.modbus_server import ThreadedModbusServer


@dataclass
class RelayFaults:
    """Faults to inject at any time: ``no_answer``, ``exception_replies`` (a Modbus exception code, 0 = off)."""

    no_answer: bool = False
    exception_replies: int = 0


@dataclass
class RelayBoardModel:
    """The board's relays and counters."""

    channels: int
    on_switch: Callable[[int, bool], None] | None = None
    faults: RelayFaults = field(default_factory=RelayFaults)
    relays: list[bool] = field(default_factory=list)
    alive: int = 0
    power_on_count: int = 1
    holding: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not 1 <= self.channels <= reg.MAX_CHANNELS:
            raise ValueError(f"a relay board has 1..{reg.MAX_CHANNELS} channels, got {self.channels}")
        self.relays = [False] * self.channels

    def switch(self, slot: int, on: bool) -> None:
        if self.relays[slot] != on:
            self.relays[slot] = on
            if self.on_switch is not None:
                self.on_switch(slot, on)

    def power_loss(self) -> None:
        """The board loses its supply and comes back: every relay drops, the power-on counter counts."""
        for k in range(self.channels):
            self.switch(k, False)
        self.power_on_count += 1

    def input_registers(self) -> dict[int, int]:
        return {reg.IR_CHANNELS: self.channels, reg.IR_ALIVE: self.alive & 0xFFFF,
                reg.IR_POWER_ON_COUNT_LO: self.power_on_count & 0xFFFF,
                reg.IR_POWER_ON_COUNT_HI: (self.power_on_count >> 16) & 0xFFFF}

    def write_holding(self, address: int, values: list[int]) -> ExcCodes | None:
        return ExcCodes.ILLEGAL_ADDRESS


class SimulatedRelayBoard(ThreadedModbusServer):
    """The relay board on Modbus/TCP (127.0.0.1, a free port by default)."""

    _role = "relay board"
    #: the base's register-block glue is unused: _device and _action are the board's own
    _map: ClassVar[ModuleType] = reg
    model: RelayBoardModel

    def __init__(self, channels: int = 64, host: str = "127.0.0.1", port: int = 0, *, unit: int = 1,
                 on_switch: Callable[[int, bool], None] | None = None) -> None:
        self.host, self.port, self.unit = host, port, unit
        self.model = RelayBoardModel(channels, on_switch)
        self._init_server()

    @property
    def faults(self) -> RelayFaults:
        return self.model.faults

    @property
    def url(self) -> str:
        if self.port == 0:
            raise RuntimeError("the simulated relay board is not started (no port yet)")
        return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"

    def _device(self) -> SimDevice:
        n = self.model.channels
        coils = [SimData(reg.RELAY_START, count=n, values=False, datatype=DataType.BITS)]
        discrete = [SimData(0, count=16, values=False, datatype=DataType.BITS, readonly=True)]
        holding = [SimData(0, count=1, values=0, datatype=DataType.REGISTERS)]
        inputs = [SimData(0, count=reg.IR_COUNT, values=0, datatype=DataType.REGISTERS)]
        return SimDevice(id=self.unit, simdata=(coils, discrete, holding, inputs), action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None) -> ExcCodes | None:
        self.accesses += 1
        faults, model = self.model.faults, self.model
        if faults.exception_replies:
            return ExcCodes(faults.exception_replies)
        if faults.no_answer:
            return None
        model.alive += 1
        if function_code == 4:
            for addr, value in model.input_registers().items():
                registers[addr - start_address] = value
            return None
        if function_code in (5, 15) and set_values is not None:
            # coils: ``address`` is the first coil, ``set_values`` one bool per coil
            first = address - reg.RELAY_START
            if first < 0 or first + len(set_values) > model.channels:
                return ExcCodes.ILLEGAL_ADDRESS
            for k, v in enumerate(set_values):
                model.switch(first + k, bool(v))
            return None
        if function_code in (1, 5):
            # reads (and a single write's readback): the datastore packs 16 coils per word, LSB first
            for w in range(len(registers)):
                word = 0
                for b in range(16):
                    k = 16 * (start_address + w) + b - reg.RELAY_START
                    if 0 <= k < model.channels and model.relays[k]:
                        word |= 1 << b
                registers[w] = word
            return None
        if function_code in (6, 16, 23) and set_values is not None:
            return ExcCodes.ILLEGAL_ADDRESS
        return None

    async def _open_server(self) -> ModbusTcpServer:
        server = ModbusTcpServer(self._device(), address=(self.host, self.port), trace_packet=self._trace_packet)
        await server.serve_forever(background=True)
        # pymodbus types the listener's transport as asyncio.BaseTransport; for a server it is the asyncio.Server
        self.port = int(server.transport.sockets[0].getsockname()[1])  # type: ignore[attr-defined]
        return server


__all__ = ["RelayBoardModel", "RelayFaults", "SimulatedRelayBoard"]
