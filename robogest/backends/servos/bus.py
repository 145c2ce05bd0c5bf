"""What every serial-servo backend shares above the transactions: connect and its checks, the servos' own speed and
acceleration limits, goals and their read-back, torque on/off and its read-back, health checks, safe shutdown.

A family package subclasses :class:`ServoBackend` (:mod:`~robogest.backends.servos.dynamixel`,
:mod:`~robogest.backends.servos.feetech`); the transactions, retries and the rad <-> tick mapping are in
:class:`~robogest.backends.servos.bus_io.ServoBusIO`.
"""

from __future__ import annotations

import contextlib
import time
from enum import Enum
from functools import partial
from typing import Any

import numpy as np

from robogest.backends.servos.bus_io import BusUnreliableError, ServoBusIO
from robogest.errors import BackendError, ConfigError, RobogestError
from robogest.robot.config import RobotConfig

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


class ServoBackend(ServoBusIO):
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
            self._check_servos_answer()
            self._read_position_limits()
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

    def _check_servos_answer(self) -> None:
        """Ping every servo (a read of its Model Number); BackendError naming each missing servo and wrong model."""
        missing, wrong = [], []
        for sid, model in zip((int(i) for i in self.ids), self.models, strict=True):
            self._budget = self.tick_retry_budget  # each servo's check is its own group of transactions
            try:
                found = self._call(sid, "pinging", None, partial(self._ping_raw, sid))
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
                f"{self.protocol.number:g} (expected ids {', '.join(str(int(i)) for i in self.ids)}): wrong baud "
                f"rate, protocol or port, or no power? `{scan}` shows what answers"
            )
        if missing or wrong:
            raise BackendError(
                f"servo check failed on {self.port_name} at {self.baudrate} baud: "
                + "; ".join(missing + wrong)
                + f"; `{scan}` shows what answers"
            )

    def _read_position_limits(self) -> None:
        """The servos' position-limit registers ``(J,)`` ticks; BackendError for a servo in wheel mode."""
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

    def speed_cap_units(self) -> np.ndarray:
        """Per servo ``(J,)``: the value for its speed-cap register, the joint's velocity limit times
        :data:`SPEED_CAP_MARGIN` at the servo horn (through the gear), in the model's units (at least 1: 0 means
        no cap)."""
        v = self.robot.v_max_rad_s * np.abs(self._gear) * SPEED_CAP_MARGIN  # (J,) rad/s at the horn
        unit = np.array([m.speed_unit_rad_s for m in self.models])
        top = np.array([m.speed_max_units for m in self.models])
        units: np.ndarray = np.clip(np.ceil(v / unit), 1, top).astype(np.int64)
        return units

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
        """Glide to rest (if torque is on and the port answers; :func:`~robogest.backends.rest.go_to_rest`),
        then torque off, then close. Idempotent."""
        from robogest.backends.signals import deferred_signals

        if self._shut_down:
            return
        self._shut_down = True
        with deferred_signals():  # a signal now is raised after torque off on every servo, not between two
            self._shut_down_now()

    def _shut_down_now(self) -> None:
        problems: list[str] = []
        try:
            if self.is_connected and self.torque_enabled and not self.port_lost:
                from robogest.backends.rest import go_to_rest

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
        if self.protocol.has_sync_read:  # one transaction for all every n ticks, or torque_check_s when ticks run late
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
            return self.wire.decode(reg, self.wire.from_bytes(block[a - lo : a - lo + size]))

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


def servo_backend(robot: RobotConfig, **options: Any) -> ServoBackend:
    """The servo backend of ``robot``'s bus family, not connected (``options`` as for :class:`ServoBackend`);
    ConfigError without a bus section or when the family's backend is no servo bus."""
    from robogest.backends.base import get_backend_factory

    if robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section; add one (docs/servos.md)")
    backend = get_backend_factory(robot.bus.family)(robot, **options)
    if not isinstance(backend, ServoBackend):
        raise ConfigError(f"robot {robot.name!r}: backend {robot.bus.family!r} is not a serial servo bus")
    return backend
