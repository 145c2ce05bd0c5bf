"""Small robot definitions for tests and benchmarks of the servo stack (no files under ``robots/`` needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from robogest.robot.config import RobotConfig, load_robot_config
from robogest.trajectory.types import Trajectory
from robogest.virtualbus.tables import find_model

_MJCF = """<mujoco model="{name}"><worldbody><body name="base">
{joints}</body></worldbody></mujoco>
"""

DEFAULT_MODELS = {("dynamixel", 2.0): "XL430-W250", ("dynamixel", 1.0): "AX-12A", ("feetech", 0.0): "STS3215",
                  ("feetech", 1.0): "SCS0009"}  # fmt: skip


def make_robot(
    folder: str | Path,
    *,
    family: str = "dynamixel",
    protocol: float = 2.0,
    model: str | None = None,
    n_joints: int = 3,
    baudrate: int = 1_000_000,
    limit_rad: float = 1.0,
    v_max: float = 3.0,  # within every default model's rating (STS3215: 3.54 rad/s)
    a_max: float = 40.0,
    directions: list[int] | None = None,
    name: str = "testbot",
    ids: list[int] | None = None,
) -> RobotConfig:
    """Write ``<folder>/<name>.yaml`` (+ a tiny MJCF) for a chain of ``n_joints`` servos with ids 1..n.

    Joint k gets limits ``[-limit_rad, limit_rad]`` shifted a little per joint, alternating
    directions and non-zero zero offsets, so the rad <-> tick mapping is really exercised.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model = model or DEFAULT_MODELS[(family, float(protocol))]
    names = [f"j{k}" for k in range(n_joints)]
    (folder / f"{name}.xml").write_text(
        _MJCF.format(name=name, joints="".join(f'<joint name="{n}" type="hinge"/>\n' for n in names))
    )
    ids = ids or list(range(1, n_joints + 1))
    directions = directions or [1 if k % 2 == 0 else -1 for k in range(n_joints)]
    doc = {
        "name": name,
        "model": f"{name}.xml",
        "joints": [
            {
                "name": n,
                "lower_rad": -limit_rad + 0.05 * k,
                "upper_rad": limit_rad - 0.05 * k,
                "max_velocity_rad_s": v_max,
                "max_acceleration_rad_s2": a_max,
                "rest_rad": 0.0,
            }
            for k, n in enumerate(names)
        ],
        "retarget": [{"human": ["l_shoulder", "l_elbow"], "robot": ["a", "b"]}],
        "bus": {
            "family": family,
            "protocol": protocol,
            "baudrate": baudrate,
            "servos": {
                n: {"id": ids[k], "model": model, "zero_offset_rad": 0.02 * k, "direction": directions[k]}
                for k, n in enumerate(names)
            },
        },
    }
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_robot_config(path)


def monologue(robot: RobotConfig, seconds: float, fps: float = 50.0, amp_rad: float = 0.45) -> Trajectory:
    """A long-talk stand-in: gesture bursts of 3 s (0.8 Hz, phase-shifted per joint) with 1 s rests, in limits."""
    t = np.arange(0, seconds + 1e-9, 1 / fps)
    cycle = np.mod(t, 4.0)
    burst = (cycle < 3.0) * np.sin(np.pi * cycle / 3.0) ** 2
    q = amp_rad * burst[:, None] * np.sin(2 * np.pi * 0.8 * t[:, None] + np.arange(len(robot.joints)) * 0.7)
    return Trajectory.for_robot(robot, np.clip(q, robot.q_min_rad, robot.q_max_rad), t_s=t)


def servo_acceleration_ratio(rec: dict[str, np.ndarray], robot: RobotConfig) -> np.ndarray:
    """``(S,)`` each simulated servo's largest acceleration while its torque is on, at the joint (through the gear),
    over the joint's ``max_acceleration_rad_s2``; servos in ``rec["servo_ids"]`` order (``rec`` from
    :meth:`~robogest.virtualbus.VirtualBus.record`).

    Second divided differences of the unrounded ``position_ticks`` over consecutive samples: each is a weighted mean
    of the acceleration between its three samples, so sampling jitter cannot inflate the figure, and it never
    exceeds the servo's true peak.
    """
    assert robot.bus is not None
    t, p, on = rec["t_s"], rec["position_ticks"], rec["torque_on"]
    if len(t) < 3:
        return np.zeros(len(rec["servo_ids"]))
    v = np.diff(p, axis=0) / np.diff(t)[:, None]
    a = np.diff(v, axis=0) / (0.5 * (t[2:] - t[:-2]))[:, None]
    held = on[:-2] & on[1:-1] & on[2:]
    joint_of = {sc.id: name for name, sc in robot.bus.servos.items()}
    out = np.zeros(len(rec["servo_ids"]))
    for k, sid in enumerate(rec["servo_ids"]):
        name = joint_of[int(sid)]
        sc = robot.bus.servos[name]
        ticks_per_rad = find_model(sc.model).ticks_per_rad() * abs(sc.gear_ratio)
        peak = np.abs(a[held[:, k], k]).max(initial=0.0) / ticks_per_rad
        out[k] = peak / robot.a_max_rad_s2[robot.joint_names.index(name)]
    return out
