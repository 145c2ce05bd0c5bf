"""What must hold before real servos move under a robot YAML: the backends' servo model tables against the
YAML's servo section and limits. Lives with the backends because the model tables do; the control loop runs it
before torque goes on, and ``robogest robots validate`` reports it with the rest."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robogest.errors import ConfigError
from robogest.robot.config import RobotConfig
from robogest.robot.mjcf import load_mjcf
from robogest.robot.problems import Problem, sim_mapping_problems, summary

#: No-load speed at 12 V (rad/s) of the servo models whose datasheets we have; velocity limits must stay below
#: :data:`SPEED_MARGIN` of it (a loaded servo is slower, and a goal it cannot reach in time lags and overshoots).
NO_LOAD_RAD_S = {"XL430-W250": 6.39, "XM430-W350": 4.82, "STS3215": 4.72}
SPEED_MARGIN = 0.75
_TOL = 1e-6


def servo_problems(robot: RobotConfig, yml: Path) -> list[Problem]:
    """Servo models the backend knows (with the bus's protocol), joint limits inside the servo's tick range, and
    velocity limits the servo can keep up with."""
    if robot.bus is None:
        return []
    from robogest.backends.base import get_backend_factory

    lookup = getattr(get_backend_factory(robot.bus.family), "lookup_model", None)
    if lookup is None:  # a plugin backend that publishes no model table
        return []
    out = []
    for j in robot.joints:
        s = robot.bus.servos[j.name]
        key = f"bus.servos.{j.name}.model"
        try:
            model = lookup(s.model, robot.bus.protocol)
        except ConfigError as e:
            out.append(
                Problem(
                    yml,
                    key,
                    str(e),
                    "use a model the bus's family and protocol know (`robogest servo scan` reads them)",
                )
            )
            continue
        ends = [model.centre_tick + (s.direction * q * s.gear_ratio + s.zero_offset_rad) * model.ticks_per_rev
                / (2 * np.pi) for q in (j.lower_rad, j.upper_rad)]  # fmt: skip
        if min(ends) < -0.5 or max(ends) > model.max_tick + 0.5:
            out.append(Problem(yml, f"bus.servos.{j.name}.zero_offset_rad", f"joint limits [{j.lower_rad}, "
                               f"{j.upper_rad}] rad fall on ticks {min(ends):.0f}..{max(ends):.0f}, outside the "
                               f"{model.name}'s 0..{model.max_tick}", "check zero_offset_rad, gear_ratio and the "
                               "limits (the servo cannot turn past its last tick)"))  # fmt: skip
        no_load = NO_LOAD_RAD_S.get(model.name)
        if no_load is not None and j.max_velocity_rad_s > SPEED_MARGIN * no_load / s.gear_ratio + _TOL:
            cap = SPEED_MARGIN * no_load / s.gear_ratio
            out.append(
                Problem(
                    yml,
                    f"joints[{robot.joint_names.index(j.name)}].max_velocity_rad_s",
                    f"{j.max_velocity_rad_s} rad/s is more than {SPEED_MARGIN:.0%} of the {model.name}'s "
                    f"no-load speed ({no_load} rad/s at 12 V) at the joint",
                    f"set it to {cap:.2f} or less",
                )
            )
    return out


def require_hardware_safe(robot: RobotConfig, nothing: str = "nothing moved") -> None:
    """Raise :class:`ConfigError` (one line, file and keys) when :func:`hardware_problems` finds any."""
    problems = hardware_problems(robot)
    if problems:
        where = robot.path or robot.name
        raise ConfigError(f"{where}: not safe to move real servos with ({nothing}): {summary(problems, where)}")


def hardware_problems(robot: RobotConfig) -> list[Problem]:
    """What must hold before real servos move under ``robot``'s YAML: servo models known, joint limits inside each
    servo's tick range and inside the model's joint ranges (the robot's mechanical range), velocity limits the
    servos can keep. The rest of :func:`validate_robot` concerns the simulation only."""
    yml = robot.path or Path(f"{robot.name}.yaml")
    out = servo_problems(robot, yml)
    try:
        m = load_mjcf(robot)
    except ConfigError:  # no model to compare with (playing a trajectory needs none); validate reports it
        return out
    return out + [p for p in sim_mapping_problems(robot, m) if p.key.startswith("joints[")]
