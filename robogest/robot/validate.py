"""Check that a robot definition and its MuJoCo model agree, before anything moves.

The YAML schema (:mod:`robogest.robot.config`) checks each file on its own; these checks need both the YAML and the
compiled model: every YAML joint is a limited hinge in the MJCF whose range contains the YAML limits, each joint has
one position actuator whose ``ctrlrange`` covers them, the ``home`` keyframe is the YAML rest pose, the rest pose
is free of self-contact, servo models are known and fast enough for the velocity limits, and the retargeting
vectors can actually be followed. The test suite runs :func:`validate_robot` on every shipped robot and
``robogest robots validate`` runs it on a user's, so both are held to the same checks.

This module sits above the stages it checks: it imports MuJoCo, the retargeter and the servo backends' model
tables lazily, inside the functions, so importing :mod:`robogest.robot` stays cheap and free of upward imports.
"""

from __future__ import annotations

import difflib
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robogest.errors import ConfigError
from robogest.fileio import load_yaml
from robogest.robot.config import RobotConfig

#: No-load speed at 12 V (rad/s) of the servo models whose datasheets we have; velocity limits must stay below
#: :data:`SPEED_MARGIN` of it (a loaded servo is slower, and a goal it cannot reach in time lags and overshoots).
NO_LOAD_RAD_S = {"XL430-W250": 6.39, "XM430-W350": 4.82, "STS3215": 4.72}
SPEED_MARGIN = 0.75
#: A retarget vector whose robot link points further than this from its human bone, on average over a short
#: gesture sequence, is not being followed (a swapped site pair or a wrong ``retarget_frame_rpy_rad`` gives ~90-180°).
MAX_MEAN_REACH_ERROR_DEG = 45.0
#: Physics step of the sim backend at most this (s): position servos at 200 Hz or faster stay stable.
MAX_TIMESTEP_S = 0.005
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


def validate(name_or_path: str | Path) -> list[Problem]:
    """All problems of a robot given by name or YAML path; a YAML that does not load is reported, not raised."""
    from robogest.robot.registry import find_robot

    try:
        robot = find_robot(str(name_or_path))
    except ConfigError as e:
        if not Path(str(name_or_path)).is_file():
            raise  # no such robot: nothing to validate (the message lists the known ones)
        return _load_problems(name_or_path, str(e))
    return validate_robot(robot)


def validate_robot(robot: RobotConfig, check_reach: bool = True) -> list[Problem]:
    """All problems of a loaded robot (empty list: it is consistent and safe to play)."""
    yml = robot.path or Path(f"{robot.name}.yaml")
    mjcf = robot.model_path
    try:
        m = load_mjcf(robot)
    except ConfigError as e:
        msg = str(e).removeprefix(f"{robot.path or robot.name}: key model: ")
        return [Problem(yml, "model", msg, "fix the MJCF (or the model path)")]
    problems = _servo_problems(robot, yml)
    problems += _joint_problems(robot, m, yml, mjcf)
    if m.opt.timestep > MAX_TIMESTEP_S:
        problems.append(
            Problem(
                mjcf,
                "<option timestep>",
                f"physics step {m.opt.timestep} s is too coarse for position servos",
                f'set <option timestep="0.002"/> (at most {MAX_TIMESTEP_S})',
            )
        )
    site_problems = _site_problems(robot, m, yml, mjcf)
    problems += site_problems
    # the keyframe and reach checks need every YAML joint as a hinge with exactly one actuator
    joints_ok = not any(p.key.endswith(".name") or p.key.startswith("<actuator") or "hinge" in p.message
                        for p in problems)  # fmt: skip
    if joints_ok:
        problems += _home_problems(robot, m, mjcf)
    if check_reach and joints_ok and not site_problems:
        problems += _reach_problems(robot, yml)
    return problems


# --- the checks ---------------------------------------------------------------------------------------------------


def _servo_problems(robot: RobotConfig, yml: Path) -> list[Problem]:
    """Servo models the backend knows (with the bus's protocol), joint limits inside the servo's tick range, and
    velocity limits the servo can keep up with."""
    if robot.bus is None:
        return []
    from robogest.backends import get_backend_factory

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


def joint_actuators(m, jid: int) -> list[int]:
    """Actuators of MuJoCo model ``m`` that drive joint ``jid`` directly (joint transmission)."""
    import mujoco

    return [
        a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] == jid
    ]


def sim_mapping_problems(robot: RobotConfig, m) -> list[Problem]:
    """What would make the simulator not do what the YAML commands: a YAML joint missing from model ``m`` or not
    a hinge, YAML limits past the joint's range, and a joint not driven by exactly one position servo (gear 1)
    whose ctrlrange covers the YAML limits. The simulator refuses to run such a model."""
    return _joint_problems(robot, m, robot.path or Path(f"{robot.name}.yaml"), robot.model_path, mapping_only=True)


def summary(problems: list[Problem], where: object) -> str:
    """The first two problems on one line (keys relative to ``where``, the robot file), the count of the rest, and
    where to see them all: for the one-line refusals of the simulator and the control loop."""
    more = f" (and {len(problems) - 2} more)" if len(problems) > 2 else ""
    said = "; ".join(str(p).removeprefix(f"{where}: ") for p in problems[:2])
    return f"{said}{more}; `robogest robots validate {where}` lists every problem"


def require_hardware_safe(robot: RobotConfig, nothing: str = "nothing moved") -> None:
    """Raise :class:`ConfigError` (one line, file and keys) when :func:`hardware_problems` finds any."""
    problems = hardware_problems(robot)
    if problems:
        where = robot.path or robot.name
        raise ConfigError(f"{where}: not safe to move real servos with ({nothing}): {summary(problems, where)}")


#: Problems of :func:`follow_problems` by robot definition and MJCF content (the check retargets a test gesture,
#: ~0.1 s; a session that opens the same robot again need not repeat it).
_FOLLOW_CACHE: dict[tuple[str, str], list[Problem]] = {}


def follow_problems(robot: RobotConfig) -> list[Problem]:
    """The retargeting check of :func:`validate_robot` alone (every retarget vector that a joint not held points
    follows its bone on a test gesture), cached in memory per robot definition and MJCF file content."""
    import hashlib

    try:
        digest = hashlib.sha256(robot.model_path.read_bytes()).hexdigest()
    except OSError:
        digest = ""  # the loader names the unreadable file
    key = (robot.model_dump_json() + str(robot.path), digest)
    if key not in _FOLLOW_CACHE:
        _FOLLOW_CACHE[key] = _reach_problems(robot, robot.path or Path(f"{robot.name}.yaml"))
    return _FOLLOW_CACHE[key]


def require_followable(robot: RobotConfig) -> None:
    """Raise :class:`ConfigError` (exit code 3, one line naming the vectors and the fix) when the robot's links
    cannot follow the human bones it maps (:func:`follow_problems`): speak, play, serve and a live session would
    otherwise run with joints that never gesture."""
    problems = follow_problems(robot)
    if problems:
        where = robot.path or robot.name
        raise ConfigError(
            f"{where}: refused, the robot fails the retargeting check (nothing was generated or moved): "
            f"{summary(problems, where)}"
        )


def load_mjcf(robot: RobotConfig):
    """``robot``'s MuJoCo model, compiled (``mujoco.MjModel``): the one loader of the IK, the simulator and the
    checks. ConfigError on one line naming the file when MuJoCo cannot load it (its parser's message spans lines).

    A floating base (a free joint on a body that carries the robot's joints, as menagerie humanoids have) is welded
    at standing height (:func:`weld_floating_base`): robogest gestures, it does not balance.
    """
    import mujoco

    try:
        m = mujoco.MjModel.from_xml_path(str(robot.model_path))
        return weld_floating_base(m, robot.model_path)
    except ValueError as e:
        msg = " ".join(str(e).split())
        raise ConfigError(
            f"{robot.path or robot.name}: key model: MuJoCo cannot load {robot.model_path}: {msg}"
        ) from None


def _lowest_point_z(m, d, geoms: np.ndarray) -> float:
    """Lowest world z of ``geoms`` (ids) at the pose in ``d`` (after kinematics): exact per shape, meshes by their
    vertices; planes are skipped."""
    import mujoco

    t = mujoco.mjtGeom
    low = np.inf
    for g in geoms:
        kind, size, z, rot = m.geom_type[g], m.geom_size[g], d.geom_xpos[g, 2], d.geom_xmat[g].reshape(3, 3)
        up = rot[2]  # the world z of each geom axis
        if kind == t.mjGEOM_PLANE:
            continue
        if kind == t.mjGEOM_SPHERE:
            lo = z - size[0]
        elif kind == t.mjGEOM_CAPSULE:
            lo = z - abs(up[2]) * size[1] - size[0]
        elif kind == t.mjGEOM_CYLINDER:
            lo = z - abs(up[2]) * size[1] - size[0] * np.sqrt(max(0.0, 1.0 - up[2] ** 2))
        elif kind == t.mjGEOM_ELLIPSOID:
            lo = z - np.sqrt(np.sum((up * size) ** 2))
        elif kind == t.mjGEOM_MESH and m.geom_dataid[g] >= 0:
            mid = m.geom_dataid[g]
            a, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            lo = z + float((m.mesh_vert[a : a + n] @ up).min())
        else:  # box, and anything else by its bounding box
            half = size if kind == t.mjGEOM_BOX else m.geom_aabb[g, 3:]
            lo = z - float(np.abs(up) @ half)
        low = min(low, lo)
    return float(low)


def _spec_body(spec, m, b: int):
    """The spec's body for model body ``b`` (same order), named if it was not (contact excludes name bodies)."""
    body = spec.bodies[b]
    if not body.name:
        body.name = f"robogest_body_{b}"
    return body


def weld_floating_base(m, path: Path):
    """``m`` (compiled from ``path``) with each free joint whose body carries hinge joints removed and that body
    welded to the world standing: at the free joint's pose in the ``home`` keyframe if there is one, else at the
    body's default pose moved up or down so that the robot's lowest point touches z = 0 (its feet on the floor).
    Keyframes lose the free joint's entries. A model without such a joint is returned as it is."""
    import mujoco

    hinge_bodies = {int(m.jnt_bodyid[j]) for j in range(m.njnt) if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE}
    free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
            and any(m.body_rootid[b] == m.body_rootid[m.jnt_bodyid[j]] for b in hinge_bodies)]  # fmt: skip
    if not free:
        return m
    home = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)  # qpos0: every free body at its default pose
    spec = mujoco.MjSpec.from_file(str(path))
    drop_q, drop_v = [], []
    for j in free:
        b, qa = int(m.jnt_bodyid[j]), int(m.jnt_qposadr[j])
        if home >= 0:
            pos, quat = m.key_qpos[home, qa : qa + 3].copy(), m.key_qpos[home, qa + 3 : qa + 7].copy()
        else:
            pos, quat = m.qpos0[qa : qa + 3].copy(), m.qpos0[qa + 3 : qa + 7].copy()
            pos[2] -= _lowest_point_z(m, d, np.flatnonzero(m.body_rootid[m.geom_bodyid] == m.body_rootid[b]))
        body = _spec_body(spec, m, b)
        joint = next(x for x in body.joints if x.type == mujoco.mjtJoint.mjJNT_FREE)
        spec.delete(joint)
        body.pos, body.quat = pos, quat / np.linalg.norm(quat)
        # MuJoCo skips contacts between a body and its parent, but not when the parent is welded to the world: the
        # hips would collide with the pelvis they hang from. Exclude those pairs as the floating model did.
        base = [c for c in range(m.nbody) if m.body_weldid[c] == b]  # the base and what is bolted to it
        for c in range(m.nbody):
            if m.body_weldid[c] != b and m.body_parentid[c] in base:
                for p in base:
                    spec.add_exclude(bodyname1=_spec_body(spec, m, p).name, bodyname2=_spec_body(spec, m, c).name)
        drop_q += range(qa, qa + 7)
        drop_v += range(int(m.jnt_dofadr[j]), int(m.jnt_dofadr[j]) + 6)
    for key in spec.keys:
        if len(key.qpos) == m.nq:
            key.qpos = np.delete(np.asarray(key.qpos), drop_q)
        if len(key.qvel) == m.nv:
            key.qvel = np.delete(np.asarray(key.qvel), drop_v)
    return spec.compile()


def hardware_problems(robot: RobotConfig) -> list[Problem]:
    """What must hold before real servos move under ``robot``'s YAML: servo models known, joint limits inside each
    servo's tick range and inside the model's joint ranges (the robot's mechanical range), velocity limits the
    servos can keep. The rest of :func:`validate_robot` concerns the simulation only."""
    yml = robot.path or Path(f"{robot.name}.yaml")
    out = _servo_problems(robot, yml)
    try:
        m = load_mjcf(robot)
    except ConfigError:  # no model to compare with (playing a trajectory needs none); validate reports it
        return out
    return out + [p for p in sim_mapping_problems(robot, m) if p.key.startswith("joints[")]


def _joint_problems(robot: RobotConfig, m, yml: Path, mjcf: Path, mapping_only: bool = False) -> list[Problem]:
    """Every YAML joint against the model; ``mapping_only`` leaves out what only makes the simulation less
    faithful (no range on the MJCF joint, no damping, no force limit, actuators for other joints)."""
    import mujoco

    out = []
    mj_joints = [m.joint(i).name for i in range(m.njnt)]
    driven = set()
    for k, j in enumerate(robot.joints):
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        if jid < 0:
            out.append(not_in_model(yml, f"joints[{k}].name", j.name, "joint", mj_joints, mjcf))
            continue
        if m.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            out.append(Problem(mjcf, f'<joint name="{j.name}">', "not a hinge joint", "robogest drives hinges only"))
            continue
        lo, hi = m.jnt_range[jid] if m.jnt_limited[jid] else (-np.inf, np.inf)
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
        acts = joint_actuators(m, jid)
        driven.update(acts)
        where = f'<actuator> for joint "{j.name}"'
        if len(acts) != 1:
            out.append(
                Problem(
                    mjcf,
                    where,
                    f"{len(acts)} actuators drive this joint",
                    f'give it exactly one <position joint="{j.name}" .../>',
                )
            )
            continue
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


def _site_problems(robot: RobotConfig, m, yml: Path, mjcf: Path) -> list[Problem]:
    """Every retarget site exists, and some YAML joint turns each vector's link."""
    import mujoco

    out = []
    sites = [m.site(i).name for i in range(m.nsite)]
    jbodies = {int(m.jnt_bodyid[jid]) for j in robot.joints
               if (jid := mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)) >= 0}  # fmt: skip

    def moved_by(sid: int) -> set[int]:
        b, chain = int(m.site_bodyid[sid]), set()
        while b > 0:
            chain |= {b} & jbodies
            b = int(m.body_parentid[b])
        return chain

    for k, v in enumerate(robot.retarget):
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in v.robot]
        for s, sid in zip(v.robot, ids, strict=True):
            if sid < 0:
                out.append(not_in_model(yml, f"retarget[{k}].robot", s, "site", sites, mjcf))
        if min(ids) >= 0 and not moved_by(ids[0]) | moved_by(ids[1]):
            out.append(
                Problem(
                    yml,
                    f"retarget[{k}].robot",
                    f"no YAML joint moves sites {v.robot[0]!r} or "
                    f"{v.robot[1]!r}, so this link cannot turn to follow the human bone",
                    "pick sites on links that the YAML joints move",
                )
            )
    return out


def _home_problems(robot: RobotConfig, m, mjcf: Path) -> list[Problem]:
    """``home`` keyframe = YAML rest pose (qpos and ctrl), and no two robot parts touch at rest."""
    import mujoco

    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
    if key < 0:
        rest = " ".join(f"{q:g}" for q in robot.rest_q_rad)
        return [
            Problem(
                mjcf,
                "<keyframe>",
                "no keyframe named 'home' (the sim starts there)",
                f'add <key name="home" qpos="..." ctrl="..."/> with the rest pose ({rest} in YAML order)',
            )
        ]
    out = []
    for j in robot.joints:
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        a = next(a for a in range(m.nu) if m.actuator_trnid[a, 0] == jid)
        q, c = m.key_qpos[key, m.jnt_qposadr[jid]], m.key_ctrl[key, a]
        if abs(q - j.rest_rad) > _TOL or abs(c - j.rest_rad) > _TOL:
            out.append(
                Problem(
                    mjcf,
                    f'<key name="home"> joint "{j.name}"',
                    f"qpos {q:g} / ctrl {c:g} differ from the YAML rest_rad {j.rest_rad:g}",
                    "make both equal rest_rad",
                )
            )
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    robot_geom = m.body_rootid[m.geom_bodyid] != 0  # MuJoCo already drops parent-child pairs
    pairs = sorted({(m.geom(c.geom1).name or str(c.geom1), m.geom(c.geom2).name or str(c.geom2))
                    for c in d.contact[: d.ncon] if robot_geom[c.geom1] and robot_geom[c.geom2]})  # fmt: skip
    if pairs:
        out.append(
            Problem(
                mjcf,
                '<key name="home">',
                f"the robot touches itself at rest: geoms {pairs}",
                "choose a rest pose with clearance, or exclude the pair with <contact><exclude>",
            )
        )
    return out


def _reach_problems(robot: RobotConfig, yml: Path) -> list[Problem]:
    """Retarget a short gesture sequence; every vector's link that a joint not held turns must follow its human
    bone on average (held joints stay at rest throughout)."""
    from robogest.generators.poses import READY, REST, dofs_to_rotations, pose
    from robogest.motion.human_motion import HumanMotion
    from robogest.retarget import DirectionIK

    keys = [REST, READY, READY + pose(both_elbow=0.5, both_flex=0.4), READY + pose(both_abd=0.5, both_twist=-0.3),
            READY + pose(both_elbow=-0.4, both_wrist=-0.3, head_yaw=0.4, head_pitch=0.2), REST]  # fmt: skip
    dofs = np.concatenate([np.linspace(a, b, 10) for a, b in itertools.pairwise(keys)])
    motion = HumanMotion(20.0, dofs_to_rotations(dofs), np.tile([0.0, 1.0, 0.0], (len(dofs), 1)))
    try:
        ik = DirectionIK(robot)
        res = ik.retarget(motion)
    except ConfigError as e:
        return [Problem(yml, "retarget", str(e), "fix the named key")]
    # a vector only held joints turn (the torso's, with the waist held) is not asked to follow
    mean_deg = np.where(ik.followable(), np.degrees(res.direction_error_rad.mean(axis=0)), 0.0)
    return [
        Problem(
            yml,
            f"retarget[{k}]",
            f"the robot link {v.robot[0]}->{v.robot[1]} points {e:.0f} deg away from the "
            f"human bone {v.human[0]}->{v.human[1]} on average over a test gesture (limit "
            f"{MAX_MEAN_REACH_ERROR_DEG:.0f})",
            "check the site order, retarget_frame_rpy_rad and the joint ranges",
        )
        for k, (v, e) in enumerate(zip(robot.retarget, mean_deg, strict=True))
        if e > MAX_MEAN_REACH_ERROR_DEG
    ]


def not_in_model(file: Path, key: str, name: str, kind: str, known: list[str], mjcf: Path) -> Problem:
    """A YAML name the MJCF lacks, with the nearest MJCF name as the likely typo (also for the IK's refusal)."""
    near = difflib.get_close_matches(name, known, n=1)
    hint = f"did you mean {near[0]!r}? " if near else ""
    also = " (and rename its bus.servos entry)" if kind == "joint" else ""
    return Problem(file, key, f"{name!r} is not a {kind} in {mjcf}",
                   f"{hint}use one of {', '.join(known) or '(none)'}{also}")  # fmt: skip


def _load_problems(name_or_path: str | Path, message: str) -> list[Problem]:
    """A YAML that does not load: its message, plus joint names checked against the MJCF when they can be.

    A joint-name typo also breaks the ``bus.servos`` cross-check, whose message names the wrong culprit; the MJCF
    knows the real joint names, so the typo itself is reported first.
    """
    path = Path(str(name_or_path))
    out: list[Problem] = []
    try:
        raw = load_yaml(path.read_text()) if path.is_file() else None
        model = (path.parent / raw["model"]).resolve() if isinstance(raw, dict) and "model" in raw else None
        if model is not None and model.is_file():
            import mujoco

            m = mujoco.MjModel.from_xml_path(str(model))
            names = [m.joint(i).name for i in range(m.njnt)]
            for k, j in enumerate(raw.get("joints") or []):
                n = j.get("name") if isinstance(j, dict) else None
                if isinstance(n, str) and n not in names:
                    out.append(not_in_model(path, f"joints[{k}].name", n, "joint", names, model))
    except Exception:  # the load error below already says what is wrong; this is only a better hint
        pass
    # the loader's messages already say how to fix things, on one line: "PATH: key K: message" or "PATH: invalid
    # robot definition: key K: message; key K2: message2"
    flat = " ".join(message.split()).removeprefix(f"{path}: ")
    head, sep, rest = flat.partition("invalid robot definition: ")
    parts = rest.split("; key ") if sep and not head else [flat]
    for k, part in enumerate(parts):
        text = part if k == 0 else "key " + part
        key, _, msg = text.removeprefix("key ").partition(": ") if text.startswith("key ") else ("(file)", "", text)
        out.append(Problem(path, key, msg, ""))
    return out
