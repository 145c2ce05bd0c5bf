"""Problems of a robot definition against its compiled MuJoCo model, and how they are reported.

:class:`Problem` is what every robot check returns (file, key, message, fix); :func:`sim_mapping_problems` is the
part the simulator needs before it runs (each YAML joint a limited hinge driven by one position servo). The full
check, with servos, rest pose and retargeting, is :func:`robogest.tools.validate.validate_robot`, which sits above
the stages it checks.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.robot.config import JointConfig, RobotConfig
from robogest.robot.mjcf import joint_actuators

if TYPE_CHECKING:
    import mujoco

_TOL = 1e-6


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a robot: where it is (file and key), what is wrong, and how to fix it."""

    file: Path | str
    key: str
    message: str
    fix: str

    def __str__(self) -> str:
        return f"{self.file}: key {self.key}: {self.message}" + (f"; fix: {self.fix}" if self.fix else "")


def sim_mapping_problems(robot: RobotConfig, m: mujoco.MjModel) -> list[Problem]:
    """What would make the simulator not do what the YAML commands: a YAML joint missing from model ``m`` or not
    a hinge, YAML limits past the joint's range, and a joint not driven by exactly one position servo (gear 1)
    whose ctrlrange covers the YAML limits. The simulator refuses to run such a model."""
    return joint_problems(robot, m, robot.path or Path(f"{robot.name}.yaml"), robot.model_path, mapping_only=True)


def summary(problems: list[Problem], where: object) -> str:
    """The first two problems on one line (keys relative to ``where``, the robot file), the count of the rest, and
    where to see them all: for the one-line refusals of the simulator and the control loop."""
    more = f" (and {len(problems) - 2} more)" if len(problems) > 2 else ""
    said = "; ".join(str(p).removeprefix(f"{where}: ") for p in problems[:2])
    return f"{said}{more}; `robogest robots validate {where}` lists every problem"


def not_in_model(file: Path | str, key: str, name: str, kind: str, known: list[str], mjcf: Path) -> Problem:
    """A YAML name the MJCF lacks, with the nearest MJCF name as the likely typo (also for the IK's refusal)."""
    near = difflib.get_close_matches(name, known, n=1)
    hint = f"did you mean {near[0]!r}? " if near else ""
    also = " (and rename its bus.servos entry)" if kind == "joint" else ""
    return Problem(file, key, f"{name!r} is not a {kind} in {mjcf}",
                   f"{hint}use one of {', '.join(known) or '(none)'}{also}")  # fmt: skip


def joint_problems(
    robot: RobotConfig, m: mujoco.MjModel, yml: Path, mjcf: Path, mapping_only: bool = False
) -> list[Problem]:
    """Every YAML joint against the model; ``mapping_only`` leaves out what only makes the simulation less
    faithful (no range on the MJCF joint, no damping, no force limit, actuators for other joints)."""
    import mujoco

    out: list[Problem] = []
    mj_joints = [m.joint(i).name for i in range(m.njnt)]
    driven: set[int] = set()
    for k, j in enumerate(robot.joints):
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        if jid < 0:
            out.append(not_in_model(yml, f"joints[{k}].name", j.name, "joint", mj_joints, mjcf))
            continue
        if m.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            out.append(Problem(mjcf, f'<joint name="{j.name}">', "not a hinge joint", "robogest drives hinges only"))
            continue
        out += _hinge_problems(m, jid, k, j, yml, mjcf, mapping_only)
        acts = joint_actuators(m, jid)
        driven.update(acts)
        out += _servo_problems(m, jid, acts, j, mjcf, mapping_only)
    extra = [m.actuator(a).name or str(a) for a in range(m.nu) if a not in driven]
    if extra and not mapping_only:
        out.append(
            Problem(
                mjcf,
                "<actuator>",
                f"actuators {extra} drive no YAML joint",
                "remove them or add their joints to the YAML",
            )
        )
    return out


def _joint_range(m: mujoco.MjModel, jid: int) -> tuple[float, float]:
    """The hinge's range (rad), infinite when the MJCF joint is not limited."""
    lo, hi = m.jnt_range[jid] if m.jnt_limited[jid] else (-np.inf, np.inf)
    return lo, hi


def _hinge_problems(
    m: mujoco.MjModel, jid: int, k: int, j: JointConfig, yml: Path, mjcf: Path, mapping_only: bool
) -> list[Problem]:
    """YAML joint ``k`` (``j``) against its MJCF hinge ``jid``: the YAML limits within the hinge's range, and (not
    ``mapping_only``) a range and the damping and armature that make the simulated servo behave like one."""
    out: list[Problem] = []
    lo, hi = _joint_range(m, jid)
    if not m.jnt_limited[jid] and not mapping_only:
        out.append(
            Problem(
                mjcf,
                f'<joint name="{j.name}">',
                "has no range",
                f'add range="{j.lower_rad} {j.upper_rad}" (the YAML limits)',
            )
        )
    if j.lower_rad < lo - _TOL:
        out.append(
            Problem(
                yml,
                f"joints[{k}].lower_rad",
                f"{j.lower_rad} lies below the model's range [{lo:.4g}, {hi:.4g}]",
                f"set lower_rad >= {lo:.4g} or widen the MJCF joint's range",
            )
        )
    if j.upper_rad > hi + _TOL:
        out.append(
            Problem(
                yml,
                f"joints[{k}].upper_rad",
                f"{j.upper_rad} lies above the model's range [{lo:.4g}, {hi:.4g}]",
                f"set upper_rad <= {hi:.4g} or widen the MJCF joint's range",
            )
        )
    dof = m.jnt_dofadr[jid]
    if (m.dof_damping[dof] <= 0 or m.dof_armature[dof] <= 0) and not mapping_only:
        out.append(
            Problem(
                mjcf,
                f'<joint name="{j.name}">',
                "needs damping and armature > 0 (the servo's "
                "back-EMF and gearbox inertia); without them the simulated servo rings",
                'set e.g. damping="0.6" armature="0.006" (STS3215-sized servo)',
            )
        )
    return out


def _servo_problems(
    m: mujoco.MjModel, jid: int, acts: list[int], j: JointConfig, mjcf: Path, mapping_only: bool
) -> list[Problem]:
    """The actuators ``acts`` of hinge ``jid``: exactly one, a position servo with gear 1 whose ctrlrange covers
    the YAML limits and stays within the hinge's range, and (not ``mapping_only``) a force limit."""
    where = f'<actuator> for joint "{j.name}"'
    if len(acts) != 1:
        return [
            Problem(
                mjcf,
                where,
                f"{len(acts)} actuators drive this joint",
                f'give it exactly one <position joint="{j.name}" .../>',
            )
        ]
    import mujoco

    out: list[Problem] = []
    a = acts[0]
    kp = m.actuator_gainprm[a, 0]
    if not (m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE and kp > 0
            and abs(m.actuator_biasprm[a, 1] + kp) < _TOL * max(1.0, kp)):  # fmt: skip
        out.append(
            Problem(
                mjcf,
                where,
                "not a position servo (force = kp * (ctrl - q) - kv * qdot)",
                "use a <position> actuator with kp > 0",
            )
        )
    gear = float(m.actuator_gear[a, 0])
    if abs(gear - 1.0) > _TOL:
        out.append(
            Problem(
                mjcf,
                where,
                f"gear {gear:g}: the joint would settle at ctrl / {gear:g}, not where the YAML commands it",
                "remove gear (1 is the default): joint angles are commanded directly",
            )
        )
    lo, hi = _joint_range(m, jid)
    clo, chi = m.actuator_ctrlrange[a] if m.actuator_ctrllimited[a] else (-np.inf, np.inf)
    if not m.actuator_ctrllimited[a] or clo > j.lower_rad + _TOL or chi < j.upper_rad - _TOL:
        out.append(
            Problem(
                mjcf,
                where,
                f"ctrlrange [{clo:.4g}, {chi:.4g}] does not cover the YAML limits [{j.lower_rad}, {j.upper_rad}]",
                'set inheritrange="1" or ctrlrange to the limits',
            )
        )
    elif clo < lo - _TOL or chi > hi + _TOL:
        out.append(
            Problem(
                mjcf,
                where,
                f"ctrlrange [{clo:.4g}, {chi:.4g}] reaches past the joint range [{lo:.4g}, {hi:.4g}]",
                'set inheritrange="1"',
            )
        )
    if not m.actuator_forcelimited[a] and not mapping_only:
        out.append(
            Problem(
                mjcf,
                where,
                "no force limit: the simulated servo would be infinitely strong",
                "set forcerange to the servo's stall torque (N*m), e.g. -2.94 2.94 for an STS3215",
            )
        )
    return out
