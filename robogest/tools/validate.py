"""Check that a robot definition and its MuJoCo model agree, before anything moves.

The YAML schema (:mod:`robogest.robot.config`) checks each file on its own; these checks need both the YAML and the
compiled model: every YAML joint is a limited hinge in the MJCF whose range contains the YAML limits, each joint has
one position actuator whose ``ctrlrange`` covers them, the ``home`` keyframe is the YAML rest pose, the rest pose
is free of self-contact, servo models are known and fast enough for the velocity limits, and the retargeting
vectors can actually be followed. The test suite runs :func:`validate_robot` on every shipped robot and
``robogest robots validate`` runs it on a user's, so both are held to the same checks.

This module is a robot tool, above the stages it checks (retargeting, the servo backends' model tables); the
parts those stages need themselves live below them: the MJCF loader (:mod:`robogest.robot.mjcf`), the model/YAML
mapping check (:mod:`robogest.robot.problems`) and the servo check (:mod:`robogest.backends.servos.check`).
MuJoCo and the retargeter load inside the functions, so the CLI's import stays cheap.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import ConfigError
from robogest.fileio import load_yaml, read_text_capped
from robogest.robot.config import RobotConfig
from robogest.robot.mjcf import compile_mjcf, load_mjcf
from robogest.robot.problems import Problem, joint_problems, not_in_model, summary

if TYPE_CHECKING:
    import mujoco

#: A retarget vector whose robot link points further than this from its human bone, on average over a short
#: gesture sequence, is not being followed (a swapped site pair or a wrong ``retarget_frame_rpy_rad`` gives ~90-180°).
MAX_MEAN_REACH_ERROR_DEG = 45.0
#: Physics step of the sim backend at most this (s): position servos at 200 Hz or faster stay stable.
MAX_TIMESTEP_S = 0.005
_TOL = 1e-6


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
    from robogest.backends.servos.check import servo_problems  # the backends load their servo tables on use

    yml = robot.path or Path(f"{robot.name}.yaml")
    mjcf = robot.model_path
    try:
        m = load_mjcf(robot)
    except ConfigError as e:
        msg = str(e).removeprefix(f"{robot.path or robot.name}: key model: ")
        return [Problem(yml, "model", msg, "fix the MJCF (or the model path)")]
    problems = servo_problems(robot, yml)
    problems += joint_problems(robot, m, yml, mjcf)
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


def _site_problems(robot: RobotConfig, m: mujoco.MjModel, yml: Path, mjcf: Path) -> list[Problem]:
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


def _home_problems(robot: RobotConfig, m: mujoco.MjModel, mjcf: Path) -> list[Problem]:
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


def _load_problems(name_or_path: str | Path, message: str) -> list[Problem]:
    """A YAML that does not load: its message, plus joint names checked against the MJCF when they can be.

    A joint-name typo also breaks the ``bus.servos`` cross-check, whose message names the wrong culprit; the MJCF
    knows the real joint names, so the typo itself is reported first.
    """
    path = Path(str(name_or_path))
    out: list[Problem] = []
    try:
        raw = load_yaml(read_text_capped(path, what="robot file"))  # InputError: the load error says it already
        model = (path.parent / raw["model"]).resolve() if isinstance(raw, dict) and "model" in raw else None
        if isinstance(raw, dict) and model is not None and model.is_file():
            m = compile_mjcf(model)
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
