"""``robogest servo doctor|calibrate|jog``: checking a real bus, measuring a robot's joints, moving one joint."""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robogest.errors import ConfigError, InputError

if TYPE_CHECKING:
    from robogest.backends.servos.bringup import Finding, FoundServo
    from robogest.backends.servos.bus import ServoBackend
    from robogest.backends.servos.protocol import ServoModel
    from robogest.backends.servos.transport import Transport
    from robogest.robot.config import RobotConfig


def _robot_backend(name: str, port: str | None, **options: Any) -> tuple[RobotConfig, ServoBackend]:
    from robogest.backends.servos.bus import servo_backend
    from robogest.robot.registry import find_robot

    robot = find_robot(name)
    if robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section; add bus: family, protocol, baudrate, servos")
    return robot, servo_backend(robot, port=port, **options)


def _joint_index(robot: RobotConfig, joint: str) -> int:
    if joint not in robot.joint_names:
        raise InputError(f"robot {robot.name!r} has no joint {joint!r}; its joints: {', '.join(robot.joint_names)}")
    return robot.joint_names.index(joint)


# --- jog -----------------------------------------------------------------------------------------
def jog(args: argparse.Namespace) -> int:
    """One joint to an angle through the one control loop (online limiter + goal guard) at a fraction of the limits."""
    from robogest.backends.control import ControlLoop
    from robogest.backends.servos.bus import servo_backend
    from robogest.backends.signals import signals_end_at_rest
    from robogest.robot.registry import find_robot

    robot = find_robot(args.robot)
    if robot.bus is None:
        raise ConfigError(f"robot {robot.name!r} has no bus section; add bus: family, protocol, baudrate, servos")
    k = _joint_index(robot, args.joint)
    lo, hi = float(robot.q_min_rad[k]), float(robot.q_max_rad[k])
    if not (math.isfinite(args.angle) and lo <= args.angle <= hi):
        raise InputError(
            f"joint {args.joint}: angle {args.angle:+.3f} rad is outside its limits [{lo:+.3f}, {hi:+.3f}] rad; "
            "pick an angle inside them"
        )
    if not (0.0 < args.speed <= 1.0 and 0.0 <= args.hold <= 60.0):
        raise InputError("--speed must lie in (0, 1] (fraction of the speed limit) and --hold in [0, 60] s")
    # Gentle: the robot as the loop and the guard see it has its speed, acceleration and jerk limits scaled down.
    gentle = robot.model_copy(
        update={
            "joints": [
                j.model_copy(
                    update={
                        "max_velocity_rad_s": j.max_velocity_rad_s * args.speed,
                        "max_acceleration_rad_s2": j.max_acceleration_rad_s2 * args.speed,
                    }
                )
                for j in robot.joints
            ]
        }
    )
    backend = servo_backend(gentle, port=args.port)
    with signals_end_at_rest(), ControlLoop(backend, rate_hz=50.0) as loop:  # leaving: rest, torque off
        goal = loop.goal_rad.copy()
        goal[k] = args.angle
        assert loop.limiter is not None  # started: the loop has its limiter
        goal = loop.limiter.clamp_target(goal)  # the loop keeps its margin inside the limits: wait for that pose
        loop.set_idle(lambda t: goal)
        deadline = time.monotonic() + 120.0
        while np.max(np.abs(loop.goal_rad - goal)) > 1e-4 and time.monotonic() < deadline:
            loop.run_for(0.02)  # raises the loop's error: a fault stops the jog (at rest, torque off)
        loop.run_for(args.hold)
        reached = loop.goal_rad[k]  # the loop thread owns the port: no read from here
    # leaving the block raised if the loop failed or rest was not reached
    kept = "" if abs(goal[k] - args.angle) < 1e-9 else f", kept {abs(goal[k] - args.angle):.3f} rad inside the limit"
    print(f"{args.joint}: at {reached:+.3f} rad (goal {args.angle:+.3f} rad{kept}); back to rest, torque off")
    return 0


# --- calibrate -----------------------------------------------------------------------------------
def _ask(prompt: str, sample: Any = None) -> None:
    """Wait for Enter; meanwhile call ``sample()`` at ~20 Hz when stdin can be polled (a terminal or pipe)."""
    import select

    print(prompt, file=sys.stderr, flush=True)
    try:
        pollable = sample is not None and sys.stdin.fileno() >= 0
    except (AttributeError, OSError, ValueError):
        pollable = False
    while pollable and not select.select([sys.stdin], [], [], 0.05)[0]:
        sample()
    if sys.stdin.readline() == "":
        raise InputError("calibration needs an answer (Enter) at each step; stdin was closed")


def calibrate(args: argparse.Namespace) -> int:
    import yaml

    from robogest.cli.checks import check_outputs
    from robogest.fileio import read_text_capped
    from robogest.robot.yaml_edit import write_robot_yaml

    robot, backend = _robot_backend(args.robot, args.port, check_limits=False)
    src = Path(robot.path) if robot.path is not None else None
    if src is None:
        raise InputError(f"robot {robot.name!r} has no YAML file to copy")
    out = Path(args.out) if args.out else src.with_name(f"{src.stem}.calibrated.yaml")
    if out.resolve() == src.resolve():
        raise InputError(f"--out {out} is the robot's own YAML; calibration writes a copy, never over the original")
    check_outputs({"--out": out}, {"--robot": src})  # before anything moves: a folder, device, unwritable path
    joints = args.joint or robot.joint_names
    for j in joints:
        _joint_index(robot, j)
    if not 0.0 <= args.margin_rad < 0.5:
        raise InputError("--margin-rad must lie in [0, 0.5) rad")
    measured: dict[str, dict[str, float]] = {}
    backend.connect()
    try:
        backend.set_torque(False)
        print("torque is off: move the joints by hand as asked (support the arms)", file=sys.stderr)
        for j in joints:
            k = robot.joint_names.index(j)
            ticks: dict[str, float] = {}
            seen: list[float] = []  # every reading while the joint travels to its ends

            def tick_now(k: int = k) -> float:
                return float(backend.rad_to_ticks(backend.read_positions())[k])

            def sample(seen: list[float] = seen) -> None:
                seen.append(tick_now())

            for step, where in (
                ("zero", "its zero pose (0 rad in the robot's convention)"),
                ("upper", "its upper end (the positive direction)"),
                ("lower", "its lower end, through its whole range"),
            ):
                _ask(f"{j}: move it to {where}, then press Enter", None if step == "zero" else sample)
                ticks[step] = tick_now()
                if step != "zero":
                    seen.append(ticks[step])
            measured[j] = _fit_joint(backend, k, j, ticks, seen, args.margin_rad)
    finally:
        backend.shutdown()

    doc = yaml.safe_load(read_text_capped(src, what="robot file"))
    if robot.base is not None:  # a file of changes to its base (docs/servos.md): the copy gets every value
        doc = {**robot.model_dump(mode="json", by_alias=True, exclude_none=True), "model": str(robot.model_path)}
        del doc["base"]
    for jd in doc["joints"]:
        if jd["name"] in measured:
            m = measured[jd["name"]]
            jd["lower_rad"], jd["upper_rad"] = m["lower_rad"], m["upper_rad"]
            jd["rest_rad"] = float(np.clip(jd.get("rest_rad", 0.0), m["lower_rad"], m["upper_rad"]))
            servo = doc["bus"]["servos"][jd["name"]]
            servo["zero_offset_rad"], servo["direction"] = m["zero_offset_rad"], int(m["direction"])
    if out.parent.resolve() != src.parent.resolve():
        doc["model"] = str((src.parent / doc["model"]).resolve())  # keep the MJCF reachable from the copy
    write_robot_yaml(out, doc)  # published only if the copy loads
    for j, m in measured.items():
        k = robot.joint_names.index(j)
        lo, hi = float(robot.q_min_rad[k]), float(robot.q_max_rad[k])
        wider = m["lower_rad"] < lo - 1e-3 or m["upper_rad"] > hi + 1e-3  # beyond what the line shows
        print(
            f"{j}: zero_offset_rad {m['zero_offset_rad']:+.4f}, direction {int(m['direction']):+d}, "
            f"limits [{m['lower_rad']:+.3f}, {m['upper_rad']:+.3f}] rad"
            + (f" (WIDER than the original's [{lo:+.3f}, {hi:+.3f}]: the measured travel; narrow them in the copy "
               "if the original's were chosen on purpose)" if wider else "")
        )  # fmt: skip
    print(
        f"wrote {out} (the original {src} is unchanged); review the copy, then "
        f"`robogest servo doctor --port {backend.port_name} --robot {out} --fix` writes its limits into the servos"
    )
    return 0


#: Readings this close to either end of a servo's encoder range (ticks) mean the joint's travel may cross it.
WRAP_BAND_TICKS = 16


def _fit_joint(
    backend: Any, k: int, joint: str, ticks: dict[str, float], seen: list[float], margin: float
) -> dict[str, float]:
    """Zero offset, direction and limits from the ticks read at the zero pose, at both ends, and on the way
    (the furthest reading on each side is the end)."""
    servo = backend.robot.bus.servos[joint]
    model = backend.models[k]
    per_rad = model.ticks_per_rev / (2 * math.pi)
    readings = [ticks["zero"], *seen]  # in the order they were read
    half = model.ticks_per_rev / 2
    wraps = any(abs(b - a) > half for a, b in itertools.pairwise(readings))
    wraps |= any(abs(r - ticks["zero"]) > half for r in readings)
    edge = [r for r in readings if r < WRAP_BAND_TICKS or r > model.max_tick - WRAP_BAND_TICKS]
    if wraps or edge:
        raise InputError(
            f"joint {joint}: its travel {'crosses' if wraps else 'reaches'} the end of the servo's encoder range "
            f"(0 or {model.max_tick} ticks), where the reading jumps a whole turn: limits measured across it would "
            "span nearly a turn; turn the horn on the servo shaft (or set the servo's homing offset) so that the "
            "joint's whole travel lies inside the range, then calibrate again; nothing was written"
        )
    zero = (ticks["zero"] - model.centre_tick) / per_rad
    direction = 1.0 if ticks["upper"] >= ticks["zero"] else -1.0

    def rad(tick: float) -> float:
        return float(((tick - model.centre_tick) / per_rad - zero) / (servo.gear_ratio * direction))

    far_up, far_down = (max(seen), min(seen)) if direction > 0 else (min(seen), max(seen))
    upper, lower = rad(far_up) - margin, rad(far_down) + margin
    if not lower < 0.0 < upper:
        raise InputError(
            f"joint {joint}: measured range [{lower + margin:+.3f}, {upper - margin:+.3f}] rad does not hold the "
            "zero pose with the margin inside; move it to its zero pose, then to each end, as asked"
        )
    return {"zero_offset_rad": round(zero, 5), "direction": direction, "lower_rad": round(lower, 4),
            "upper_rad": round(upper, 4)}  # fmt: skip


# --- doctor --------------------------------------------------------------------------------------
def doctor(args: argparse.Namespace) -> int:
    from robogest.backends.servos.bringup import Finding, check_latency_timer, scan, set_baud
    from robogest.backends.servos.protocol import ServoProtocol
    from robogest.backends.servos.transport import Transport

    findings = [check_latency_timer(args.port, args.fix)]
    for f in findings:
        print(f.line())
    expected: dict[int, tuple[str, int, int, ServoModel]] = {}  # id -> (joint, min tick, max tick, model) from the YAML
    if args.robot:
        robot, backend = _robot_backend(args.robot, args.port)
        assert robot.bus is not None
        proto = ServoProtocol.of_bus(robot.bus.family, robot.bus.protocol)
        lo_t, hi_t = backend.rad_to_ticks(robot.q_min_rad), backend.rad_to_ticks(robot.q_max_rad)
        for k, j in enumerate(robot.joint_names):
            expected[int(backend.ids[k])] = (j, int(min(lo_t[k], hi_t[k])), int(max(lo_t[k], hi_t[k])),
                                             backend.models[k])  # fmt: skip
        bus_found = scan(args.port, [proto], [robot.bus.baudrate], max_id=max(expected))
        for sid, (j, *_) in expected.items():
            if not any(f.id == sid for f in bus_found):
                elsewhere = [f for f in scan(args.port, [proto], max_id=sid) if f.id == sid]
                where = f"; it answers at {elsewhere[0].baud} baud" if elsewhere else ""
                what = f"servo id {sid} (joint {j}): no answer at {robot.bus.baudrate} baud{where}"
                if elsewhere and args.fix:
                    set_baud(args.port, proto, sid, elsewhere[0].baud, robot.bus.baudrate)
                    bus_found += [f for f in scan(args.port, [proto], [robot.bus.baudrate], max_id=sid) if f.id == sid]
                    _say(findings, Finding("fixed", what + f"; moved to {robot.bus.baudrate} baud"))
                    continue
                _say(findings, Finding("error", what + "; set its Baud Rate register or the YAML's bus.baudrate"))
    else:
        bus_found = scan(args.port, [ServoProtocol.named(p) for p in args.protocol or []], args.baud)
        if not bus_found:
            _say(findings, Finding("error", f"no servo answered on {args.port}; check power and wiring"))
    for found in bus_found:
        with Transport(args.port, found.protocol, found.baud) as link:
            for finding in _check_servo(link, found, expected.get(found.id), args.fix):
                _say(findings, finding)
    bad = [f for f in findings if f.level in ("warn", "error")]
    print(f"{len(bad)} problem(s)" + ("; --fix sets what it can" if bad and not args.fix else ""))
    return 1 if bad else 0


def _say(findings: list[Finding], f: Finding) -> None:
    findings.append(f)
    print(f.line(), flush=True)


def _check_servo(
    link: Transport, f: FoundServo, expected: tuple[str, int, int, ServoModel] | None, fix: bool
) -> list[Finding]:
    from robogest.backends.servos.bringup import Finding, write_eeprom

    who = f"servo id {f.id}" + (f" (joint {expected[0]})" if expected else "")
    out = []
    if f.return_delay_us > 0:
        if fix:
            write_eeprom(link, f.id, link.wire.reg("RETURN_DELAY_TIME"), 0)
            out.append(Finding("fixed", f"{who}: return delay {f.return_delay_us:.0f} us -> 0"))
        else:
            out.append(Finding("warn", f"{who}: return delay {f.return_delay_us:.0f} us before every reply; set 0"))
    else:
        out.append(Finding("ok", f"{who}: return delay 0"))
    if expected is not None and f.model_number != expected[3].number:  # its ticks mean other angles: touch nothing
        out.append(Finding("error", f"{who}: the bus has a {f.model} ({f.model_number}) where the YAML says "
                                    f"{expected[3].name} ({expected[3].number}); fix the YAML or the wiring; nothing "
                                    "written to it"))  # fmt: skip
        return out
    if expected is not None and not 0 <= expected[1] <= expected[2] <= expected[3].max_tick:
        why = (f"{who}: the YAML's joint limits map to [{expected[1]}, {expected[2]}] ticks, outside the servo's "
               f"range [0, {expected[3].max_tick}]; check its zero_offset_rad and direction (`robogest servo "
               "calibrate`); limits not written")  # fmt: skip
        out.append(Finding("error", why))
        expected = None
    if expected is not None:
        _, lo, hi, _ = expected
        smin, smax = f.min_position_tick, f.max_position_tick
        narrower = lo < smin - 1 or hi > smax + 1
        wider = smin < lo - 1 or smax > hi + 1
        if narrower or wider:
            what = (
                f"{who}: position limits in the servo [{smin}, {smax}] ticks, the YAML's joint limits map to "
                f"[{lo}, {hi}]" + ("; motion would be refused at connect" if narrower else "")
            )
            if fix:
                write_eeprom(link, f.id, link.wire.reg("MIN_POSITION_LIMIT", "CW_ANGLE_LIMIT"), lo)
                write_eeprom(link, f.id, link.wire.reg("MAX_POSITION_LIMIT", "CCW_ANGLE_LIMIT"), hi)
                out.append(Finding("fixed", what + f"; servo limits set to [{lo}, {hi}]"))
            else:
                why = "" if narrower else " (the servo's own limits are a second line of defence)"
                out.append(Finding("error" if narrower else "warn", what + f"; set them to the YAML's{why}"))
        else:
            out.append(Finding("ok", f"{who}: position limits [{smin}, {smax}] match the YAML"))
    regs = link.wire.registers.__members__
    torque = next((n for n in ("MAX_TORQUE_LIMIT", "MAX_TORQUE", "PWM_LIMIT") if n in regs), None)
    if torque:
        full = 885 if torque == "PWM_LIMIT" else (1000 if link.protocol.family == "feetech" else 1023)
        pct = 100.0 * link.read(f.id, regs[torque]) / full
        level = "ok" if pct >= 50 else "warn"
        out.append(Finding(level, f"{who}: torque limit {pct:.0f} % ({torque})" + ("" if pct >= 50 else "; weak")))
    volt = next(regs[n] for n in ("PRESENT_INPUT_VOLTAGE", "PRESENT_VOLTAGE") if n in regs)
    v = link.read(f.id, volt) / 10.0
    vmin, vmax = (link.read(f.id, regs[n]) / 10.0 for n in ("MIN_VOLTAGE_LIMIT", "MAX_VOLTAGE_LIMIT"))
    temp = link.read(f.id, regs["PRESENT_TEMPERATURE"])
    level = "ok" if vmin <= v <= vmax and temp < 60 else "error"
    out.append(Finding(level, f"{who}: supply {v:.1f} V (limits [{vmin:.1f}, {vmax:.1f}] V), {temp} °C"))
    return out
