"""The Modbus rate-table controller on loopback: a pymodbus server (TCP, or RTU framing over a
TCP socket that a `socket://` serial URL reaches) in a background thread, backed by a
`TableMechanics` attached to the World.  Register map: drivers/rate_table/modbus_protocol.py."""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass, field
from typing import Any

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simcore import SimCore

from drivers.rate_table import modbus_protocol as mp

from .fault_controls import TableFaultControls
from .mechanics import CommandRejected, TableMechanics
from .pty_bridge import PtyBridge

_READ_FCS = (3, 4)
_WRITE_FCS = (6, 16)


@dataclass
class _LinkFaults:
    """Reply corruption the tests ask for: kind in "short", "garbage", "drop"; count replies."""

    kind: str = ""
    count: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def apply(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            return data
        with self.lock:
            if self.count <= 0:
                return data
            self.count -= 1
            kind = self.kind
        if kind == "short":
            return data[: max(1, len(data) // 2)]
        if kind == "garbage":
            return bytes((b ^ 0x5A) for b in data)
        return b""  # drop


class _TableRegisters:
    """The pymodbus `action`: reads fill registers from the mechanics, writes command it."""

    def __init__(self, world, mech: TableMechanics) -> None:
        self.world, self.mech = world, mech

    async def handle(self, fc, start_address, address, count, registers, set_values):
        if fc not in _READ_FCS + _WRITE_FCS:
            return ExcCodes.ILLEGAL_FUNCTION
        if fc in _WRITE_FCS and set_values is None:
            # pymodbus reads the written register back (FC6 echo) through the action: the write
            # has already been applied and pymodbus stored the written values, so echo them
            return None
        if fc in _WRITE_FCS:
            self.mech.feed()  # every write feeds the watchdog, without waiting for the world
            if address == mp.HR_HEARTBEAT and count == 1:
                return None
            with self.world.lock:
                return self._write(registers, start_address, address, list(set_values))
        with self.world.lock:
            if fc == 4:
                registers[0 : mp.IR_COUNT] = mp.encode_status(*self.mech.status())
            else:
                registers[0 : mp.HR_COUNT] = self._holding()
        return None

    def _holding(self) -> list[int]:
        m = self.mech
        rate = m.traverse_dps if m.mode == mp.MODE_POSITION else m.target_rate_dps
        return [
            m.mode,
            *mp.float_to_regs(rate),
            *mp.float_to_regs(m.target_angle_deg),
            *mp.float_to_regs(m.accel_dps2),
            int(m.enabled),
            0,
            0,
            min(65535, int(round(m.watchdog_s * 1000))),
        ]

    def _write(self, registers, start_address, address, values) -> ExcCodes | None:
        m = self.mech
        regs = self._holding()
        off = address - start_address
        regs[off : off + len(values)] = values
        touched = set(range(address, address + len(values)))
        try:
            if mp.HR_WATCHDOG_MS in touched:
                m.set_watchdog_s(regs[mp.HR_WATCHDOG_MS] / 1000.0)
            if mp.HR_FAULT_RESET in touched:
                if regs[mp.HR_FAULT_RESET] not in (0, 1):
                    return ExcCodes.ILLEGAL_VALUE
                if regs[mp.HR_FAULT_RESET] == 1:
                    m.fault_reset()
            if mp.HR_ENABLE in touched:
                if regs[mp.HR_ENABLE] not in (0, 1):
                    return ExcCodes.ILLEGAL_VALUE
                m.set_enabled(bool(regs[mp.HR_ENABLE]))
            if touched & set(range(mp.CMD_BLOCK_START, mp.CMD_BLOCK_START + mp.CMD_BLOCK_COUNT)):
                rate = mp.regs_to_float(regs[mp.HR_RATE_CMD : mp.HR_RATE_CMD + 2])
                angle = mp.regs_to_float(regs[mp.HR_ANGLE_CMD : mp.HR_ANGLE_CMD + 2])
                accel = mp.regs_to_float(regs[mp.HR_ACCEL : mp.HR_ACCEL + 2])
                m.command(regs[mp.HR_MODE], rate, angle, accel)
        except CommandRejected as exc:
            return ExcCodes.ILLEGAL_VALUE if exc.bad_value else ExcCodes.DEVICE_FAILURE
        registers[0 : mp.HR_COUNT] = self._holding()
        registers[mp.HR_FAULT_RESET] = 0
        return None


class _OneUnitCore(SimCore):
    """The server's datastore, answering only its own unit id (and 255 on TCP, the id the Modbus
    TCP guide reserves for "this server"); any other id raises NoSuchIdException, which pymodbus
    turns into silence (RTU) or exception 0x0B (TCP), see docs/rate_table_modbus.md."""

    def __init__(self, device: SimDevice, *, also: tuple[int, ...] = ()) -> None:
        super().__init__(device)
        self._runtime = self.devices[device.id]
        self._ids = {device.id, *also}

    def _unit(self, device_id: int):
        if device_id not in self._ids:
            raise NoSuchIdException(f"unit id {device_id} is not this controller's")
        return self._runtime

    async def async_getValues(self, device_id, func_code, address, count=1):
        return await self._unit(device_id).async_getValues(func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):
        return await self._unit(device_id).async_setValues(func_code, address, values)


class ModbusTableServer(TableFaultControls):
    """Handle of a running Modbus table: `.host`, `.port`, `.url`, `.mechanics`, `.stop()`."""

    def __init__(
        self, world, mechanics: TableMechanics, *, host: str, port: int, framer: str, device_id: int, use_pty=False
    ):
        if framer not in ("tcp", "rtu"):
            raise ValueError(f"framer={framer!r}: expected 'tcp' or 'rtu'")
        self.world, self.mechanics, self.framer, self.device_id = world, mechanics, framer, device_id
        self.link_faults = _LinkFaults()
        device = SimDevice(
            id=device_id,
            simdata=(
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=16, values=False, datatype=DataType.BITS)],
                [SimData(0, count=mp.HR_COUNT, values=0, datatype=DataType.REGISTERS)],
                [SimData(0, count=mp.IR_COUNT, values=0, datatype=DataType.REGISTERS, readonly=True)],
            ),
            action=_TableRegisters(world, mechanics).handle,
        )
        self._server_args = dict(
            framer=FramerType.SOCKET if framer == "tcp" else FramerType.RTU,
            address=(host, port),
            trace_packet=self.link_faults.apply,
            # a slave on a serial line answers only its own address; a TCP server that is
            # asked for another unit answers "gateway target device failed to respond" (0x0B)
            ignore_missing_devices=framer == "rtu",
        )
        self._device = device
        self._loop = asyncio.new_event_loop()
        self._server: ModbusTcpServer | None = None
        started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(started,), name="modbus-table", daemon=True)
        self._thread.start()
        if not started.wait(10.0) or self._error is not None:
            raise RuntimeError(f"Modbus table server did not start: {self._error!r}")
        sock = self._server.transport.sockets[0]
        self.host, self.port = sock.getsockname()[:2]
        self._bridge = PtyBridge(self.host, self.port) if use_pty else None

    async def _start(self) -> None:
        self._server = ModbusTcpServer(self._device, **self._server_args)
        # pymodbus's own SimCore falls back to unit 0 and fails with a KeyError inside the
        # server for any unknown unit id: ours refuses it as a real controller does
        self._server.context = _OneUnitCore(self._device, also=(255,) if self.framer == "tcp" else ())
        await self._server.serve_forever(background=True)

    def _run(self, started: threading.Event) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start())
        except BaseException as exc:  # reported to the constructor
            self._error = exc
            started.set()
            return
        started.set()
        self._loop.run_forever()
        self._loop.close()

    @property
    def url(self) -> str:
        """What a serial (RTU) client opens through pyserial: the pty path, or `socket://host:port`."""
        return self._bridge.path if self._bridge is not None else f"socket://{self.host}:{self.port}"

    def stop(self) -> None:
        if self._bridge is not None:
            self._bridge.close()
            self._bridge = None
        if not self._thread.is_alive():
            return
        fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
        try:
            fut.result(timeout=5.0)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout=5.0)
        with self.world.lock:
            self.world.detach(self.mechanics)

    def __enter__(self) -> ModbusTableServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def serve_modbus_table(
    world,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    framer: str = "tcp",
    device_id: int = 1,
    use_pty: bool = False,
    mechanics: TableMechanics | None = None,
    **mechanics_kw,
) -> ModbusTableServer:
    """Attach a TableMechanics to the world and serve it over Modbus on loopback (port 0: any);
    use_pty (RTU): also open a pty wired to the server, its path in `.url`."""
    mech = mechanics if mechanics is not None else TableMechanics(seed=world.seed, **mechanics_kw)
    with world.lock:
        world.attach(mech)
    return ModbusTableServer(world, mech, host=host, port=port, framer=framer, device_id=device_id, use_pty=use_pty)


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[ModbusTableServer, dict[str, Any]]:
    """A simulated station's `modbus-table`: served from its station keys; (handle, driver address keys)."""
    handle = serve_modbus_table(
        world,
        max_rate_dps=cfg["max_rate_dps"],
        max_accel_dps2=cfg["max_accel_dps2"],
        watchdog_s=cfg["watchdog_s"],
        device_id=cfg["device_id"],
    )
    return handle, {"host": handle.host, "port": handle.port, "serial_port": ""}
