"""The parts of the vendor SDKs (``dynamixel_sdk``, ``scservo_sdk``) robogest calls, as typing Protocols.

The two SDKs share one shape (``scservo_sdk`` is a port of ``dynamixel_sdk``): a ``PortHandler`` owning the pyserial
port, a ``PacketHandler`` per protocol that frames packets, and group sync read/write helpers. Only what is listed
here is used, so a family on another SDK of this shape is one folder (:mod:`robogest.backends.servos`).
"""

from __future__ import annotations

from typing import Protocol


class SerialPortLike(Protocol):
    """The pyserial ``Serial`` a port handler holds."""

    is_open: bool

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def reset_input_buffer(self) -> None: ...

    def fileno(self) -> int: ...


class PortHandlerLike(Protocol):
    """``PortHandler``: the open port and the deadline of the packet being received."""

    ser: SerialPortLike
    is_open: bool
    is_using: bool
    baudrate: int
    tx_time_per_byte: float

    def getCFlagBaud(self, baudrate: int) -> int: ...

    def setPacketTimeout(self, packet_length: int) -> None: ...

    def setPacketTimeoutMillis(self, msec: float) -> None: ...

    def isPacketTimeout(self) -> bool: ...

    def closePort(self) -> None: ...


class PacketHandlerLike(Protocol):
    """``PacketHandler``: frames instruction packets and receives status packets (``COMM_*`` result codes)."""

    def readTx(self, port: PortHandlerLike, sid: int, address: int, length: int) -> int: ...

    def writeTxOnly(self, port: PortHandlerLike, sid: int, address: int, length: int, data: list[int]) -> int: ...

    def txPacket(self, port: PortHandlerLike, packet: list[int]) -> int: ...

    def rxPacket(self, port: PortHandlerLike, *flags: bool) -> tuple[list[int], int]: ...

    def getTxRxResult(self, result: int) -> str: ...

    def getRxPacketError(self, error: int) -> str: ...


class GroupSyncWriteLike(Protocol):
    def clearParam(self) -> None: ...

    def addParam(self, sid: int, data: list[int]) -> bool: ...

    def txPacket(self) -> int: ...


class GroupSyncReadLike(Protocol):
    def addParam(self, sid: int) -> bool: ...

    def txPacket(self) -> int: ...


class SdkModule(Protocol):
    """The SDK module itself: its classes (called as factories) and the success code."""

    __name__: str
    COMM_SUCCESS: int

    def PortHandler(self, port_name: str) -> PortHandlerLike: ...

    def PacketHandler(self, protocol: float) -> PacketHandlerLike: ...

    def GroupSyncWrite(
        self, port: PortHandlerLike, ph: PacketHandlerLike, start_address: int, data_length: int
    ) -> GroupSyncWriteLike: ...

    def GroupSyncRead(
        self, port: PortHandlerLike, ph: PacketHandlerLike, start_address: int, data_length: int
    ) -> GroupSyncReadLike: ...
