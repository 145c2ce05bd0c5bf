"""The servo bus base: the rad <-> tick mapping and every transaction with its retries, budgets and error texts.

A family (``dynamixel/``, ``feetech/``) subclasses :class:`~robogest.backends.servos.bus.ServoBackend` and supplies
its register roles, its model lookup and its quirks (hardware-error bits, position-mode check, voltage limits); the
wire itself (SDK, byte order, late replies) is the shared :class:`~robogest.backends.servos.transport.Transport`.
Ticks never leave :mod:`robogest.backends.servos`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from enum import Enum
from typing import Any, ClassVar, TypeVar

import numpy as np

from robogest.backends.base import Backend
from robogest.backends.governor import Governor, GovernorConfig
from robogest.backends.servos.protocol import ServoModel, ServoProtocol
from robogest.backends.servos.transport import Transport, is_port_error
from robogest.backends.servos.wire import Wire, wire_of
from robogest.errors import BackendError, ConfigError, InputError
from robogest.robot.config import RobotConfig

#: Result of one transaction: (value, ok, status error byte, comm description).
Raw = tuple[int, bool, int, str]
T = TypeVar("T")


class BusUnreliableError(BackendError):
    """Replies kept getting lost or corrupted: the retry budget or the attempts ran out."""


class ServoBusIO(Backend):
    """The transaction half of :class:`~robogest.backends.servos.bus.ServoBackend` (its parameters are documented
    there): configuration, the rad <-> tick mapping, and reads/writes with their retries and budgets."""

    family: ClassVar[str] = ""

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
        self.protocol = ServoProtocol.of_bus(bus.family, bus.protocol)
        self.wire: Wire = wire_of(self.protocol)
        #: role -> register (goal, present, torque, temperature, voltage, load, min, max, speed_cap, acceleration).
        self.REG: dict[str, Enum] = self._roles()
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
        self._init_mapping(robot)
        self._init_state()

    def _init_mapping(self, robot: RobotConfig) -> None:
        """Per joint ``(J,)``: servo id, model, direction, gear, zero offset and the model's resolution."""
        assert robot.bus is not None
        servos = [robot.bus.servos[n] for n in robot.joint_names]
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

    def _init_state(self) -> None:
        """What a session learns while it runs: counters, retry budget, the last readings and goals."""
        self.transport: Transport | None = None  # once connected
        self._stale_before = (0, 0)  # stale replies and bytes of the connections before this one
        self.is_connected = False
        self.port_lost = False
        self.torque_enabled = False
        self.torque_off_attempted = False
        self.retry_count = 0  #: re-sent transactions and re-read servos
        self.missed_reads = 0  #: position reads that got no valid reply within the tick (last value kept)
        self.events: list[str] = []  #: retries and health readings worth reporting
        self._budget = self.tick_retry_budget
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
        n = len(self.ids)
        self._positions_known = False
        self._last_ticks = np.zeros(n, dtype=np.int64)  # last valid present position per servo
        self._goal_ticks = np.zeros(n, dtype=np.int64)  # the last goal written, ticks
        self._last_ok_s = np.zeros(n)  # time.monotonic() of that reading
        self._misses = np.zeros(n, dtype=np.int64)  # consecutive ticks without a valid reading
        self._miss_attempts = np.zeros(n, dtype=np.int64)  # attempts since the last valid reading

    @property
    def stale_replies(self) -> int:
        """Status packets discarded as late answers to earlier requests (every connection of this backend)."""
        return self._stale_before[0] + (self.transport.stale_replies if self.transport is not None else 0)

    @property
    def stale_bytes(self) -> int:
        """Bytes of late replies dropped before a request (every connection of this backend)."""
        return self._stale_before[1] + (self.transport.stale_bytes if self.transport is not None else 0)

    @property
    def lost_after_ticks(self) -> int:
        return max(1, math.ceil(self.lost_after_s * self.control_rate_hz - 1e-9))

    @property
    def torque_check_ticks(self) -> int:
        """Position reads (control ticks) between two read-backs of a servo's torque: ``torque_check_s`` at the
        control rate, at least 1."""
        return max(1, math.floor(self.torque_check_s * self.control_rate_hz + 1e-9))

    # --- family hooks ----------------------------------------------------------------------------
    def _roles(self) -> dict[str, Enum]:
        """This bus's register for each role (see :attr:`REG`): :data:`~.wire.ROLE_NAMES` in the protocol's table;
        a family whose table names them otherwise overrides this."""
        return self.wire.roles()

    @classmethod
    def lookup_model(cls, name: str, protocol: ServoProtocol | float) -> ServoModel:
        """Facts of the servo model called ``name`` on a bus of this ``protocol`` (a member, or the YAML's
        ``bus.protocol`` number); ConfigError if unknown there."""
        raise NotImplementedError

    @classmethod
    def _protocol_of(cls, protocol: ServoProtocol | float) -> ServoProtocol:
        return protocol if isinstance(protocol, ServoProtocol) else ServoProtocol.of_bus(cls.family, protocol)

    def _lookup_model(self, name: str, sid: int) -> ServoModel:
        try:
            return self.lookup_model(name, self.protocol)
        except ConfigError as e:
            raise ConfigError(f"servo id {sid}: {e}") from None

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

    # --- the port --------------------------------------------------------------------------------
    def _open(self) -> None:
        self._stale_before = (self.stale_replies, self.stale_bytes)
        self.transport = None
        self.transport = Transport(
            self.port_name, self.protocol, self.baudrate, late_reply_window_s=self.late_reply_window_s,
            who=self._who, events=self.events,
        )  # fmt: skip

    def _close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    @property
    def _link(self) -> Transport:
        """The open transport; BackendError before connect."""
        if self.transport is None:
            raise BackendError(f"{self.family} backend on {self.port_name}: not connected; call connect() first")
        return self.transport

    # --- raw transactions (decoded values) -------------------------------------------------------
    def _read_block_raw(self, sid: int, addr: int, size: int) -> tuple[list[int], bool, int, str]:
        return self._link.read_block(sid, addr, size)

    def _ping_raw(self, sid: int) -> Raw:
        """(model number, ok, error byte, comm text): a read of the Model Number register (the SDKs' ping takes any
        packet from the id as its answer, and Feetech's raises on a short one)."""
        return self._read_raw(sid, self.REG["model"])

    def _read_raw(self, sid: int, reg: Enum) -> Raw:
        data, ok, err, comm = self._link.read_block(sid, *reg.value)
        return (self.wire.decode(reg, self.wire.from_bytes(data)) if ok else 0), ok, err, comm

    def _write_raw(self, sid: int, reg: Enum, value: int) -> Raw:
        addr, size = reg.value
        data = self.wire.to_bytes(self.wire.encode(reg, value), size)
        _, ok, err, comm = self._link.write_block(sid, addr, data)
        return 0, ok, err, comm

    def _sync_read_raw(self, reg: Enum, ids: list[int]) -> dict[int, Raw]:
        """One SYNC READ (:meth:`Transport.sync_read`), values decoded; one read per servo without sync read."""
        if not self.protocol.has_sync_read:
            return {i: self._read_raw(i, reg) for i in ids}
        out: dict[int, Raw] = {}
        for sid, (params, err, comm) in self._link.sync_read(reg, ids).items():
            ok = params is not None
            value = self.wire.decode(reg, self.wire.from_bytes(params)) if params is not None else 0
            out[sid] = (value, ok, err, comm)
        return out

    # --- mapping ---------------------------------------------------------------------------------
    def rad_to_ticks(self, q_rad: np.ndarray) -> np.ndarray:
        """``(J,)`` joint radians -> ``(J,)`` integer ticks (YAML mapping, then the model's resolution)."""
        q_servo = self._dir * np.asarray(q_rad, float) * self._gear + self._zero
        ticks: np.ndarray = np.rint(self._centre + q_servo * self._tpr).astype(np.int64)
        return ticks

    def ticks_to_rad(self, ticks: np.ndarray) -> np.ndarray:
        """``(J,)`` integer ticks -> ``(J,)`` joint radians."""
        q_servo = (np.asarray(ticks, float) - self._centre) / self._tpr
        q_rad: np.ndarray = (q_servo - self._zero) / (self._gear * self._dir)
        return q_rad

    # --- transactions with retries ---------------------------------------------------------------
    def _who(self, sid: int) -> str:
        return f"servo id {sid} (joint {self._joint_of.get(sid, '?')})"

    def _port_error(self, e: BaseException, what: str) -> BackendError:
        self.port_lost = True
        return BackendError(f"serial port {self.port_name} lost while {what}: {e}; torque off attempted")

    def _call(self, sid: int, what: str, reg: Enum | None, fn: Callable[[], tuple[T, bool, int, str]]) -> T:
        """Run one transaction, retrying timeouts/corruption within the per-op and per-tick budgets."""
        attempts = self.retries + 1
        last = ""
        regname = reg.name if reg else ""
        for attempt in range(1, attempts + 1):
            try:
                value, ok, err, comm = fn()
            except Exception as e:  # pyserial raises SerialException when the port goes away
                if is_port_error(e):
                    raise self._port_error(e, f"{what} {regname} of {self._who(sid)}") from None
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
                        f"spent ({what} {regname}: {comm}); motion stopped"
                    )
                self.events.append(f"retry {what} {regname} {self._who(sid)}: {comm}")
        raise BusUnreliableError(
            f"{self._who(sid)}: no valid reply to {what} register {regname or '-'} after {attempts} attempts ({last})"
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
            if is_port_error(e):
                raise self._port_error(e, f"sync reading {reg.name}") from None
            raise

    def _sync_read(self, reg: Enum, *, tolerate_missing: bool = False) -> np.ndarray:
        """Read ``reg`` of every servo ``(J,)``; retry rounds re-read only the servos whose reply was missing/corrupt.

        Strict (``tolerate_missing=False``, used while connecting): a servo still unread after ``retries`` extra
        rounds raises. Tolerant (present positions during motion): re-reads are limited by the tick's retry budget; a
        servo still unread keeps its last known value, and is declared lost once it has gone unread for
        ``lost_after_s`` (or ``lost_after_ticks`` ticks).
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
                value, ok, err, comm = got.get(sid, (0, False, 0, "no reply"))
                if not ok:
                    still.append(sid)
                    comm_of[sid] = comm
                    continue
                self._take_reading(reg, sid, index[sid], value, err, f"{attempts[sid]}/{self.retries + 1}", out,
                                   now if tolerate_missing else None)  # fmt: skip
            missing = sorted(still, key=index.__getitem__)
            if not missing or rounds >= self.retries:
                break
            todo = self._reread(missing, index, now) if tolerate_missing else missing
            if not todo:
                break
            rounds += 1
            self.retry_count += len(todo)
            for sid in todo:
                self.events.append(f"sync read {reg.name}: {self._who(sid)} {comm_of[sid]}; re-reading")
        if missing and not tolerate_missing:
            sid = missing[0]
            raise BackendError(
                f"{self._who(sid)}: no valid reply to reading register {reg.name} after {attempts[sid]} attempts "
                f"({comm_of[sid]})"
            )
        for sid in missing:
            self._note_miss(reg, sid, index[sid], attempts[sid], comm_of[sid])
        return out

    def _take_reading(
        self, reg: Enum, sid: int, k: int, value: int, err: int, attempt: str, out: np.ndarray, now: float | None
    ) -> None:
        """Servo ``sid``'s valid reply (joint ``k``) into ``out``; a flagged hardware fault raises (noted instead
        on the glide to rest). ``now``: a tolerant read, which also resets the servo's miss count."""
        hw = self._hardware_error(sid, err)
        if hw and not self._noted_while_stopping(sid, f"reports {hw}"):
            raise self._fault_error(sid, hw, reg, attempt)
        out[k] = value
        if now is not None:
            self._last_ok_s[k] = now
            self._misses[k] = 0
            self._miss_attempts[k] = 0

    def _reread(self, missing: list[int], index: dict[int, int], now: float) -> list[int]:
        """Which of the servos ``missing`` a tolerant read asks again: none once one of them has been unheard for
        ``lost_after_s`` (it is declared lost now rather than after another timeout), else as many as the tick's
        retry budget allows."""
        if any(now - self._last_ok_s[index[sid]] >= self.lost_after_s for sid in missing):
            return []
        todo = missing[: max(0, self._budget)]
        self._budget -= len(todo)
        return todo

    def _note_miss(self, reg: Enum, sid: int, k: int, attempts: int, comm: str) -> None:
        """Servo ``sid`` (joint ``k``) stayed unread this tick: its last value is kept, or, after two misses in a row
        over ``lost_after_s`` (or ``lost_after_ticks`` ticks), it is declared lost."""
        now = time.monotonic()
        self._misses[k] += 1
        self._miss_attempts[k] += attempts
        self.missed_reads += 1
        unheard = now - self._last_ok_s[k]
        # Two misses at least: on a starved machine one slow tick alone can outlast lost_after_s.
        misses = int(self._misses[k])
        lost = misses >= max(2, self.lost_after_ticks) or (misses >= 2 and unheard >= self.lost_after_s)
        if lost and not self._noted_while_stopping(sid, "lost (no valid reply)"):
            raise BackendError(
                f"{self._who(sid)}: lost, no valid reply to reading register {reg.name} for {self._misses[k]} "
                f"ticks ({unheard:.2f} s, {self._miss_attempts[k]} attempts; last: {comm}); motion stopped, torque off"
            )
        if not lost:
            self.events.append(
                f"missed {reg.name} of {self._who(sid)} ({comm}); holding its last value "
                f"({self._misses[k]}/{self.lost_after_ticks} ticks)"
            )

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

    def _sync_write_raw(self, reg: Enum, values: dict[int, int]) -> None:
        """One SYNC WRITE of signed ``values`` (servo id -> value) to ``reg``; OSError when it could not be sent."""
        self._link.sync_write(reg, {sid: self.wire.encode(reg, v) for sid, v in values.items()})

    def _sync_write(self, reg: Enum, ticks: np.ndarray) -> None:
        """Write ``ticks`` ``(J,)`` (signed register values) to ``reg`` of every servo in one SYNC WRITE."""
        try:
            self._sync_write_raw(reg, {int(i): int(v) for i, v in zip(self.ids, ticks, strict=True)})
        except Exception as e:
            if is_port_error(e):
                raise self._port_error(e, f"sync writing {reg.name}") from None
            raise
