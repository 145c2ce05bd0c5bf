"""What every serial-servo backend shares: rad <-> tick mapping, retries, health checks, safe shutdown.

The raw transactions (:meth:`ServoBackend._ping_raw` and friends) are written once against the shape both vendor
SDKs share; a family subclass (:mod:`~robogest.backends.dynamixel`, :mod:`~robogest.backends.feetech`) names its
SDK module and registers and supplies its quirks (value encoding, byte order, sync read); ticks never leave this
module and its subclasses.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any, ClassVar

import numpy as np

from robogest.backends.base import Backend
from robogest.backends.governor import Governor, GovernorConfig
from robogest.errors import BackendError, ConfigError, InputError, RobogestError
from robogest.robot.config import RobotConfig

#: Result of one raw SDK transaction: (value, ok, error byte, comm description).
Raw = tuple[int, bool, int, str]


@dataclass(frozen=True)
class ServoModel:
    """Per-model facts the mapping needs."""

    name: str
    number: int
    ticks_per_rev: float
    centre_tick: int
    max_tick: int
    #: One unit of the servo's own speed-cap register (``REG["speed_cap"]``), rad/s at the servo horn.
    speed_unit_rad_s: float
    #: Largest value that register takes.
    speed_max_units: int
    #: One unit of the servo's own acceleration register (``REG["acceleration"]``), rad/s² at the servo horn; 0 for a
    #: model without one (AX-12A, SCS0009), whose acceleration limit is kept by the goal stream alone.
    accel_unit_rad_s2: float = 0.0
    #: Largest value that register takes.
    accel_max_units: int = 0


#: The servos' own speed cap, set at connect, is the joint's velocity limit times this: goals already keep to
#: the limit on average, and the cap keeps the servo from covering each goal step at its full speed between goals
#: (at a low control rate it would otherwise move in bursts far above the limit); the margin keeps it from lagging
#: a goal stream that moves at the limit.
SPEED_CAP_MARGIN = 1.25
#: The servos' own acceleration limit, set at connect, is the joint's acceleration limit times at most this (rounded
#: down to the register's unit): goals keep the limit, but a goal that arrives late, or after one that was lost,
#: is a bigger step, and without its own limit the servo met it at 2.8-3.9x the joint's limit on the simulated bus
#: (``benchmarks/bench_servo_profile.py``); a little above the limit, it still follows goals accelerating at it.
ACCEL_CAP_MARGIN = 1.1


class ServoBackend(Backend):
    """A chain of position-controlled servos on one serial port.

    Parameters
    ----------
    robot : RobotConfig
        Needs a ``bus`` section of this backend's family.
    port, baudrate : optional
        Override ``bus.port`` / ``bus.baudrate``.
    retries : int
        Extra attempts for one transaction that timed out or came back corrupted; for a sync read,
        extra rounds that re-read only the servos whose reply was missing or corrupt.
    tick_retry_budget : int
        Servo re-reads allowed across one control tick (:meth:`_send_goal` + :meth:`read_positions`),
        so one tick never takes much longer than its period. A position read still missing when the
        budget or the rounds are spent keeps the servo's last known value for that tick; a torque write
        that needs more than the budget stops the motion; a health reading that cannot get through is
        skipped, and stops the motion only after ``health_lost_after_s`` (2 s) without one.
    lost_after_s : float
        A servo whose present position has not been read for this long (or for
        ``ceil(lost_after_s * control_rate_hz)`` consecutive ticks), with at least two reads missed in a
        row, is declared lost: motion stopped, torque off. The default leaves room for one reply timeout
        (~35 ms with the SDKs' 16 ms latency-timer allowance) so a vanished servo stops the motion within 0.2 s.
    control_rate_hz : float
        Tick rate used to turn ``lost_after_s`` into ticks, and the rate of the goal guard and of the ramp to rest
        at shutdown; :func:`~robogest.backends.player.play` sets it (:meth:`set_control_rate`).
    health_hz : float
        Each servo's temperature, voltage and load are read at this rate (round robin).
    torque_check_s : float
        While torque is on, every servo's Torque Enable register is read back at least this often: one sync read
        of all servos every ``torque_check_ticks`` position reads (control ticks), or sooner when ticks run late
        and ``torque_check_s`` has passed; without sync read (Dynamixel Protocol 1.0) one servo at a time, each
        once per ``torque_check_ticks``, spread evenly over them. A servo found limp (a brownout or reset, or
        another program on the bus switched it off) stops the motion: the servos still holding torque glide to
        rest, torque goes off, and a BackendError names it; its torque is never switched back on. A read-back that
        gets no reply is repeated on the next tick, so with one lost reply a limp servo is still found within
        0.2 s. 0 turns the check off.
    max_temperature_c : float
        Stop above this temperature.
    voltage_range_v : (float, float), optional
        Stop outside this range; default: the servos' own voltage-limit registers.
    max_load_pct : float, optional
        Stop when |load| exceeds this percentage of the maximum (off by default).
    governor : bool
        Scale gestures down as the servos heat up or strain (:mod:`robogest.backends.governor`).
    warn_temperature_c : float, optional
        Where the governor starts acting; default ``max_temperature_c - 10``. It starts on load at 60 %
        (or 60 % of ``max_load_pct`` when that is set).
    check_limits : bool
        Refuse to connect when the joint limits map outside the servos' position-limit registers;
        ``servo calibrate`` turns it off (the zero offsets it replaces may be what is wrong).
    late_reply_window_s : float
        How long a reply that missed its deadline may still arrive. Every reply is matched to its
        request by servo id and length; within this window a read whose answer could not be told apart
        from such a late reply (same servo, same length, other register) also reads the byte below, so
        its answer's length is unique; a write drains the input until the line is quiet for
        ``late_reply_quiet_s`` (25 ms, above a USB adapter's 16 ms latency timer).
    """

    family: ClassVar[str] = ""
    #: role -> register Enum; set by subclasses (goal, present, torque, temperature, voltage, load, min, max,
    #: speed_cap, acceleration).
    REG: ClassVar[dict[str, Enum]] = {}

    def __init__(
        self,
        robot: RobotConfig,
        port: str | None = None,
        baudrate: int | None = None,
        *,
        retries: int = 2,
        tick_retry_budget: int = 6,
        lost_after_s: float = 0.15,
        control_rate_hz: float = 50.0,
        health_hz: float = 2.0,
        torque_check_s: float = 0.1,
        max_temperature_c: float = 65.0,
        voltage_range_v: tuple[float, float] | None = None,
        max_load_pct: float | None = None,
        late_reply_window_s: float = 0.5,
        governor: bool = True,
        warn_temperature_c: float | None = None,
        check_limits: bool = True,
        **_ignored: Any,
    ) -> None:
        super().__init__(robot)
        bus = robot.bus
        if bus is None:
            raise ConfigError(f"robot {robot.name!r} has no bus section; add bus: family: {self.family}, servos: ...")
        if bus.family != self.family:
            raise ConfigError(
                f"robot {robot.name!r} has {bus.family} servos (bus.family in its YAML), not {self.family}; "
                f"use --backend {bus.family}"
            )
        self.protocol = float(bus.protocol)
        self.port_name = port or bus.port or ""
        if not self.port_name:
            raise ConfigError(f"robot {robot.name!r}: no serial port; pass --port or set bus.port in the YAML")
        self.baudrate = int(baudrate or bus.baudrate)
        self.retries = retries
        self.tick_retry_budget = tick_retry_budget
        self.lost_after_s = lost_after_s
        self.set_control_rate(control_rate_hz)
        self.health_period_s = 1.0 / health_hz if health_hz > 0 else float("inf")
        if not (math.isfinite(torque_check_s) and torque_check_s >= 0):
            raise InputError(f"torque_check_s = {torque_check_s!r} must be a finite number of seconds >= 0 (0: off)")
        self.torque_check_s = float(torque_check_s)
        self.max_temperature_c = max_temperature_c
        self.voltage_range_v = voltage_range_v
        self.max_load_pct = max_load_pct
        self.late_reply_window_s = late_reply_window_s
        self.check_limits = check_limits
        load_limit = max_load_pct if max_load_pct is not None else 100.0
        self.governor = Governor(
            GovernorConfig(
                warn_temperature_c=max_temperature_c - 10.0 if warn_temperature_c is None else warn_temperature_c,
                max_temperature_c=max_temperature_c,
                warn_load_pct=0.6 * load_limit,
                max_load_pct=load_limit,
            ),
            enabled=governor,
        )
        self.late_reply_quiet_s = 0.025
        self.stale_replies = 0  #: status packets discarded as late answers to earlier requests
        self.stale_bytes = 0  #: bytes of late replies dropped before a request
        self._late: dict[tuple[int, int], tuple[int, float]] = {}  # (id, reply length) -> (address, until)

        servos = [bus.servos[n] for n in robot.joint_names]
        self.ids = np.array([s.id for s in servos], dtype=np.int64)
        self.models = [self._lookup_model(s.model, s.id) for s in servos]
        self._dir = np.array([s.direction for s in servos], dtype=float)
        self._gear = np.array([s.gear_ratio for s in servos], dtype=float)
        self._zero = np.array([s.zero_offset_rad for s in servos], dtype=float)
        self._tpr = np.array([m.ticks_per_rev / (2 * np.pi) for m in self.models])
        self._centre = np.array([m.centre_tick for m in self.models], dtype=float)
        self._tick_lo = np.zeros(len(servos), dtype=np.int64)
        self._tick_hi = np.array([m.max_tick for m in self.models], dtype=np.int64)
        self._joint_of = {int(i): n for i, n in zip(self.ids, robot.joint_names, strict=True)}

        self.is_connected = False
        self.port_lost = False
        self.torque_enabled = False
        self.torque_off_attempted = False
        self.retry_count = 0  #: re-sent transactions and re-read servos
        self.missed_reads = 0  #: position reads that got no valid reply within the tick (last value kept)
        self.events: list[str] = []  #: retries and health readings worth reporting
        self._budget = tick_retry_budget
        self._health_idx = 0
        self._next_health = 0.0
        self._health_unread_since: dict[int, float] = {}
        self._torque_reads = 0  # position reads since the last read-back of every servo's torque
        self._torque_read_s = 0.0  # time.monotonic() of that read-back
        self._torque_unread: list[int] = []  # servos whose last torque read-back got no reply: read next tick
        self._torque_put_off_s: float | None = None  # when a read-back was first put off for a struggling bus
        #: Servos found with torque off while it was on (:meth:`_maybe_check_torque`); never switched back on.
        self.limp_ids: list[int] = []
        self._stop_faults: set[str] = set()  # faults noted during the final glide (:meth:`_noted_while_stopping`)
        #: A servo whose health cannot be read for this long stops the motion (seconds).
        self.health_lost_after_s = 2.0
        self._volt_limits: dict[int, tuple[float, float]] = {}
        self._shut_down = False
        self._port: Any = None  # the SDK's PortHandler, PacketHandler and GroupSyncWrite per register, once open
        self._ph: Any = None
        self._writers: dict[Enum, Any] = {}
        n = len(servos)
        self._positions_known = False
        self._last_ticks = np.zeros(n, dtype=np.int64)  # last valid present position per servo
        self._goal_ticks = np.zeros(n, dtype=np.int64)  # the last goal written, ticks
        self._last_ok_s = np.zeros(n)  # time.monotonic() of that reading
        self._misses = np.zeros(n, dtype=np.int64)  # consecutive ticks without a valid reading
        self._miss_attempts = np.zeros(n, dtype=np.int64)  # attempts since the last valid reading

    @property
    def lost_after_ticks(self) -> int:
        return max(1, math.ceil(self.lost_after_s * self.control_rate_hz - 1e-9))

    @property
    def torque_check_ticks(self) -> int:
        """Position reads (control ticks) between two read-backs of a servo's torque: ``torque_check_s`` at the
        control rate, at least 1."""
        return max(1, math.floor(self.torque_check_s * self.control_rate_hz + 1e-9))

    # --- family hooks ----------------------------------------------------------------------------
    #: The vendor SDK module: ``PortHandler``, ``PacketHandler``, ``GroupSyncWrite``, ``COMM_SUCCESS`` (the two SDKs
    #: share these shapes, one being a port of the other). Set by each family.
    sdk: ClassVar[Any] = None

    @classmethod
    def lookup_model(cls, name: str, protocol: float) -> ServoModel:
        """Facts of the servo model called ``name`` on a bus of this ``protocol``; ConfigError if unknown there."""
        raise NotImplementedError

    def _lookup_model(self, name: str, sid: int) -> ServoModel:
        try:
            return self.lookup_model(name, self.protocol)
        except ConfigError as e:
            raise ConfigError(f"servo id {sid}: {e}") from None

    def _packet_protocol(self) -> Any:
        """The ``PacketHandler`` argument (protocol version, or byte order)."""
        raise NotImplementedError

    def _prep(self) -> None:
        """Before every transaction: free the SDK's port for it (families add their quirks)."""
        self._port.is_using = False

    #: Status packet layout: index of the id, of the error byte, of the first parameter, and checksum bytes.
    STATUS_LAYOUT: ClassVar[tuple[int, int, int, int]] = (2, 4, 5, 1)

    def _encode(self, reg: Enum, value: int) -> int:
        """Signed value -> raw register value (default: two's complement in the register's width)."""
        return value & ((1 << (8 * reg.value[1])) - 1)

    def _decode(self, reg: Enum, raw: int) -> int:
        raise NotImplementedError

    def _to_bus_bytes(self, raw: int, size: int) -> list[int]:
        """A raw register value as the bytes on the bus (default: little-endian)."""
        return list(raw.to_bytes(size, "little"))

    def _from_bus_bytes(self, data: bytes | list[int]) -> int:
        """Bytes from the bus -> raw register value (default: little-endian)."""
        return int.from_bytes(bytes(data), "little")

    def _rx_packet(self) -> tuple[list[int], bool]:
        """The next status packet from the SDK and whether it arrived whole with a valid checksum."""
        pkt, comm = self._ph.rxPacket(self._port)
        return list(pkt), comm == self.sdk.COMM_SUCCESS

    def _has_sync_read(self) -> bool:
        return True

    def _open(self) -> None:
        self._port = open_port_exclusive(self.sdk, self.port_name, self.baudrate)
        self._ph = self.sdk.PacketHandler(self._packet_protocol())
        self._writers = {}
        self._late.clear()

    def _close(self) -> None:
        port = getattr(self, "_port", None)
        if port is not None:
            close_port(port)

    # --- raw transactions: every reply is matched to its request ---------------------------------
    def _begin(self, expect: list[int], n_params: int, addr: int, *, widen: bool = False, ordered: bool = False) -> int:
        """Clear the input before a request expecting ``n_params`` bytes from servos ``expect``; returns
        how many bytes below ``addr`` a read must also ask for.

        A reply that missed its own transaction's deadline may still be on its way; bytes already here
        are dropped, and replies arriving later are told apart by servo id and length. When a reply
        still in flight from one of these servos has the expected length but answers another address,
        a read (``widen``) also asks for the byte(s) below ``addr`` so that its answer has a length no
        late reply has; a write instead drains the input until the line has been quiet for
        ``late_reply_quiet_s``. For a sync read (``ordered``) a late reply of the expected length
        clashes even at the same address: coming ahead of the others, it would pass for this round's
        answer, and since servos answer in order, the servos before it would look lost.
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
        ser = self._port.ser
        waiting = ser.in_waiting
        if waiting:  # late replies that arrived after their deadline: counted, then dropped
            self.stale_bytes += len(ser.read(waiting))
        ser.reset_input_buffer()
        if clash(k):
            self._drain_quiet()
            self._late.clear()
            return 0
        return k

    def _drain_quiet(self) -> None:
        ser = self._port.ser
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

    def _mark_late(self, ids: list[int], n_params: int, addr: int) -> None:
        """Replies from ``ids`` to the request at ``addr`` did not arrive in time: they may still come."""
        until = time.monotonic() + self.late_reply_window_s
        for sid in ids:
            self._late[(sid, n_params)] = (addr, until)

    def _split_status(self, pkt: list[int]) -> tuple[int, int, list[int]]:
        id_at, err_at, p0, trailer = self.STATUS_LAYOUT
        return pkt[id_at], pkt[err_at], pkt[p0 : len(pkt) - trailer]

    def _await_status(self, sid: int, n_params: int, addr: int) -> tuple[list[int], bool, int, str]:
        """Receive until the status packet of ``sid`` with ``n_params`` parameters, or the deadline.

        Packets from other servos or of another length are late replies to earlier requests: they
        are counted and skipped, never taken as this request's answer.
        """
        while True:
            pkt, valid = self._rx_packet()
            if not valid:
                self._mark_late([sid], n_params, addr)
                self._port.is_using = False
                return [], False, 0, "no reply (timeout)" if not pkt else "corrupt reply (bad checksum or cut short)"
            pid, err, params = self._split_status(pkt)
            if pid == sid and len(params) == n_params:
                self._port.is_using = False
                return params, True, err, "ok"
            self._discard_stale(pkt, self._who(sid))

    def _discard_stale(self, pkt: list[int], waiting_for: str) -> None:
        pid, _, params = self._split_status(pkt)
        self.stale_replies += 1
        self.events.append(f"discarded a late reply ({len(params)} bytes from id {pid}) waiting for {waiting_for}")

    def _read_block_raw(self, sid: int, addr: int, size: int) -> tuple[list[int], bool, int, str]:
        """``size`` bytes from ``addr`` of one servo, as sent (bus byte order)."""
        self._prep()
        k = self._begin([sid], size, addr, widen=True)
        comm = self._ph.readTx(self._port, sid, addr - k, size + k)
        if comm != self.sdk.COMM_SUCCESS:
            self._port.is_using = False
            return [], False, 0, self._ph.getTxRxResult(comm)
        data, ok, err, text = self._await_status(sid, size + k, addr - k)
        return data[k:], ok, err, text

    def _write_block_raw(self, sid: int, addr: int, data: list[int]) -> tuple[list[int], bool, int, str]:
        self._prep()
        self._begin([sid], 0, addr)
        comm = self._ph.writeTxOnly(self._port, sid, addr, len(data), data)
        if comm != self.sdk.COMM_SUCCESS:
            self._port.is_using = False
            return [], False, 0, self._ph.getTxRxResult(comm)
        _, _, p0, trailer = self.STATUS_LAYOUT
        self._port.setPacketTimeout(p0 + trailer)
        return self._await_status(sid, 0, addr)

    def _ping_raw(self, sid: int) -> Raw:
        """(model number, ok, error byte, comm text): a read of the Model Number register (the SDKs' ping
        takes any packet from the id as its answer, and Feetech's raises on a short one)."""
        return self._read_raw(sid, self.REG["model"])

    def _read_raw(self, sid: int, reg: Enum) -> Raw:
        data, ok, err, comm = self._read_block_raw(sid, *reg.value)
        return (self._decode(reg, self._from_bus_bytes(data)) if ok else 0), ok, err, comm

    def _write_raw(self, sid: int, reg: Enum, value: int) -> Raw:
        addr, size = reg.value
        _, ok, err, comm = self._write_block_raw(sid, addr, self._to_bus_bytes(self._encode(reg, value), size))
        return 0, ok, err, comm

    def _sync_write_raw(self, reg: Enum, values: dict[int, int]) -> None:
        self._prep()
        addr, size = reg.value
        gsw = self._writers.get(reg)
        if gsw is None:
            gsw = self._writers[reg] = self.sdk.GroupSyncWrite(self._port, self._ph, addr, size)
        gsw.clearParam()
        for sid, v in values.items():
            gsw.addParam(sid, self._to_bus_bytes(self._encode(reg, v), size))
        comm = gsw.txPacket()
        self._port.is_using = False
        if comm != self.sdk.COMM_SUCCESS:
            raise OSError(f"sync write {reg.name} failed: {self._ph.getTxRxResult(comm)}")

    def _sync_read_raw(self, reg: Enum, ids: list[int]) -> dict[int, Raw]:
        """One SYNC READ, status packets matched to ids (the SDKs' group API drops each status error byte,
        and its ``readRx`` discards every reply after a lost one); one read per servo without sync read."""
        if not self._has_sync_read():
            return {i: self._read_raw(i, reg) for i in ids}
        self._prep()
        addr, size = reg.value
        k = self._begin(ids, size, addr, widen=True, ordered=True)
        addr, size = addr - k, size + k
        group = self.sdk.GroupSyncRead(self._port, self._ph, addr, size)
        for sid in ids:
            group.addParam(sid)
        comm = group.txPacket()
        if comm != self.sdk.COMM_SUCCESS:
            self._port.is_using = False
            return {sid: (0, False, 0, self._ph.getTxRxResult(comm)) for sid in ids}
        id_at = self.STATUS_LAYOUT[0]
        pkt_len = self.STATUS_LAYOUT[2] + size + self.STATUS_LAYOUT[3]
        got = collect_status_packets(
            ids,
            self._rx_packet,
            self._port.isPacketTimeout,
            id_at,
            length=pkt_len,
            on_stale=lambda pkt: self._discard_stale(pkt, f"a sync read of {reg.name}"),
        )
        self._port.is_using = False
        out: dict[int, Raw] = {}
        for sid in ids:
            pkt = got[sid]
            if pkt is None:
                self._mark_late([sid], size, addr)
                out[sid] = (0, False, 0, "no valid status packet (missing or corrupt)")
                continue
            _, err, params = self._split_status(pkt)
            out[sid] = (self._decode(reg, self._from_bus_bytes(params[k:])), True, err, "ok")
        return out

    def _load_is_percent(self, k: int) -> bool:
        """Whether joint ``k``'s load register holds 0.1 % of the maximum (current-sensing models hold mA)."""
        return True

    def _hardware_error(self, sid: int, err: int) -> str | None:
        """Text of the fault flagged by status error byte ``err``, or None when it is clean."""
        raise NotImplementedError

    def _voltage_limits_v(self, sid: int) -> tuple[float, float]:
        raise NotImplementedError

    def _check_position_mode(self, sid: int) -> None:
        """Raise unless servo ``sid`` is in a position-control mode that reads goals as robogest writes them (a
        servo in speed or PWM mode would take the speed cap as a speed to turn at)."""

    # --- mapping ---------------------------------------------------------------------------------
    def rad_to_ticks(self, q_rad: np.ndarray) -> np.ndarray:
        """``(J,)`` joint radians -> ``(J,)`` integer ticks (YAML mapping, then the model's resolution)."""
        q_servo = self._dir * np.asarray(q_rad, float) * self._gear + self._zero
        return np.rint(self._centre + q_servo * self._tpr).astype(np.int64)

    def ticks_to_rad(self, ticks: np.ndarray) -> np.ndarray:
        q_servo = (np.asarray(ticks, float) - self._centre) / self._tpr
        return (q_servo - self._zero) / (self._gear * self._dir)

    # --- transactions with retries ---------------------------------------------------------------
    def _who(self, sid: int) -> str:
        return f"servo id {sid} (joint {self._joint_of.get(sid, '?')})"

    def _port_error(self, e: BaseException, what: str) -> BackendError:
        self.port_lost = True
        return BackendError(f"serial port {self.port_name} lost while {what}: {e}; torque off attempted")

    def _call(self, sid: int, what: str, reg: Enum | None, fn: Callable[[], tuple[Any, bool, int, str]]) -> Any:
        """Run one transaction, retrying timeouts/corruption within the per-op and per-tick budgets."""
        attempts = self.retries + 1
        last = ""
        for attempt in range(1, attempts + 1):
            try:
                value, ok, err, comm = fn()
            except Exception as e:  # pyserial raises SerialException when the port goes away
                if _is_port_error(e):
                    raise self._port_error(e, f"{what} {reg.name if reg else ''} of {self._who(sid)}") from None
                raise
            if ok:
                hw = self._hardware_error(sid, err)
                if hw:
                    raise self._fault_error(sid, hw, reg, f"{attempt}/{attempts}")
                return value
            last = comm
            self.retry_count += 1
            if attempt < attempts:
                self._budget -= 1
                if self._budget < 0:
                    raise BusUnreliableError(
                        f"{self._who(sid)}: bus too unreliable, retry budget of {self.tick_retry_budget} per tick "
                        f"spent ({what} {reg.name if reg else ''}: {comm}); motion stopped"
                    )
                self.events.append(f"retry {what} {reg.name if reg else ''} {self._who(sid)}: {comm}")
        regname = reg.name if reg else "-"
        raise BusUnreliableError(
            f"{self._who(sid)}: no valid reply to {what} register {regname} after {attempts} attempts ({last})"
        )

    def _fault_error(self, sid: int, hw: str, reg: Enum | None, attempt: str) -> BackendError:
        """The error for a reply whose status byte flags hardware fault ``hw`` (:meth:`_hardware_error`)."""
        return BackendError(
            f"{self._who(sid)} reports {hw} (register {reg.name if reg else '-'}, attempt {attempt}); "
            "motion stopped, torque off"
        )

    def read_register(self, sid: int, reg: Enum) -> int:
        return self._call(sid, "reading", reg, lambda: self._read_raw(sid, reg))

    def write_register(self, sid: int, reg: Enum, value: int) -> None:
        self._call(sid, "writing", reg, lambda: self._write_raw(sid, reg, int(value)))

    def _sync_read_group(self, reg: Enum, ids: list[int]) -> dict[int, Raw]:
        try:
            return self._sync_read_raw(reg, ids)
        except Exception as e:
            if _is_port_error(e):
                raise self._port_error(e, f"sync reading {reg.name}") from None
            raise

    def _sync_read(self, reg: Enum, *, tolerate_missing: bool = False) -> np.ndarray:
        """Read ``reg`` of every servo; retry rounds re-read only the servos whose reply was missing/corrupt.

        Strict (``tolerate_missing=False``, used while connecting): a servo still unread after
        ``retries`` extra rounds raises. Tolerant (present positions during motion): re-reads are
        limited by the tick's retry budget; a servo still unread keeps its last known value, and is
        declared lost once it has gone unread for ``lost_after_s`` (or ``lost_after_ticks`` ticks).
        """
        ids = [int(i) for i in self.ids]
        index = {sid: k for k, sid in enumerate(ids)}
        out = self._last_ticks.copy() if tolerate_missing else np.zeros(len(ids), dtype=np.int64)
        attempts = dict.fromkeys(ids, 0)
        comm_of: dict[int, str] = {}
        missing: list[int] = []
        todo = ids
        rounds = 0
        while True:
            got = self._sync_read_group(reg, todo)
            now = time.monotonic()
            still = [sid for sid in missing if sid not in todo]  # over budget last round: not re-read
            for sid in todo:
                attempts[sid] += 1
                k = index[sid]
                value, ok, err, comm = got.get(sid, (0, False, 0, "no reply"))
                if not ok:
                    still.append(sid)
                    comm_of[sid] = comm
                    continue
                hw = self._hardware_error(sid, err)
                if hw and not self._noted_while_stopping(sid, f"reports {hw}"):
                    raise self._fault_error(sid, hw, reg, f"{attempts[sid]}/{self.retries + 1}")
                out[k] = value
                if tolerate_missing:
                    self._last_ok_s[k] = now
                    self._misses[k] = 0
                    self._miss_attempts[k] = 0
            missing = sorted(still, key=index.__getitem__)
            if not missing or rounds >= self.retries:
                break
            if tolerate_missing:
                if any(now - self._last_ok_s[index[sid]] >= self.lost_after_s for sid in missing):
                    break  # already unheard for too long: declare it lost now rather than wait another timeout
                todo = missing[: max(0, self._budget)]
                if not todo:
                    break
                self._budget -= len(todo)
            else:
                todo = missing
            rounds += 1
            self.retry_count += len(todo)
            for sid in todo:
                self.events.append(f"sync read {reg.name}: {self._who(sid)} {comm_of[sid]}; re-reading")
        if not missing:
            return out
        if not tolerate_missing:
            sid = missing[0]
            raise BackendError(
                f"{self._who(sid)}: no valid reply to reading register {reg.name} after {attempts[sid]} attempts "
                f"({comm_of[sid]})"
            )
        now = time.monotonic()
        for sid in missing:
            k = index[sid]
            self._misses[k] += 1
            self._miss_attempts[k] += attempts[sid]
            self.missed_reads += 1
            unheard = now - self._last_ok_s[k]
            # Two misses at least: on a starved machine one slow tick alone can outlast lost_after_s.
            lost = self._misses[k] >= max(2, self.lost_after_ticks) or (
                self._misses[k] >= 2 and unheard >= self.lost_after_s
            )
            if lost and not self._noted_while_stopping(sid, "lost (no valid reply)"):
                raise BackendError(
                    f"{self._who(sid)}: lost, no valid reply to reading register {reg.name} for {self._misses[k]} "
                    f"ticks ({unheard:.2f} s, {self._miss_attempts[k]} attempts; last: {comm_of[sid]}); "
                    "motion stopped, torque off"
                )
            if not lost:
                self.events.append(
                    f"missed {reg.name} of {self._who(sid)} ({comm_of[sid]}); holding its last value "
                    f"({self._misses[k]}/{self.lost_after_ticks} ticks)"
                )
        return out

    def _noted_while_stopping(self, sid: int, what: str) -> bool:
        """While gliding to rest at the end (:attr:`stopping`), a fault is noted once in :attr:`events` and the
        glide goes on with the servos that still answer (True); otherwise (False) the caller raises it."""
        if not self.stopping:
            return False
        key = f"{self._who(sid)} {what}"
        if key not in self._stop_faults:
            self._stop_faults.add(key)
            self.events.append(f"{key} during the glide to rest; the other servos go on to rest")
        return True

    def _sync_write(self, reg: Enum, ticks: np.ndarray) -> None:
        try:
            self._sync_write_raw(reg, {int(i): int(v) for i, v in zip(self.ids, ticks, strict=True)})
        except Exception as e:
            if _is_port_error(e):
                raise self._port_error(e, f"sync writing {reg.name}") from None
            raise

    # --- Backend API -----------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the port, ping every servo, check models, read limits and present positions."""
        if self.is_connected:
            return
        try:
            self._open()
        except RobogestError:
            raise
        except Exception as e:
            raise BackendError(f"cannot open serial port {self.port_name} at {self.baudrate} baud: {e}") from None
        self._shut_down = False
        try:
            missing, wrong = [], []
            for sid, model in zip(self.ids, self.models, strict=True):
                sid = int(sid)
                self._budget = self.tick_retry_budget  # each servo's check is its own group of transactions
                try:
                    found = self._call(sid, "pinging", None, lambda sid=sid: self._ping_raw(sid))
                except BackendError as e:
                    if self.port_lost:
                        raise
                    missing.append(f"{self._who(sid)}: {e}")
                    continue
                if found != model.number:
                    wrong.append(f"{self._who(sid)}: expected model {model.name} ({model.number}), found {found}")
            scan = f"robogest servo scan --port {self.port_name}"
            if len(missing) == len(self.ids):
                raise BackendError(
                    f"no servo answered on {self.port_name} at {self.baudrate} baud with {self.family} protocol "
                    f"{self.protocol:g} (expected ids {', '.join(str(int(i)) for i in self.ids)}): wrong baud rate, "
                    f"protocol or port, or no power? `{scan}` shows what answers"
                )
            if missing or wrong:
                raise BackendError(
                    f"servo check failed on {self.port_name} at {self.baudrate} baud: "
                    + "; ".join(missing + wrong)
                    + f"; `{scan}` shows what answers"
                )
            lo = self._sync_read(self.REG["min"])
            hi = self._sync_read(self.REG["max"])
            self._tick_lo, self._tick_hi = np.minimum(lo, hi), np.maximum(lo, hi)
            wheel = np.nonzero((lo == 0) & (hi == 0))[0]
            if wheel.size:  # both angle limits 0 is wheel (continuous turn) mode on AX/MX and SCS servos
                raise BackendError(
                    f"{self._who(int(self.ids[wheel[0]]))}: both position-limit registers are 0, which is wheel "
                    "(continuous rotation) mode: goals would set its speed, not its angle; set its limits "
                    "(`robogest servo doctor --fix`) before using it"
                )
            for sid in self.ids:
                self._budget = self.tick_retry_budget
                self._check_position_mode(int(sid))
            if self.check_limits:
                self._check_limits_fit()
            for sid in self.ids:
                self._budget = self.tick_retry_budget
                self._volt_limits[int(sid)] = self.voltage_range_v or self._voltage_limits_v(int(sid))
            self._write_profiles()
            self.is_connected = True
            self.governor.reset()
            self._budget = self.tick_retry_budget
            self._positions_known = False
            self._next_health = time.monotonic() + self.health_period_s / max(1, len(self.ids))
            self.read_positions()
            self._connected()
        except BaseException:
            self._safe_close()
            raise

    def speed_cap_units(self) -> np.ndarray:
        """Per servo ``(J,)``: the value for its speed-cap register, the joint's velocity limit times
        :data:`SPEED_CAP_MARGIN` at the servo horn (through the gear), in the model's units (at least 1: 0 means
        no cap)."""
        v = self.robot.v_max_rad_s * np.abs(self._gear) * SPEED_CAP_MARGIN  # (J,) rad/s at the horn
        unit = np.array([m.speed_unit_rad_s for m in self.models])
        top = np.array([m.speed_max_units for m in self.models])
        return np.clip(np.ceil(v / unit), 1, top).astype(np.int64)

    def accel_cap_units(self) -> np.ndarray:
        """Per servo ``(J,)``: the value for its acceleration register, the largest whole number of the model's units
        not above the joint's acceleration limit times :data:`ACCEL_CAP_MARGIN` at the servo horn (through the gear),
        at least 1 (0 means no limit) and at most the register's top; 0 for a model without the register."""
        a = self.robot.a_max_rad_s2 * np.abs(self._gear) * ACCEL_CAP_MARGIN  # (J,) rad/s² at the horn
        unit = np.array([m.accel_unit_rad_s2 for m in self.models])
        top = np.array([m.accel_max_units for m in self.models])
        has = unit > 0
        units = np.clip(np.floor(a / np.where(has, unit, 1.0) * (1 + 1e-12)), 1, np.maximum(top, 1))
        return np.where(has, units, 0).astype(np.int64)

    def profile_caps(self) -> list[tuple[Enum, np.ndarray]]:
        """The servos' own limits as ``(register, units (J,))``: the speed cap (profile velocity / moving speed /
        goal speed, :meth:`speed_cap_units`) and the acceleration limit (profile acceleration / goal acceleration /
        ACC, :meth:`accel_cap_units`; 0 where the model has no such register). What a connect writes, and what
        ``servo write --robot`` sends with a goal."""
        return [(self.REG["speed_cap"], self.speed_cap_units()), (self.REG["acceleration"], self.accel_cap_units())]

    def _write_profiles(self) -> None:
        """The servos' own speed and acceleration limits (:meth:`profile_caps`), each read back: RAM registers, so
        written at every connect, and a servo that does not keep what was written (a register its firmware lacks)
        is refused."""
        caps = self.profile_caps()
        for k, sid in enumerate(int(i) for i in self.ids):
            for reg, units in caps:
                if not units[k]:
                    continue  # this model has no such register
                self._budget = self.tick_retry_budget
                self.write_register(sid, reg, int(units[k]))
                held = self.read_register(sid, reg)
                if held != units[k]:
                    raise BackendError(
                        f"{self._who(sid)}: register {reg.name} reads back {held} after {units[k]} was written, so "
                        "the servo would not keep its own speed and acceleration limits; check its model and firmware "
                        "(`robogest servo scan`)"
                    )

    def _check_limits_fit(self) -> None:
        t_lo = self.rad_to_ticks(self.robot.q_min_rad)
        t_hi = self.rad_to_ticks(self.robot.q_max_rad)
        lo, hi = np.minimum(t_lo, t_hi), np.maximum(t_lo, t_hi)
        bad = np.nonzero((lo < self._tick_lo - 1) | (hi > self._tick_hi + 1))[0]
        if bad.size:
            k = int(bad[0])
            raise BackendError(
                f"{self._who(int(self.ids[k]))}: joint limits map to ticks [{lo[k]}, {hi[k]}] but the servo only "
                f"accepts [{self._tick_lo[k]}, {self._tick_hi[k]}]; fix zero_offset_rad/direction or the servo's "
                "position-limit registers"
            )

    def read_positions(self) -> np.ndarray:
        trouble = self.retry_count + self.missed_reads
        ticks = self._sync_read(self.REG["present"], tolerate_missing=self._positions_known)
        if not self._positions_known:  # the first read (while connecting) must see every servo
            self._last_ok_s[:] = time.monotonic()
            self._misses[:] = 0
            self._miss_attempts[:] = 0
            self._positions_known = True
        self._last_ticks = ticks
        self._maybe_check_torque(busy=self.retry_count + self.missed_reads > trouble)
        self._maybe_check_health()
        return self.ticks_to_rad(ticks)

    def _send_goal(self, q_rad: np.ndarray) -> None:
        self._budget = self.tick_retry_budget  # a new control tick starts here
        ticks = np.clip(self.rad_to_ticks(q_rad), self._tick_lo, self._tick_hi)
        self._sync_write(self.REG["goal"], ticks)
        self._goal_ticks = ticks

    def confirm_goal(self) -> None:
        """Read the goal registers back and re-send the last goal until every servo holds it (``retries`` extra
        rounds). A sync write is never acknowledged: before torque goes on, a servo that missed it would drive at
        full speed to whatever goal it held before (another session's pose)."""
        if self.last_goal_rad is None:
            raise BackendError("confirm_goal: no goal sent yet; write_goal() first")
        for attempt in range(1, self.retries + 2):
            self._budget = self.tick_retry_budget
            held = self._sync_read(self.REG["goal"])
            wrong = np.nonzero(held != self._goal_ticks)[0]
            if not wrong.size:
                return
            k = int(wrong[0])
            what = f"{self._who(int(self.ids[k]))} holds goal tick {held[k]}, not {self._goal_ticks[k]}"
            if attempt <= self.retries:
                self.events.append(f"{what}; goal sent again")
                self._sync_write(self.REG["goal"], self._goal_ticks)
        raise BackendError(f"{what} after {self.retries + 1} writes; torque not enabled")

    def set_torque(self, on: bool) -> None:
        """Torque on/off, one confirmed write per servo (a lost sync write must not leave torque on)."""
        if not on:
            self.torque_off_attempted = True
        self._budget = self.tick_retry_budget  # its own group of transactions, not part of a tick
        errors = []
        for sid in self.ids:
            try:
                self.write_register(int(sid), self.REG["torque"], int(on))
            except BackendError as e:
                if on or self.port_lost:
                    raise
                errors.append(str(e))  # keep turning the others off
        self.torque_enabled = on
        self._torque_reads, self._torque_read_s, self._torque_unread = 0, time.monotonic(), []
        self._torque_put_off_s = None
        if errors:
            raise BackendError("torque off failed: " + "; ".join(errors))

    def disconnect(self) -> None:
        self._safe_close()

    def _safe_close(self) -> None:
        self.is_connected = False
        with contextlib.suppress(Exception):
            self._close()

    def shutdown(self) -> None:
        """Glide to rest (if torque is on and the port answers; :func:`~robogest.backends.control.go_to_rest`),
        then torque off, then close. Idempotent."""
        from robogest.backends.control import deferred_signals

        if self._shut_down:
            return
        self._shut_down = True
        with deferred_signals():  # a signal now is raised after torque off on every servo, not between two
            self._shut_down_now()

    def _shut_down_now(self) -> None:
        problems: list[str] = []
        try:
            if self.is_connected and self.torque_enabled and not self.port_lost:
                from robogest.backends.control import go_to_rest

                problem = go_to_rest(self)
                if problem:
                    problems.append(problem)
        finally:
            try:
                if self.is_connected and not self.port_lost:
                    self.set_torque(False)
                elif self.is_connected:
                    self.torque_off_attempted = True
                    with contextlib.suppress(BackendError):  # best effort; the port is probably gone
                        self._sync_write(self.REG["torque"], np.zeros(len(self.ids), dtype=np.int64))
            except BackendError as e:
                problems.append(str(e))
            finally:
                self.disconnect()
        self.events.extend(f"shutdown: {p}" for p in problems)

    # --- torque read-back --------------------------------------------------------------------------
    def _maybe_check_torque(self, busy: bool = False) -> None:
        """Read back Torque Enable of the servos due this tick (see ``torque_check_s``); raise when one is off.

        A servo loses torque without a word on the bus when its supply browns out (it reboots), when another
        program writes its register, or when its firmware's shutdown trips between two reads; goals written to it
        then move nothing, and playback would go on as if they did. Skipped while torque is meant to be off and on
        the final glide to rest (nothing is left to stop). ``busy``: this tick's position read had to re-read or
        missed a servo; the read-back is then put off to a later tick, for up to ``torque_check_s``, so that a
        struggling bus's ticks stay short and the next position read comes soon (two missed in a row over
        ``lost_after_s`` declare a servo lost)."""
        if not self.torque_enabled or self.stopping or self.torque_check_s <= 0 or not len(self.ids):
            return
        ids = [int(i) for i in self.ids]
        n = self.torque_check_ticks
        now = time.monotonic()
        self._torque_reads += 1
        due = set(self._torque_unread)
        if self._has_sync_read():  # one transaction for all every n ticks, or torque_check_s when ticks run late
            if self._torque_reads >= n or now - self._torque_read_s >= self.torque_check_s:
                due.update(ids)
                self._torque_reads, self._torque_read_s = 0, now
        else:  # one transaction per servo: each once per n ticks, spread evenly, so that no tick carries them all
            tick = self._torque_reads % n
            due.update(sid for j, sid in enumerate(ids) if j * n // len(ids) == tick)
        if not due:
            return
        asked = sorted(due, key=ids.index)  # bus order: servos answer a sync read in the order asked
        if busy:
            self._torque_put_off_s = self._torque_put_off_s or now
            if now - self._torque_put_off_s < self.torque_check_s:
                self._torque_unread = asked
                return
        self._torque_put_off_s = None
        reg = self.REG["torque"]
        got = self._sync_read_group(reg, asked)
        self._torque_unread = []
        limp = []
        for sid in asked:
            value, ok, err, _ = got.get(sid, (0, False, 0, "no reply"))
            if not ok:
                self._torque_unread.append(sid)  # position reads catch a servo that stopped answering
                continue
            hw = self._hardware_error(sid, err)
            if hw:
                raise self._fault_error(sid, hw, reg, "1/1")
            if value == 0:
                limp.append(sid)
        if limp:
            self.limp_ids = limp
            who = "; ".join(self._who(sid) for sid in limp[:4])
            who += f"; and {len(limp) - 4} more" if len(limp) > 4 else ""
            raise BackendError(
                f"{who}: torque found off while robogest held it on (a brownout or reset, or another program on the "
                "bus switched it off); motion stopped, the servos still holding torque glided to rest, torque off; "
                "check the servos' power supply and that no other program uses the port"
            )

    # --- health ----------------------------------------------------------------------------------
    def _maybe_check_health(self) -> None:
        """One servo's health, round-robin, at a low rate. A reading that cannot get through a noisy bus is
        skipped and tried again next round (position reads already catch a servo that stopped answering);
        only a servo whose health stays unreadable for ``health_lost_after_s`` stops the motion. Hardware
        error bits and readings past the thresholds always stop it."""
        now = time.monotonic()
        if self.stopping or now < self._next_health or not len(self.ids):
            return  # on the way to rest at the end: a reading past a limit would only cut that short
        self._next_health = now + self.health_period_s / len(self.ids)
        sid = int(self.ids[self._health_idx % len(self.ids)])
        self._health_idx += 1
        self._budget = self.tick_retry_budget  # its own group of transactions, not the position read's
        try:
            self.check_health(sid)
        except BusUnreliableError as e:
            first = self._health_unread_since.setdefault(sid, now)
            if self.port_lost or now - first > self.health_lost_after_s:
                raise
            self.events.append(f"health reading skipped ({e})")
        else:
            self._health_unread_since.pop(sid, None)

    def read_health(self, sid: int) -> dict[str, float]:
        """Temperature (°C), voltage (V) and load (% of max, signed) of one servo, in one read of the
        block that holds the three registers (its length matches no other read, so a late reply to
        another request cannot pass for it)."""
        regs = [self.REG["temperature"], self.REG["voltage"], self.REG["load"]]
        lo = min(r.value[0] for r in regs)
        n = max(r.value[0] + r.value[1] for r in regs) - lo
        block = self._call(sid, "reading", None, lambda: self._read_block_raw(sid, lo, n))

        def value(reg: Enum) -> int:
            a, size = reg.value
            return self._decode(reg, self._from_bus_bytes(block[a - lo : a - lo + size]))

        return {
            "temperature_c": float(value(regs[0])),
            "voltage_v": value(regs[1]) / 10.0,
            "load_pct": value(regs[2]) / 10.0,
        }

    def shape_target(self, q_target_rad: np.ndarray, rest_q_rad: np.ndarray) -> np.ndarray:
        return self.governor.shape(q_target_rad, rest_q_rad)

    def governor_state(self) -> dict[str, float]:
        return self.governor.state()

    def check_health(self, sid: int) -> dict[str, float]:
        """Read one servo's health, feed the governor, and stop past the hard limits."""
        h = self.read_health(sid)
        before = self.governor.target_factor()
        k = int(np.nonzero(self.ids == sid)[0][0]) if sid in self.ids else -1
        self.governor.observe(sid, h["temperature_c"], h["load_pct"] if self._load_is_percent(k) else None)
        after = self.governor.target_factor()
        if self.governor.enabled and after < 1.0 <= before:
            self.events.append(
                f"health governor: {self._who(sid)} at {h['temperature_c']:.0f} °C, load {abs(h['load_pct']):.0f} % "
                f"(warning from {self.governor.config.warn_temperature_c:.0f} °C); gestures scaled down, rests longer"
            )
        lo, hi = self._volt_limits.get(sid, (0.0, float("inf")))
        if h["temperature_c"] > self.max_temperature_c:
            why = f"temperature {h['temperature_c']:.0f} °C above the {self.max_temperature_c:.0f} °C limit"
        elif not lo <= h["voltage_v"] <= hi:
            why = f"supply voltage {h['voltage_v']:.1f} V outside [{lo:.1f}, {hi:.1f}] V"
        elif self.max_load_pct is not None and abs(h["load_pct"]) > self.max_load_pct:
            why = f"load {h['load_pct']:.0f} % above the {self.max_load_pct:.0f} % limit"
        else:
            return h
        raise BackendError(f"{self._who(sid)}: {why}; motion stopped, torque off")


class BusUnreliableError(BackendError):
    """Replies kept getting lost or corrupted: the retry budget or the attempts ran out."""


def sign_magnitude_encode(value: int, bit: int) -> int:
    """``value`` as a register that stores the sign in bit ``bit`` and the magnitude below it."""
    return (-value & ((1 << bit) - 1)) | (1 << bit) if value < 0 else value


def sign_magnitude_decode(raw: int, bit: int | None) -> int:
    """Servo registers that store the sign in bit ``bit`` (Feetech positions/speeds, Dynamixel P1 load)."""
    if bit is not None and raw & (1 << bit):
        return -(raw & ((1 << bit) - 1))
    return raw


def collect_status_packets(
    ids: list[int],
    receive: Callable[[], tuple[list[int], bool]],
    timed_out: Callable[[], bool],
    id_at: int,
    length: int | None = None,
    on_stale: Callable[[list[int]], None] | None = None,
) -> dict[int, list[int] | None]:
    """Match the status packets of one sync read to servo ids: ``{id: packet, or None when missing/corrupt}``.

    ``receive()`` returns the next packet and whether its checksum was valid; ``timed_out()`` says
    whether the read's deadline has passed. The SDKs' ``readRx(id)`` skips packets of other ids
    while looking for its own, so one lost reply used to swallow every reply after it; here each
    packet goes to the id it names. Servos answer in the order asked, so a reply from a later id
    means the earlier missing ones are not coming, and no time is spent waiting for them. With
    ``length``, a valid packet of another length is a late reply to another request and is skipped.
    Each valid packet skipped is handed to ``on_stale``.
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
        if sid in pending:
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


def open_port_exclusive(sdk: Any, port_name: str, baudrate: int) -> Any:
    """The vendor SDK's ``PortHandler`` on ``port_name``, opened with an exclusive lock.

    The lock (``flock``, taken by pyserial before it touches the port's settings) keeps a second
    robogest process or tool from opening the port mid-motion; ``TIOCEXCL`` also keeps out other
    programs that open it without root rights. Both SDKs' handlers have the same shape.

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


def close_port(handler: Any) -> None:
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


def _is_port_error(e: BaseException) -> bool:
    """True for errors meaning the port itself is gone (unplugged adapter, closed pty)."""
    import termios

    from serial import SerialException

    return isinstance(e, SerialException | OSError | termios.error)


def describe_bits(err: int, table: dict[int, str]) -> str:
    names = [name for bit, name in table.items() if err & bit]
    return " + ".join(names) + f" error (0x{err:02X})" if names else f"error 0x{err:02X}"
