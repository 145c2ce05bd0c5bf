"""The simulated servo bus: a pseudo-terminal answered by a chain of emulated servos.

Any serial client (the vendor SDKs, pyserial, a terminal program) opens :attr:`VirtualBus.port`
like a USB-serial adapter. One thread reads instruction packets as soon as they arrive, updates
the servos' control tables, advances their motor models on the monotonic clock, answers with
status packets and samples a ~100 Hz recording of goals, positions and torque.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import random
import select
import termios
import threading
import time
import tty
from pathlib import Path
from typing import Any

import numpy as np

from robogest.errors import ConfigError
from robogest.fileio import atomic_path
from robogest.robot.config import RobotConfig, ServoConfig
from robogest.virtualbus import framing
from robogest.virtualbus.faults import FaultSpec
from robogest.virtualbus.protocol import Protocol1Server, Protocol2Server, name_of
from robogest.virtualbus.servo import SimServo, ThermalModel
from robogest.virtualbus.tables import ModelSpec, find_model

_SPEEDS = {
    getattr(termios, f"B{b}"): b
    for b in (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1152000,
              2000000, 2500000, 3000000, 3500000, 4000000)
    if hasattr(termios, f"B{b}")
}  # fmt: skip


_COALESCE_S = 0.006  # return-delay-only replies this close behind a due one leave with it
_TCGETS2 = 0x802C542A  # Linux: ioctl reading struct termios2 (44 bytes), which holds custom speeds


def _baud_index(spec: ModelSpec, baudrate: int) -> int | None:
    for value, rate in spec.baud_table.items():
        if abs(rate - baudrate) <= 0.03 * baudrate:
            return value
    return None


class VirtualBus:
    """A pty that behaves like the robot's servo chain.

    Parameters
    ----------
    robot : RobotConfig
        Must have a ``bus`` section: family, protocol, baudrate and one servo per joint.
    faults : FaultSpec or str, optional
        Fault injection (see :mod:`robogest.virtualbus.faults` for the grammar).
    start_q_rad : ndarray [shape=(J,)], radians, optional
        Where the joints are at power-up; defaults to the robot's rest pose.
    check_baud : bool
        Only answer when the client's port speed matches the servos' Baud Rate register, as real
        servos do (speeds a pty cannot report, like 128000, are accepted).
    record_hz : float
        Sampling rate of :meth:`record`.
    thermal : ThermalModel, optional
        How the servos heat with load and cool at rest (default: 25 °C above 30 °C ambient at full load,
        2 min time constant).
    return_delay_time : int, optional
        Return Delay Time register of every servo at power-up (units of 2 us): 0 by default, as on a bus
        set up by ``servo doctor --fix`` or LeRobot; None keeps each model's factory value (250 on X/AX).
    """

    def __init__(
        self,
        robot: RobotConfig,
        faults: FaultSpec | str | None = None,
        *,
        start_q_rad: np.ndarray | None = None,
        check_baud: bool = True,
        record_hz: float = 100.0,
        thermal: ThermalModel | None = None,
        return_delay_time: int | None = 0,
    ) -> None:
        if robot.bus is None:
            raise ConfigError(f"robot {robot.name!r} has no bus section; add bus: family, protocol, servos")
        self.robot = robot
        self.family = robot.bus.family
        self.protocol = float(robot.bus.protocol)
        self.faults = faults if isinstance(faults, FaultSpec) else FaultSpec.parse(faults)
        self.check_baud = check_baud
        self.record_period_s = 1.0 / record_hz
        self._rng = random.Random(self.faults.seed)
        q0 = robot.rest_q_rad if start_q_rad is None else np.asarray(start_q_rad, float)

        entries = []
        for j, joint in enumerate(robot.joints):
            sc = robot.bus.servos[joint.name]
            try:
                spec = find_model(sc.model)
            except KeyError:
                raise ConfigError(f"robot {robot.name!r}: servo model {sc.model!r} is not emulated") from None
            if spec.family != self.family:
                raise ConfigError(f"servo model {sc.model} is {spec.family}, but the bus family is {self.family}")
            servo = SimServo(spec, sc.id, _baud_index(spec, robot.bus.baudrate), thermal)
            if return_delay_time is not None:
                servo._store(spec.reg("Return_Delay_Time"), return_delay_time)
                servo.flash = bytes(servo.mem[: spec.eeprom_end])
            tpr = spec.ticks_per_rad()

            def to_ticks(q: float, sc: ServoConfig = sc, spec: ModelSpec = spec, tpr: float = tpr) -> float:
                return spec.centre_tick + (sc.direction * q * sc.gear_ratio + sc.zero_offset_rad) * tpr

            start = min(max(round(to_ticks(q0[j])), 0), spec.max_tick)
            servo.motion.pos = servo.motion.cmd = float(start)
            servo._sync_feedback()
            servo._store(spec.reg("goal"), start)
            lo, hi = sorted((to_ticks(joint.lower_rad), to_ticks(joint.upper_rad)))
            entries.append((sc.id, servo, math.floor(lo), math.ceil(hi)))
        entries.sort(key=lambda e: e[0])
        self.servos: list[SimServo] = [e[1] for e in entries]
        self._ids = np.array([e[0] for e in entries], dtype=np.int64)
        self._min_ticks = np.array([e[2] for e in entries], dtype=np.int64)
        self._max_ticks = np.array([e[3] for e in entries], dtype=np.int64)

        p2 = self.family == "dynamixel" and self.protocol == 2.0
        self._parser: framing.Parser1 | framing.Parser2 = framing.Parser2() if p2 else framing.Parser1()
        self._server = Protocol2Server(self) if p2 else Protocol1Server(self)
        self._master: int | None = None
        self._slave: int | None = None
        self.port = ""
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._t0 = 0.0
        self._last_step = 0.0
        self._rec: dict[str, list[Any]] = {"t_s": [], "goal": [], "present": [], "position": [], "torque": []}
        self.errors: list[str] = []
        self.stats = {"packets_in": 0, "packets_out": 0, "bytes_in": 0, "bytes_out": 0, "bad_checksum": 0}
        self._pending_faults = sorted(
            [(t, "hw", sid, kinds) for sid, kinds, t in self.faults.hwerrors]
            + [(t, "vanish", sid, ()) for sid, t in self.faults.vanish]
            + [(t, "torqueoff", sid, ()) for sid, t in self.faults.torqueoff]
            + [(t, "reboot", sid, ()) for sid, t in self.faults.reboot],
            key=lambda f: f[0],
        )
        self.disconnected = False
        # (due, status packet, held by an injected delay)
        self._outq: collections.deque[tuple[float, bytes, bool]] = collections.deque()
        self._line_free_at = 0.0

    # --- lifecycle -------------------------------------------------------------------------------
    def start(self) -> VirtualBus:
        if self._thread is not None:
            return self
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._t0 = self._last_step = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="virtual-bus", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_fds()

    def _close_fds(self) -> None:
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
                setattr(self, name, None)

    def __enter__(self) -> VirtualBus:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def elapsed_s(self) -> float:
        return time.monotonic() - self._t0

    def servo(self, servo_id: int) -> SimServo:
        """The emulated servo answering to ``servo_id`` (for tests and inspection)."""
        for s in self.servos:
            if s.id == servo_id:
                return s
        raise KeyError(servo_id)

    def _note(self, msg: str) -> None:
        if len(self.errors) < 100_000:
            self.errors.append(f"t={self.elapsed_s:.3f}s {msg}")

    # --- main loop -------------------------------------------------------------------------------
    def _run(self) -> None:
        next_sample = self._t0
        last_rx = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            self._apply_timed_faults(now - self._t0)
            if self.disconnected:
                return
            if now >= next_sample:
                with self._lock:
                    self._advance(now)
                    self._sample(now - self._t0)
                next_sample += self.record_period_s
                if next_sample < now:
                    next_sample = now + self.record_period_s
            self._flush_out()
            due = self._next_due() or next_sample
            wait = max(0.0, min(next_sample - time.monotonic(), due - time.monotonic(), 0.01))
            master = self._master
            if master is None:  # closed (an injected disconnect)
                return
            try:
                ready, _, _ = select.select([master], [], [], wait)
                data = os.read(master, 65536) if ready else b""
            except (OSError, ValueError):
                return
            now = time.monotonic()
            if not data:
                if self._parser.buf and now - last_rx > 0.1:
                    self._parser.clear()  # half a packet that will never complete
                continue
            last_rx = now
            self.stats["bytes_in"] += len(data)
            packets = self._parser.feed(data)
            if not packets:
                continue
            with self._lock:
                self._advance(now)
                for pkt in packets:
                    self.stats["packets_in"] += 1
                    self._serve(pkt)
            self._flush_out()

    def _apply_timed_faults(self, t: float) -> None:
        while self._pending_faults and self._pending_faults[0][0] <= t:
            _, kind, sid, kinds = self._pending_faults.pop(0)
            if sid is None:  # torqueoff=all / reboot=all
                for s in self.servos:
                    self.inject_now(kind, s.id, kinds)
                continue
            try:
                self.servo(sid)
            except KeyError:
                self._note(f"fault for id {sid} ignored: no such servo")
                continue
            self.inject_now(kind, sid, kinds)
        if self.faults.disconnect_at_s is not None and t >= self.faults.disconnect_at_s and not self.disconnected:
            with self._lock:
                self._note("injected: port disconnected")
                self.disconnected = True
                self._close_fds()

    def inject_now(self, kind: str, sid: int, kinds: tuple[str, ...] = ()) -> None:
        """Apply one timed fault to servo ``sid`` now: ``hw`` (latch hardware errors ``kinds``), ``vanish``,
        ``torqueoff`` (torque switched off, as by another program on the bus) or ``reboot`` (a brownout)."""
        servo = self.servo(sid)
        with self._lock:
            if kind == "hw":
                for k in kinds:
                    servo.inject(k)
                self._note(f"injected hardware error {'+'.join(kinds)} on id {sid}")
            elif kind == "vanish":
                servo.vanished = True
                self._note(f"injected: id {sid} vanished")
            elif kind == "torqueoff":
                servo._store(servo.spec.reg("torque"), 0)
                self._note(f"injected: torque of id {sid} switched off")
            elif kind == "reboot":
                servo.reboot()
                self._note(f"injected: id {sid} rebooted (brownout)")
            else:
                raise ValueError(f"unknown fault kind {kind!r}")

    def _advance(self, now: float) -> None:
        dt = now - self._last_step
        if dt > 0:
            for s in self.servos:
                s.step(dt)
            self._last_step = now

    def _sample(self, t: float) -> None:
        self._rec["t_s"].append(t)
        self._rec["goal"].append([s.get("goal") for s in self.servos])
        self._rec["present"].append([s.get("present") for s in self.servos])
        self._rec["position"].append([s.motion.pos for s in self.servos])
        self._rec["torque"].append([s.torque_on for s in self.servos])

    # --- answering -------------------------------------------------------------------------------
    def _client_baud_ok(self, servo: SimServo) -> bool:
        if not self.check_baud or self._slave is None:
            return True
        try:
            speed = termios.tcgetattr(self._slave)[5]
        except termios.error:
            return True
        rate = _SPEEDS.get(speed) or self._custom_speed()
        return rate is None or abs(rate - servo.baudrate) <= 0.03 * rate

    def _custom_speed(self) -> int | None:
        """A rate set with BOTHER (pyserial does so for 250000, 128000, ...), read with Linux's TCGETS2."""
        if self._slave is None:
            return None
        try:
            import fcntl

            buf = fcntl.ioctl(self._slave, _TCGETS2, bytes(44))  # struct termios2: c_ospeed at byte 40
        except (OSError, ValueError, TypeError):
            return None
        return int.from_bytes(buf[40:44], "little") or None

    def _present(self, sid: int) -> SimServo | None:
        for s in self.servos:
            if s.id == sid and not s.vanished and self._client_baud_ok(s):
                return s
        return None

    def _run_end(self) -> int:
        """Length of the run of packets that leave together: the head and the packets queued right behind
        it only by return delays (the rest of a sync read's replies). Sending them in one write, when the
        last is due (never early), avoids a wake-up per reply, which would cost a GIL hand-over each (~5 ms
        when the client spins in the same process), far more than the delays themselves."""
        q = self._outq
        end = 1
        while end < len(q) and not q[end][2] and q[end][0] <= q[0][0] + _COALESCE_S:
            end += 1
        return end

    def _next_due(self) -> float | None:
        return self._outq[self._run_end() - 1][0] if self._outq else None

    def _flush_out(self) -> None:
        """Send the status packets whose time has come."""
        now = time.monotonic()
        while self._outq:
            end = self._run_end()
            if self._outq[end - 1][0] > now:
                return
            self._write(b"".join(self._outq.popleft()[1] for _ in range(end)), packets=end)

    def _emit(self, servo_id: int, pkt: bytes, inst: int, delay_s: float = 0.0) -> None:
        """Queue a status packet: it starts ``delay_s`` (the servo's return delay, plus an injected delay)
        after the line is free, so replies of one sync/bulk read follow each other as on a real chain and an
        injected delay holds back every reply queued behind it (a stalled bus)."""
        f = self.faults
        if f.noreply and self._rng.random() < f.noreply:
            self._note(f"injected: no reply from id {servo_id} to {name_of(inst)}")
            return
        if f.badcrc and self._rng.random() < f.badcrc:
            pkt = pkt[:-1] + bytes([pkt[-1] ^ 0x5A])
            self._note(f"injected: bad checksum from id {servo_id} to {name_of(inst)}")
        held = bool(f.delay_p) and self._rng.random() < f.delay_p
        if held:
            delay_s += self._rng.uniform(f.delay_min_s, f.delay_max_s)
        due = max(time.monotonic(), self._line_free_at) + delay_s
        self._line_free_at = due
        self._outq.append((due, pkt, held))

    def _write(self, data: bytes, packets: int = 1) -> None:
        if self._master is None:
            return
        try:
            n = os.write(self._master, data)
        except BlockingIOError:
            n = 0
        except OSError:
            return
        self.stats["packets_out"] += packets
        self.stats["bytes_out"] += n
        if n < len(data):
            self._note(f"output overflow: client not reading, {len(data) - n} bytes dropped")

    def _serve(self, pkt: framing.Packet) -> None:
        f = self.faults
        if f.drop and self._rng.random() < f.drop:
            self._note(f"injected: instruction {name_of(pkt.inst)} to id {pkt.servo_id} lost")
            return
        self._server.serve(pkt)

    # --- recording -------------------------------------------------------------------------------
    def record(self) -> dict[str, np.ndarray]:
        """The recording so far.

        Returns
        -------
        dict
            ``t_s (N,)`` seconds since start; ``t0_monotonic_s`` () the bus clock's zero on
            ``time.monotonic()`` (so ``t0_monotonic_s + t_s`` lines samples up with a client's own stamps);
            ``servo_ids (S,)``; ``goal_ticks (N, S)``,
            ``present_ticks (N, S)`` int64; ``position_ticks (N, S)`` float64 the motor's position before the
            Present Position register rounds it (what a servo's own speed and acceleration are measured on);
            ``torque_on (N, S)`` bool; ``min_ticks (S,)``,
            ``max_ticks (S,)`` the robot's joint limits in ticks; ``errors`` one string per
            injected or detected fault.
        """
        with self._lock:
            s = len(self.servos)
            n = len(self._rec["t_s"])
            return {
                "t_s": np.array(self._rec["t_s"], dtype=np.float64),
                "t0_monotonic_s": np.float64(self._t0),
                "servo_ids": self._ids.copy(),
                "goal_ticks": np.array(self._rec["goal"], dtype=np.int64).reshape(n, s),
                "present_ticks": np.array(self._rec["present"], dtype=np.int64).reshape(n, s),
                "position_ticks": np.array(self._rec["position"], dtype=np.float64).reshape(n, s),
                "torque_on": np.array(self._rec["torque"], dtype=bool).reshape(n, s),
                "min_ticks": self._min_ticks.copy(),
                "max_ticks": self._max_ticks.copy(),
                "errors": np.array(self.errors, dtype=str),
            }

    def save_record(self, path: str | Path) -> Path:
        """Write :meth:`record` as ``.npz`` atomically (temp file + rename)."""
        path = Path(path)
        with atomic_path(path, ".npz") as tmp:
            arrays: dict[str, Any] = self.record()  # Any: numpy's stub reads a ** mapping as its bool options
            np.savez(tmp, **arrays)
        return path
