"""One emulated servo: a byte-addressed control table plus a small motor model.

Memory is the source of truth (a write changes bytes, a read returns bytes), the motor model turns
Goal Position into Present Position each time the bus advances the clock: a trapezoidal profile
(profile velocity / acceleration registers, 0 = model maximum) followed by a first-order lag that
stands in for the position loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from robogest.virtualbus.tables import ModelSpec, Reg

#: Status-error meaning, independent of protocol; the bus maps these onto each protocol's error byte.
OK, ERR_ACCESS, ERR_RANGE, ERR_LENGTH = 0, 1, 2, 3

#: Hardware fault names (fault grammar) -> Dynamixel P2 Hardware Error Status bits.
HW_BITS_P2 = {"voltage": 0x01, "overheating": 0x04, "encoder": 0x08, "shock": 0x10, "overload": 0x20}
#: Same faults as Dynamixel P1 / Feetech status-error bits.
HW_BITS_P1 = {"voltage": 0x01, "overheating": 0x04, "encoder": 0x02, "shock": 0x08, "overload": 0x20}

_LAG_TAU_S = 0.015  # position-loop time constant
_PROFILE_PERIOD_S = 0.001  # the firmware updates its profile at 1 kHz


@dataclass(frozen=True)
class ThermalModel:
    """First-order winding temperature: it settles at ``ambient_c + rise_c_at_full_load * |load|`` (load as
    a fraction of the maximum, 0 with torque off) with time constant ``tau_s``. ``time_scale`` > 1 runs the
    thermal clock faster than the wall clock, so a test can heat a servo for minutes in seconds."""

    ambient_c: float = 30.0
    rise_c_at_full_load: float = 25.0
    tau_s: float = 120.0
    time_scale: float = 1.0


@dataclass
class _Motion:
    cmd: float  # profile generator output, ticks
    cmd_vel: float = 0.0  # ticks/s
    pos: float = 0.0  # present position (ticks, float)
    vel: float = 0.0
    temp_c: float = 30.0


class SimServo:
    """Control table + motor model of one servo. Not thread-safe: the bus thread owns it."""

    def __init__(
        self, spec: ModelSpec, servo_id: int, baud_value: int | None = None, thermal: ThermalModel | None = None
    ) -> None:
        self.spec = spec
        self.thermal = thermal or ThermalModel()
        self.mem = bytearray(spec.table_size)
        for r in spec.regs:
            self._store(r, r.default)
        self._store(spec.reg("id"), servo_id)
        if baud_value is not None:
            self._store(spec.reg("baud"), baud_value)
        start = float(spec.centre_tick)
        self.motion = _Motion(cmd=start, pos=start, temp_c=self.thermal.ambient_c)
        self._store(spec.reg("goal"), spec.centre_tick)
        self.flash = bytes(self.mem[: spec.eeprom_end])  #: EEPROM as it will be after a power cycle
        self.hw_faults: set[str] = set()  #: injected hardware faults, names from HW_BITS_P2
        self.vanished = False
        self.registered: tuple[int, bytes] | None = None  #: pending REG_WRITE (address, data)

    # --- raw value codecs ------------------------------------------------------------------------
    def _encode(self, r: Reg, value: int) -> bytes:
        if r.sign_bit is not None:
            mag = min(abs(int(value)), (1 << r.sign_bit) - 1)
            raw = mag | ((1 << r.sign_bit) if value < 0 else 0)
        else:
            raw = int(value) & ((1 << (8 * r.size)) - 1)
        return raw.to_bytes(r.size, "big" if self.spec.big_endian else "little")

    def _decode(self, r: Reg, data: bytes | bytearray) -> int:
        raw = int.from_bytes(data, "big" if self.spec.big_endian else "little")
        if r.sign_bit is not None:
            mag = raw & ((1 << r.sign_bit) - 1)
            return -mag if raw & (1 << r.sign_bit) else mag
        if r.signed and raw & (1 << (8 * r.size - 1)):
            return raw - (1 << (8 * r.size))
        return raw

    def _store(self, r: Reg, value: int) -> None:
        self.mem[r.addr : r.addr + r.size] = self._encode(r, value)

    def get(self, role: str) -> int:
        r = self.spec.reg(role)
        return self._decode(r, self.mem[r.addr : r.addr + r.size])

    def has(self, role: str) -> bool:
        return self.spec.roles.get(role, role) in self.spec.by_name

    @property
    def id(self) -> int:
        return self.get("id")

    @property
    def baudrate(self) -> int:
        return self.spec.baud_table.get(self.get("baud"), 0)

    @property
    def torque_on(self) -> bool:
        return self.get("torque") != 0

    # --- protocol-facing access ------------------------------------------------------------------
    def read(self, addr: int, length: int) -> tuple[int, bytes]:
        """Bytes ``[addr, addr+length)``; reading past the table is a length error (real servos refuse)."""
        if addr < 0 or length < 0 or addr + length > len(self.mem):
            return ERR_LENGTH, b""
        return OK, bytes(self.mem[addr : addr + length])

    def check_write(self, addr: int, data: bytes) -> int:
        """Validate a write without applying it: whole registers only, writable, unlocked, in range."""
        end = addr + len(data)
        if addr < 0 or end > len(self.mem) or not data:
            return ERR_LENGTH
        a = addr
        while a < end:
            r = self.spec.by_addr.get(a)
            if r is None:
                return ERR_ACCESS  # gap (reserved area) or middle of a register
            if a + r.size > end:
                return ERR_LENGTH
            if not r.writable:
                return ERR_ACCESS
            if self._locked(r.addr):
                return ERR_ACCESS
            value = self._decode(r, data[a - addr : a - addr + r.size])
            if (r.lo is not None and value < r.lo) or (r.hi is not None and value > r.hi):
                return ERR_RANGE
            if r.allowed is not None and value not in r.allowed:
                return ERR_RANGE
            x_series = self.spec.family == "dynamixel" and self.spec.eeprom_locked_by_torque
            if x_series and r.name == self.spec.roles["goal"] and not self.get("min") <= value <= self.get("max"):
                return ERR_RANGE  # X-series position mode refuses goals past the limits
            a += r.size
        return OK

    def _locked(self, addr: int) -> bool:
        """Whether the write protection of this model refuses a write at ``addr`` now."""
        if self.spec.family == "feetech":
            return False  # Lock only decides whether EEPROM writes are saved (see write())
        if self.spec.eeprom_locked_by_torque:
            return addr < self.spec.eeprom_end and self.torque_on
        return self.has("lock") and self.get("lock") != 0 and not 24 <= addr <= 35  # AX/MX: until power-off

    @property
    def return_delay_s(self) -> float:
        """Time between the end of an instruction and the start of this servo's status packet."""
        return self.get("Return_Delay_Time") * self.spec.return_delay_unit_s

    def write(self, addr: int, data: bytes) -> int:
        err = self.check_write(addr, data)
        if err:
            return err
        goal = self.spec.reg("goal")
        self.mem[addr : addr + len(data)] = data
        eeprom = self.spec.eeprom_end
        if addr < eeprom and not (self.spec.family == "feetech" and self.get("lock") != 0):
            self.flash = bytes(self.mem[:eeprom])  # Feetech with Lock = 1: applied now, lost at power-off
        if addr <= goal.addr < addr + len(data):
            lo, hi = self.get("min"), self.get("max")
            if not lo <= self.get("goal") <= hi:  # P1/Feetech: clamp (P1 also flags an angle error)
                self._store(goal, max(lo, min(hi, self.get("goal"))))
        torque = self.spec.reg("torque")
        if addr <= torque.addr < addr + len(data):
            if self.torque_on and self._shutdown_active():
                self._store(torque, 0)  # cannot enable torque while in a shutdown error
            elif self.torque_on:
                # Enabling torque holds the present position: the profile restarts from there.
                self.motion.cmd, self.motion.cmd_vel = self.motion.pos, 0.0
        return OK

    # --- faults ----------------------------------------------------------------------------------
    def hw_error_bits_p2(self) -> int:
        return sum(HW_BITS_P2[f] for f in self.hw_faults)

    def hw_error_bits_p1(self) -> int:
        return sum(HW_BITS_P1[f] for f in self.hw_faults)

    def _shutdown_active(self) -> bool:
        if not self.hw_faults:
            return False
        mask = self.get("shutdown") if self.has("shutdown") else 0x3F
        if self.spec.family == "dynamixel" and self.spec.eeprom_locked_by_torque:
            return bool(self.hw_error_bits_p2() & mask)
        return bool(self.hw_error_bits_p1() & mask) or self.spec.family == "feetech"

    def inject(self, fault: str) -> None:
        """Latch a hardware fault; faults in the Shutdown mask drop torque like the firmware does."""
        self.hw_faults.add(fault)
        if self.has("hw_error"):
            self._store(self.spec.reg("hw_error"), self.hw_error_bits_p2())
        if self.has("Status"):
            self._store(self.spec.by_name["Status"], self.hw_error_bits_p1())
        if self._shutdown_active():
            self._store(self.spec.reg("torque"), 0)

    def power_cycle(self) -> None:
        """Power off and on: EEPROM back from flash, RAM (torque, Lock, goals) at defaults, faults cleared."""
        self.mem[: self.spec.eeprom_end] = self.flash
        self.reboot()

    def reboot(self) -> None:
        """REBOOT: clears latched faults, torque off, RAM back to defaults (EEPROM kept)."""
        self.hw_faults.clear()
        for r in self.spec.regs:
            if r.addr >= self.spec.eeprom_end:
                self._store(r, r.default)
        self.motion.cmd, self.motion.cmd_vel = self.motion.pos, 0.0
        self._sync_feedback()
        self._store(self.spec.reg("goal"), round(self.motion.pos))

    # --- motor model -----------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance the motor model by ``dt`` seconds and refresh the present-value registers."""
        if dt <= 0:
            return
        m, spec = self.motion, self.spec
        if self.torque_on:
            goal = float(self.get("goal"))
            v_lim = spec.max_speed_ticks_s
            pv = abs(self.get("profile_velocity")) * spec.vel_unit_ticks_s if self.has("profile_velocity") else 0
            if pv > 0:
                v_lim = min(v_lim, pv)
            a_lim = 50.0 * spec.ticks_per_rev  # effectively unlimited
            if self.has("profile_acceleration"):
                pa = self.get("profile_acceleration") * spec.acc_unit_ticks_s2
                if pa > 0:
                    a_lim = pa
            prev = m.pos
            if m.cmd == goal and m.cmd_vel == 0.0:  # the profile holds still: only the position loop settles
                m.pos = goal + (m.pos - goal) * math.exp(-dt / _LAG_TAU_S)
            else:
                n = max(1, math.ceil(dt / _PROFILE_PERIOD_S - 1e-9))
                for _ in range(n):  # the firmware's own period, however late the bus advances the clock
                    self._profile_step(goal, v_lim, a_lim, dt / n)
            m.vel = (m.pos - prev) / dt
        else:
            m.vel = 0.0
            m.cmd, m.cmd_vel = m.pos, 0.0
        th = self.thermal
        load = self._load_permille()
        target_temp = th.ambient_c + th.rise_c_at_full_load * abs(load) / 1000.0
        target_temp += 60.0 if "overheating" in self.hw_faults else 0.0
        m.temp_c += (target_temp - m.temp_c) * (1.0 - math.exp(-dt * th.time_scale / th.tau_s))
        self._sync_feedback()

    def _profile_step(self, goal: float, v_lim: float, a_lim: float, h: float) -> None:
        """One firmware period ``h`` of the profile (ticks, ticks/s, ticks/s²) and of the position loop behind it.

        Velocity override, as the firmware does when a goal arrives mid-move: the profile's velocity changes by at
        most ``a_lim * h`` toward the speed from which it can still stop at the goal; a goal it cannot stop for (one
        that moved back, or one after a lost write) is overshot and come back to, never reached by a jump.
        """
        m = self.motion
        err = goal - m.cmd
        v_des = math.copysign(min(v_lim, math.sqrt(2 * a_lim * abs(err))), err)
        v0 = m.cmd_vel
        v1 = v0 + max(-a_lim * h, min(a_lim * h, v_des - v0))
        new_cmd = m.cmd + 0.5 * (v0 + v1) * h  # velocity linear within the period: |acceleration| <= a_lim
        if (goal - m.cmd) * (goal - new_cmd) <= 0 and abs(v0) <= a_lim * h:  # reached, and stops within the period
            new_cmd, v1 = goal, 0.0
        # Position loop: a first-order lag, exact for a profile moving linearly over the period.
        ramp = (new_cmd - m.cmd) / h
        lag = ramp * _LAG_TAU_S
        m.pos = new_cmd - lag + (m.pos - m.cmd + lag) * math.exp(-h / _LAG_TAU_S)
        m.cmd, m.cmd_vel = new_cmd, v1

    def _load_permille(self) -> float:
        if not self.torque_on:
            return 0.0
        if "overload" in self.hw_faults:
            return 1000.0
        return max(-1000.0, min(1000.0, 4.0 * (self.motion.cmd - self.motion.pos) + 0.02 * self.motion.vel))

    def _sync_feedback(self) -> None:
        m, spec = self.motion, self.spec
        self._store(spec.reg("present"), round(m.pos))
        vel_units = m.vel / spec.vel_unit_ticks_s
        self._store(spec.reg("velocity"), round(vel_units))
        self._store(spec.reg("load"), round(self._load_permille()))
        self._store(spec.reg("temperature"), round(m.temp_c))
        volts = spec.nominal_voltage_dv - (25 if "voltage" in self.hw_faults else 0)
        self._store(spec.reg("voltage"), volts)
        moving = self.torque_on and (abs(self.get("goal") - m.pos) > 2 or abs(m.vel) > 5)
        self._store(spec.reg("moving"), int(moving))
