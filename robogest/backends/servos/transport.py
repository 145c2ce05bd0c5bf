"""The one transport to a servo bus: a port opened exclusively with one protocol's SDK at one baud rate, and the
raw transactions on it, every reply matched to its request.

The backends (:class:`~robogest.backends.servos.bus.ServoBackend`) and bring-up (scan, doctor, setup, find-port,
``servo read``/``write``) both talk through a :class:`Transport`: the same byte order, the same late-reply handling,
the same retries. Values here are raw register values (unsigned, as on the wire); the :class:`~.wire.Wire` of the
protocol signs them. Ticks and registers never leave :mod:`robogest.backends.servos`.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from enum import Enum

from robogest.backends.servos.protocol import ServoProtocol
from robogest.backends.servos.sdk import GroupSyncWriteLike, PortHandlerLike, SdkModule
from robogest.backends.servos.wire import Wire, wire_of
from robogest.errors import BackendError, InputError

#: Result of one raw transaction: (parameters as sent, ok, status error byte, comm description).
RawReply = tuple[list[int], bool, int, str]
#: One servo's part of a sync read: (parameters or None when missing/corrupt, status error byte, comm description).
SyncReply = tuple[list[int] | None, int, str]


class Transport:
    """One serial port, one protocol, one baud rate (see the module docstring).

    Parameters
    ----------
    port_name : str
    protocol : ServoProtocol
    baudrate : int
    late_reply_window_s : float
        How long a reply that missed its deadline may still arrive. Every reply is matched to its request by servo
        id and length; within this window a read whose answer could not be told apart from such a late reply (same
        servo, same length, other register) also reads the byte below, so its answer's length is unique; a write
        drains the input until the line is quiet for ``late_reply_quiet_s`` (25 ms, above a USB adapter's 16 ms
        latency timer).
    who : callable, optional
        ``who(sid)`` names a servo in messages (a backend adds its joint); default ``"servo id N"``.
    events : list of str, optional
        Where late replies discarded are reported (a backend's ``events``).

    Opening raises as :func:`open_port_exclusive` does (a missing or busy port, a baud rate the SDK lacks).
    """

    def __init__(
        self,
        port_name: str,
        protocol: ServoProtocol,
        baudrate: int,
        *,
        late_reply_window_s: float = 0.5,
        who: Callable[[int], str] | None = None,
        events: list[str] | None = None,
    ) -> None:
        self.protocol = protocol
        self.wire: Wire = wire_of(protocol)
        self.sdk: SdkModule = self.wire.load_sdk()
        self.port_name, self.baudrate = port_name, int(baudrate)
        self.late_reply_window_s = late_reply_window_s
        self.late_reply_quiet_s = 0.025
        self.who = who or (lambda sid: f"servo id {sid}")
        self.events: list[str] = events if events is not None else []
        self.stale_replies = 0  #: status packets discarded as late answers to earlier requests
        self.stale_bytes = 0  #: bytes of late replies dropped before a request
        self._late: dict[tuple[int, int], tuple[int, float]] = {}  # (id, reply length) -> (address, until)
        self._writers: dict[Enum, GroupSyncWriteLike] = {}
        self.ph = self.sdk.PacketHandler(self.wire.packet_arg)
        self.prep()
        self.port: PortHandlerLike = open_port_exclusive(self.sdk, port_name, self.baudrate)

    def close(self) -> None:
        close_port(self.port)

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def ok(self, comm: int) -> bool:
        return comm == self.sdk.COMM_SUCCESS

    def prep(self) -> None:
        """Before every transaction: the protocol's quirk (Feetech's byte order), and the SDK's port freed for it."""
        if self.wire.before_call is not None:
            self.wire.before_call(self.sdk)
        port = getattr(self, "port", None)
        if port is not None:
            port.is_using = False

    def rx_packet(self) -> tuple[list[int], bool]:
        """The next status packet from the SDK and whether it arrived whole with a valid checksum."""
        pkt, comm = self.ph.rxPacket(self.port, *self.wire.rx_flags)
        return list(pkt), self.ok(comm)

    # --- late replies --------------------------------------------------------------------------------
    def begin(self, expect: list[int], n_params: int, addr: int, *, widen: bool = False, ordered: bool = False) -> int:
        """Clear the input before a request expecting ``n_params`` bytes from servos ``expect``; returns how many
        bytes below ``addr`` a read must also ask for.

        A reply that missed its own transaction's deadline may still be on its way; bytes already here are dropped,
        and replies arriving later are told apart by servo id and length. When a reply still in flight from one of
        these servos has the expected length but answers another address, a read (``widen``) also asks for the
        byte(s) below ``addr`` so that its answer has a length no late reply has; a write instead drains the input
        until the line has been quiet for ``late_reply_quiet_s``. For a sync read (``ordered``) a late reply of the
        expected length clashes even at the same address: coming ahead of the others, it would pass for this
        round's answer, and since servos answer in order, the servos before it would look lost.
        """
        now = time.monotonic()
        for key in [k for k, (_, until) in self._late.items() if until < now]:
            del self._late[key]

        def clash(k: int) -> bool:
            late = [self._late[key][0] for key in ((sid, n_params + k) for sid in expect) if key in self._late]
            return any(ordered or a != addr - k for a in late)

        k = 0
        while clash(k) and widen and k < addr:
            k += 1
        ser = self.port.ser
        waiting = ser.in_waiting
        if waiting:  # late replies that arrived after their deadline: counted, then dropped
            self.stale_bytes += len(ser.read(waiting))
        ser.reset_input_buffer()
        if clash(k):
            self.drain_quiet()
            self._late.clear()
            return 0
        return k

    def drain_quiet(self) -> None:
        ser = self.port.ser
        t_end = time.monotonic() + self.late_reply_window_s
        last = time.monotonic()
        while True:
            n = ser.in_waiting
            now = time.monotonic()
            if n:
                self.stale_bytes += len(ser.read(n))
                last = now
            elif now - last >= self.late_reply_quiet_s or now > t_end:
                return
            time.sleep(0.001)

    def mark_late(self, ids: list[int], n_params: int, addr: int) -> None:
        """Replies from ``ids`` to the request at ``addr`` did not arrive in time: they may still come."""
        until = time.monotonic() + self.late_reply_window_s
        for sid in ids:
            self._late[(sid, n_params)] = (addr, until)

    def forget_late(self) -> None:
        self._late.clear()

    def split_status(self, pkt: list[int]) -> tuple[int, int, list[int]]:
        """``(id, error byte, parameters)`` of a status packet."""
        id_at, err_at, p0, trailer = self.wire.status_layout
        return pkt[id_at], pkt[err_at], pkt[p0 : len(pkt) - trailer]

    def await_status(self, sid: int, n_params: int, addr: int) -> RawReply:
        """Receive until the status packet of ``sid`` with ``n_params`` parameters, or the deadline.

        Packets from other servos or of another length are late replies to earlier requests: they are counted and
        skipped, never taken as this request's answer.
        """
        while True:
            pkt, valid = self.rx_packet()
            if not valid:
                self.mark_late([sid], n_params, addr)
                self.port.is_using = False
                return [], False, 0, "no reply (timeout)" if not pkt else "corrupt reply (bad checksum or cut short)"
            pid, err, params = self.split_status(pkt)
            if pid == sid and len(params) == n_params:
                self.port.is_using = False
                return params, True, err, "ok"
            self.discard_stale(pkt, self.who(sid))

    def discard_stale(self, pkt: list[int], waiting_for: str) -> None:
        pid, _, params = self.split_status(pkt)
        self.stale_replies += 1
        self.events.append(f"discarded a late reply ({len(params)} bytes from id {pid}) waiting for {waiting_for}")

    # --- raw transactions ----------------------------------------------------------------------------
    def read_block(self, sid: int, addr: int, size: int) -> RawReply:
        """``size`` bytes from ``addr`` of one servo, as sent (bus byte order)."""
        self.prep()
        k = self.begin([sid], size, addr, widen=True)
        comm = self.ph.readTx(self.port, sid, addr - k, size + k)
        if not self.ok(comm):
            self.port.is_using = False
            return [], False, 0, self.ph.getTxRxResult(comm)
        data, ok, err, text = self.await_status(sid, size + k, addr - k)
        return data[k:], ok, err, text

    def write_block(self, sid: int, addr: int, data: list[int]) -> RawReply:
        """Write ``data`` (bus byte order) at ``addr`` of one servo and wait for its status packet."""
        self.prep()
        self.begin([sid], 0, addr)
        comm = self.ph.writeTxOnly(self.port, sid, addr, len(data), data)
        if not self.ok(comm):
            self.port.is_using = False
            return [], False, 0, self.ph.getTxRxResult(comm)
        _, _, p0, trailer = self.wire.status_layout
        self.port.setPacketTimeout(p0 + trailer)
        return self.await_status(sid, 0, addr)

    def sync_write(self, reg: Enum, values: dict[int, int]) -> None:
        """One SYNC WRITE of raw ``values`` (servo id -> raw value) to ``reg``; never acknowledged by the servos.
        OSError when the SDK could not send it."""
        self.prep()
        addr, size = reg.value
        gsw = self._writers.get(reg)
        if gsw is None:
            gsw = self._writers[reg] = self.sdk.GroupSyncWrite(self.port, self.ph, addr, size)
        gsw.clearParam()
        for sid, v in values.items():
            gsw.addParam(sid, self.wire.to_bytes(v, size))
        comm = gsw.txPacket()
        self.port.is_using = False
        if not self.ok(comm):
            raise OSError(f"sync write {reg.name} failed: {self.ph.getTxRxResult(comm)}")

    def sync_read(self, reg: Enum, ids: list[int]) -> dict[int, SyncReply]:
        """One SYNC READ of ``reg``, status packets matched to ids (the SDKs' group API drops each status error byte,
        and its ``readRx`` discards every reply after a lost one). Protocol 1.0 has none: callers read one by one."""
        self.prep()
        addr, size = reg.value
        k = self.begin(ids, size, addr, widen=True, ordered=True)
        addr, size = addr - k, size + k
        group = self.sdk.GroupSyncRead(self.port, self.ph, addr, size)
        for sid in ids:
            group.addParam(sid)
        comm = group.txPacket()
        if not self.ok(comm):
            self.port.is_using = False
            return {sid: (None, 0, self.ph.getTxRxResult(comm)) for sid in ids}
        id_at, _, p0, trailer = self.wire.status_layout
        got = collect_status_packets(
            ids,
            self.rx_packet,
            self.port.isPacketTimeout,
            id_at,
            length=p0 + size + trailer,
            on_stale=lambda pkt: self.discard_stale(pkt, f"a sync read of {reg.name}"),
        )
        self.port.is_using = False
        out: dict[int, SyncReply] = {}
        for sid in ids:
            pkt = got[sid]
            if pkt is None:
                self.mark_late([sid], size, addr)
                out[sid] = (None, 0, "no valid status packet (missing or corrupt)")
                continue
            _, err, params = self.split_status(pkt)
            out[sid] = (params[k:], err, "ok")
        return out

    # --- with retries (bring-up) ---------------------------------------------------------------------
    def read_at(self, sid: int, addr: int, size: int, what: str, attempts: int = 3) -> tuple[int, int]:
        """``(raw value, status error byte)`` of ``size`` bytes at ``addr``, retried on timeouts and corrupt
        replies; BackendError naming the servo, ``what`` (the register) and the attempts when none came back."""
        comm = "not sent"
        for _ in range(attempts):
            data, ok, err, comm = self.read_block(sid, addr, size)
            if ok and len(data) == size:
                return self.wire.from_bytes(data), err
        raise BackendError(f"{self.who(sid)}: reading {what}: {comm} ({_attempts(attempts)})")

    def write_at(self, sid: int, addr: int, size: int, raw: int, what: str, attempts: int = 3) -> int:
        """Write raw ``raw`` into ``size`` bytes at ``addr``; returns the status error byte; retried and raising as
        :meth:`read_at`."""
        comm = "not sent"
        for _ in range(attempts):
            _, ok, err, comm = self.write_block(sid, addr, self.wire.to_bytes(raw, size))
            if ok:
                return err
        raise BackendError(f"{self.who(sid)}: writing {what}: {comm} ({_attempts(attempts)})")

    def read(self, sid: int, reg: Enum, attempts: int = 3) -> int:
        """One register's raw (unsigned) value; BackendError naming the servo, register and attempts."""
        addr, size = reg.value
        return self.read_at(sid, addr, size, reg.name, attempts)[0]

    def write(self, sid: int, reg: Enum, value: int, attempts: int = 3) -> int:
        """One register (raw value); returns the status error byte."""
        addr, size = reg.value
        return self.write_at(sid, addr, size, int(value), reg.name, attempts)


def _attempts(n: int) -> str:
    return "1 attempt" if n == 1 else f"{n} attempts"


def collect_status_packets(
    ids: list[int],
    receive: Callable[[], tuple[list[int], bool]],
    timed_out: Callable[[], bool],
    id_at: int,
    length: int | None = None,
    on_stale: Callable[[list[int]], None] | None = None,
) -> dict[int, list[int] | None]:
    """Match the status packets of one sync read to servo ids: ``{id: packet, or None when missing/corrupt}``.

    ``receive()`` returns the next packet and whether its checksum was valid; ``timed_out()`` says whether the
    read's deadline has passed. The SDKs' ``readRx(id)`` skips packets of other ids while looking for its own, so
    one lost reply used to swallow every reply after it; here each packet goes to the id it names. Servos answer in
    the order asked, so a reply from a later id means the earlier missing ones are not coming, and no time is spent
    waiting for them. With ``length``, a valid packet of another length is a late reply to another request and is
    skipped. Each valid packet skipped is handed to ``on_stale``.
    """
    pending = list(ids)
    out: dict[int, list[int] | None] = {}
    while pending:
        pkt, valid = receive()
        sid = pkt[id_at] if len(pkt) > id_at else None
        if valid and (sid not in pending or (length is not None and len(pkt) != length)):
            if on_stale is not None:
                on_stale(list(pkt))  # a late reply to another request
            continue
        if sid is not None and sid in pending:
            j = pending.index(sid)
            for earlier in pending[:j]:
                out[earlier] = None
            out[sid] = list(pkt) if valid else None
            del pending[: j + 1]
        if not valid and timed_out():
            break
    for sid in pending:
        out[sid] = None
    return out


def open_port_exclusive(sdk: SdkModule, port_name: str, baudrate: int) -> PortHandlerLike:
    """The vendor SDK's ``PortHandler`` on ``port_name``, opened with an exclusive lock.

    The lock (``flock``, taken by pyserial before it touches the port's settings) keeps a second robogest process
    or tool from opening the port mid-motion; ``TIOCEXCL`` also keeps out other programs that open it without root
    rights. Both SDKs' handlers have the same shape.

    Raises
    ------
    BackendError
        The port is missing or in use; the message names the port.
    InputError
        The SDK does not support ``baudrate``.
    """
    import errno
    import fcntl
    import termios

    import serial

    handler = sdk.PortHandler(port_name)
    if handler.getCFlagBaud(baudrate) <= 0:
        raise InputError(f"baud rate {baudrate} is not supported by {sdk.__name__}; use a standard rate")
    ser = serial.Serial(baudrate=baudrate, bytesize=serial.EIGHTBITS, timeout=0, exclusive=True)
    ser.port = port_name
    try:
        ser.open()
    except (serial.SerialException, OSError) as e:
        if getattr(e, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY):
            raise BackendError(
                f"serial port {port_name} is in use by another program (another robogest or a servo tool); "
                "stop it first"
            ) from None
        raise BackendError(f"cannot open serial port {port_name}: {e}") from None
    with contextlib.suppress(OSError, termios.error, AttributeError):
        fcntl.ioctl(ser.fileno(), termios.TIOCEXCL)
    ser.reset_input_buffer()
    handler.ser, handler.is_open, handler.baudrate = ser, True, baudrate
    handler.tx_time_per_byte = (1000.0 / baudrate) * 10.0
    return handler


def close_port(handler: PortHandlerLike) -> None:
    """Undo :func:`open_port_exclusive` (``TIOCEXCL`` would outlive the close on a port still open elsewhere)."""
    import fcntl
    import termios

    ser = getattr(handler, "ser", None)
    if ser is None or not ser.is_open:
        return
    with contextlib.suppress(OSError, termios.error, ValueError, AttributeError):
        fcntl.ioctl(ser.fileno(), termios.TIOCNXCL)
    with contextlib.suppress(Exception):
        handler.closePort()


def is_port_error(e: BaseException) -> bool:
    """True for errors meaning the port itself is gone (unplugged adapter, closed pty)."""
    import termios

    from serial import SerialException

    return isinstance(e, SerialException | OSError | termios.error)
