"""Turn a URDF arm into a robogest robot: an MJCF with sites, position servos, a home keyframe and a lit scene, and
a YAML whose human-to-robot mapping is proposed from the kinematic chain and the link names.

Most robots ship a URDF. MuJoCo reads it (``mujoco.MjSpec``), but a URDF has no servo actuators, no sites for the
retargeting vectors, no rest keyframe, and no light or floor (a render comes out black). This module adds them:

- position actuators sized from each joint's ``<limit effort velocity>``, modelled like the shipped servos: force
  clipped at ``effort`` (the stall torque), ``kp = effort / 0.1 rad``, back-EMF damping ``effort / velocity`` (so
  the no-load speed is the URDF's velocity), armature and friction scaled from the STS3215's;
- sites at the shoulder, elbow and wrist joint axes and at the tip of the chain, and a retargeting proposal that maps
  them to the human arm (the right arm for a single arm, turned half a turn like the shipped desk arms; both arms
  when link names say left/right); a single arm that reaches sideways at joint zero is turned to face +X;
- a ``home`` keyframe at the rest pose: the robot's retargeted image of a person standing at rest;
- a scene file with a floor, a light, a skybox and the ``front`` camera every robogest scene has.

Everything it guesses is returned as text, written as comments into the YAML, and can be edited there; run
``robogest robots validate`` afterwards (the CLI does).
"""

from __future__ import annotations

import itertools
import math
import re
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robogest.errors import InputError

#: Servo model the actuators are scaled from when the URDF gives no effort/velocity: Feetech STS3215 at 12 V.
DEFAULT_EFFORT_NM = 2.94
DEFAULT_VELOCITY_RAD_S = 4.72
#: Joint limits the YAML proposes, relative to the URDF's: 65 % of its velocity, a gentle acceleration.
VELOCITY_SHARE = 0.65
ACCELERATION_RAD_S2 = 15.0
_SIDE_PATTERNS = {
    "l": re.compile(r"(^|[_\W])(l|left)([_\W]|$)|^left|left$", re.I),
    "r": re.compile(r"(^|[_\W])(r|right)([_\W]|$)|^right|right$", re.I),
}


@dataclass
class UrdfImport:
    """What :func:`import_urdf` wrote and what it guessed (one sentence each)."""

    yaml_path: Path
    mjcf_path: Path
    scene_path: Path
    guesses: list[str] = field(default_factory=list)


@dataclass
class _Arm:
    side: str  # "l" or "r"
    joints: list[str]  # actuated hinges from the root to the tip, in chain order
    points: dict[str, tuple[str, np.ndarray]]  # site role -> (body name, position in that body's frame)


def import_urdf(urdf: str | Path, out_yaml: str | Path, name: str | None = None, overwrite: bool = False) -> UrdfImport:
    """Write ``out_yaml`` and its MJCF (``sim/NAME/`` beside a ``robots/`` folder, else ``NAME/`` beside the YAML).

    Raises :class:`~robogest.errors.InputError` for a missing or unreadable URDF, a mesh that cannot be found, or
    outputs that exist (unless ``overwrite``).
    """
    import mujoco

    urdf, out_yaml = Path(urdf), Path(out_yaml)
    name = name or out_yaml.stem
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise InputError(f"robot name {name!r}: use letters, digits, '_', '-' or '.' (it names files)")
    try:
        text = urdf.read_text()
        root = ET.fromstring(text)
    except OSError as e:
        raise InputError(f"{urdf}: cannot read the URDF ({e.strerror})") from None
    except ET.ParseError as e:
        raise InputError(f"{urdf}: not valid XML ({e}); fix the file (xacro files must be expanded first)") from None
    if root.tag != "robot":
        raise InputError(f"{urdf}: the root element is <{root.tag}>, not <robot>; pass a URDF file")
    yaml_dir = out_yaml.parent
    model_dir = (yaml_dir.parent / "sim" / name) if yaml_dir.name == "robots" else (yaml_dir / name)
    mjcf_path, scene_path = model_dir / f"{name}.xml", model_dir / "scene.xml"
    for p in (out_yaml, mjcf_path, scene_path):
        if p.exists() and not overwrite:
            raise InputError(f"{p} exists; choose another --out or pass --force to overwrite it")
    guesses: list[str] = []

    meshes = _resolve_meshes(root, urdf)
    _keep_visuals(root, guesses)
    fixed = _fix_non_hinges(root, guesses)
    assets = model_dir / "assets"
    if meshes:
        assets.mkdir(parents=True, exist_ok=True)
        for src, dst in meshes.items():
            shutil.copyfile(src, assets / dst)
    try:  # MuJoCo's URDF reader gives the bodies, joints, limits and geoms; the rest is added to its MJCF
        root.find("mujoco/compiler").set("meshdir", str(assets))
        spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
        spec.compile()
        mj = ET.fromstring(spec.to_xml())
        m = mujoco.MjModel.from_xml_string(ET.tostring(mj, encoding="unicode"))
    except ValueError as e:
        raise InputError(f"{urdf}: MuJoCo cannot load it: {' '.join(str(e).split())}") from None
    joints = [m.joint(j).name for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    if not joints:
        raise InputError(f"{urdf}: no revolute or continuous joints; robogest drives hinge joints")
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    arms = _find_arms(m, d, joints, guesses)
    if not arms:
        raise InputError(f"{urdf}: found no chain of 2 or more joints spaced apart to map a human arm onto")
    velocity = {jn: _urdf_velocity(root, jn) for jn in joints}
    _actuate(mj, m, joints, velocity, guesses)
    vectors = _add_sites(mj, arms)
    _exclude_touching(mj, m, _start_pose(m, joints), guesses)
    if len(arms) == 1:
        _face_forward(mj, m, d, arms[0], guesses)
    flip = len(arms) == 1
    if flip:
        guesses.append(
            "a single arm stands on its base, like the shipped desk arms: human directions are turned half a turn "
            "about the forward axis (retarget_frame_rpy_rad), so a person's hanging arm maps to the arm standing up"
        )
    ET.SubElement(mj, "option", timestep="0.002", integrator="implicitfast")
    comp = mj.find("compiler")
    if comp is not None and comp.get("meshdir"):
        comp.set("meshdir", str(assets))
    try:
        m = mujoco.MjModel.from_xml_string(ET.tostring(mj, encoding="unicode"))
    except ValueError as e:
        raise InputError(
            f"{urdf}: the converted model does not load ({' '.join(str(e).split())}); please report"
        ) from None
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    key = ET.SubElement(ET.SubElement(mj, "keyframe"), "key", name="home")
    model_dir.mkdir(parents=True, exist_ok=True)
    out_yaml.parent.mkdir(parents=True, exist_ok=True)
    model_rel = Path(_relpath(scene_path, out_yaml.parent))

    def write(rest: dict[str, float]) -> None:
        qpos = np.array(m.qpos0, dtype=float)
        for jn, q in rest.items():
            qpos[m.joint(jn).qposadr[0]] = q
        d.qpos[:] = qpos
        mujoco.mj_forward(m, d)
        scene_path.write_text(_scene(m, d, name, mjcf_path.name))  # framed on the robot at rest
        key.set("qpos", " ".join(f"{q:.6g}" for q in qpos))
        key.set("ctrl", " ".join(f"{rest[j]:.6g}" for j in joints))
        if comp is not None and comp.get("meshdir"):
            comp.set("meshdir", "assets")  # meshes travel with the model, relative to it
        ET.indent(mj)
        mjcf_path.write_text(_header(urdf, guesses) + ET.tostring(mj, encoding="unicode") + "\n")
        out_yaml.write_text(
            _yaml(name, urdf, m, joints, rest, velocity, arms, vectors, flip, fixed, guesses, model_rel)
        )

    # Settling the rest pose reads the draft files, so they are written twice: an error or signal in between
    # puts back what was there before (nothing, or what --force would have replaced), never a draft that loads.
    before = {p: p.read_bytes() if p.is_file() else None for p in (scene_path, mjcf_path, out_yaml)}
    try:
        write(_start_pose(m, joints))
        write(_settle_rest(out_yaml, guesses, single_arm=len(arms) == 1))
    except BaseException:
        for path, old in before.items():
            if old is None:
                path.unlink(missing_ok=True)
            else:
                path.write_bytes(old)
        raise
    return UrdfImport(out_yaml, mjcf_path, scene_path, guesses)


# --- URDF text --------------------------------------------------------------------------------------------------


def _resolve_meshes(root: ET.Element, urdf: Path) -> dict[Path, str]:
    """Find every mesh file (``package://PKG/...``: searched above the URDF); point references at the copies."""
    out: dict[Path, str] = {}
    for mesh in root.iter("mesh"):
        ref = mesh.get("filename", "")
        rel = re.sub(r"^(package|file)://", "", ref)
        candidates = [Path(rel)] if Path(rel).is_absolute() else []
        parts = Path(rel).parts
        for base in [urdf.parent, *urdf.parent.parents][:5]:
            candidates += [base / Path(*parts[i:]) for i in range(len(parts))]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise InputError(f"{urdf}: mesh {ref!r} not found next to or above the URDF; put the meshes there")
        if found.suffix.lower() not in (".stl", ".obj", ".msh"):
            raise InputError(f"{urdf}: mesh {found.name}: MuJoCo reads STL and OBJ only; convert it (e.g. meshlab)")
        dst = out.setdefault(found.resolve(), f"{len(out):02d}_{found.name}")
        mesh.set("filename", dst)
    return out


def _keep_visuals(root: ET.Element, guesses: list[str]) -> None:
    """MuJoCo drops URDF visuals by default; keep them (that and a light make the render visible). A link with
    visuals but no collision shape collides with its visual shape, so retargeting can keep it off the desk."""
    promoted = []
    for link in root.iter("link"):
        if link.find("collision") is None and link.find("visual") is not None:
            for vis in link.findall("visual"):
                col = ET.SubElement(link, "collision")
                col.extend(c for c in vis if c.tag in ("origin", "geometry"))
            promoted.append(link.get("name", "?"))
    if promoted:
        guesses.append(f"links {promoted} have no <collision>: their visual shapes collide instead")
    ext = root.find("mujoco")
    if ext is None:
        ext = ET.SubElement(root, "mujoco")
    comp = ext.find("compiler")
    if comp is None:
        comp = ET.SubElement(ext, "compiler")
    comp.set("discardvisual", "false")
    comp.set("strippath", "false")
    comp.set("fusestatic", "false")


def _fix_non_hinges(root: ET.Element, guesses: list[str]) -> list[str]:
    """Continuous joints become hinges limited to one turn; prismatic/planar/floating ones are welded (fixed)."""
    fixed = []
    for j in root.iter("joint"):
        kind, jn = j.get("type"), j.get("name", "?")
        if kind == "continuous":
            j.set("type", "revolute")
            lim = j.find("limit") if j.find("limit") is not None else ET.SubElement(j, "limit")
            lim.set("lower", f"{-math.pi:.9f}")
            lim.set("upper", f"{math.pi:.9f}")
            guesses.append(f"continuous joint {jn!r}: limited to one turn [-pi, pi]")
        elif kind in ("prismatic", "planar", "floating"):
            j.set("type", "fixed")
            fixed.append(jn)
            guesses.append(f"{kind} joint {jn!r} (a gripper finger?) welded in place: robogest drives hinges only")
    return fixed


def _urdf_velocity(root: ET.Element, joint: str) -> float:
    for j in root.iter("joint"):
        if j.get("name") == joint and j.find("limit") is not None:
            v = float(j.find("limit").get("velocity", "0") or 0)
            if v > 0:
                return v
    return DEFAULT_VELOCITY_RAD_S


# --- the model --------------------------------------------------------------------------------------------------


def _actuate(mj: ET.Element, m, joints: list[str], velocity: dict[str, float], guesses: list[str]) -> None:
    """A servo-like position actuator on every hinge; joint damping/armature/friction scaled from its torque."""
    defaulted = []
    acts = ET.SubElement(mj, "actuator")
    for el in mj.iter("joint"):
        jn = el.get("name")
        if jn not in joints:
            continue
        j = m.joint(jn).id
        effort = float(m.jnt_actfrcrange[j][1]) if m.jnt_actfrclimited[j] and m.jnt_actfrcrange[j][1] > 0 else 0.0
        if effort <= 0:
            effort = DEFAULT_EFFORT_NM
            defaulted.append(jn)
        el.set("damping", f"{effort / velocity[jn]:.4g}")  # back-EMF: no-load speed = the URDF's velocity limit
        el.set("armature", f"{0.006 * effort / DEFAULT_EFFORT_NM:.4g}")  # the STS3215's rotor inertia, torque-scaled
        el.set("frictionloss", f"{0.02 * effort:.4g}")
        el.set("limited", "true")
        lo, hi = m.jnt_range[j]
        ET.SubElement(
            acts,
            "position",
            name=jn,
            joint=jn,
            kp=f"{effort / 0.1:.4g}",
            kv=f"{0.07 * effort:.4g}",
            ctrlrange=f"{lo:.10g} {hi:.10g}",
            forcerange=f"{-effort:.4g} {effort:.4g}",
        )
    if defaulted:
        guesses.append(f"joints {defaulted} have no <limit effort>: sized as an STS3215 ({DEFAULT_EFFORT_NM} N*m)")


def _start_pose(m, joints: list[str]) -> dict[str, float]:
    """Joint zero where it lies well inside the range, else the range's middle: where the rest search starts."""
    rest = {}
    for jn in joints:
        lo, hi = m.jnt_range[m.joint(jn).id]
        margin = min(0.1, 0.25 * (hi - lo))
        rest[jn] = 0.0 if lo + margin <= 0.0 <= hi - margin else round(0.5 * (lo + hi), 4)
    return rest


def _exclude_touching(mj: ET.Element, m, pose: dict[str, float], guesses: list[str]) -> None:
    """Parts that already overlap in the start pose (meshes meeting at a servo horn, two links away) are a modelling
    artefact, not a collision to avoid: exclude those body pairs from contact, and the fixed base from the links its
    joints turn."""
    import mujoco

    d = mujoco.MjData(m)
    for jn, q in pose.items():
        d.qpos[m.joint(jn).qposadr[0]] = q
    mujoco.mj_forward(m, d)
    robot = m.body_rootid[m.geom_bodyid] != 0
    pairs = sorted(
        {
            tuple(sorted((m.body(m.geom_bodyid[c.geom1]).name, m.body(m.geom_bodyid[c.geom2]).name)))
            for c in d.contact[: d.ncon]
            if robot[c.geom1] and robot[c.geom2] and c.dist < 0
        }
    )
    # MuJoCo skips contacts between a body and its parent, but not when the parent is welded to the world (a URDF's
    # fixed base link): the base and the link its first joint turns touch at that joint, as every other pair does
    joined = {
        (m.body(int(m.body_parentid[b])).name, m.body(b).name)
        for b in range(1, m.nbody)
        if m.body_parentid[b] > 0 and m.body_weldid[m.body_parentid[b]] == 0 and m.body_jntnum[b] > 0
    }
    if pairs:
        guesses.append(f"body pairs {pairs} overlap at joint zero: their contacts are excluded (<contact><exclude>)")
    if pairs or joined:
        contact = ET.SubElement(mj, "contact")
        for a, b in sorted(set(pairs) | joined):
            ET.SubElement(contact, "exclude", body1=a, body2=b)


def _settle_rest(yaml_path: Path, guesses: list[str], single_arm: bool) -> dict[str, float]:
    """The rest pose: the robot's retargeted image of a person standing with arms hanging (collision-free, inside
    the limits by a margin), so the robot rests where the gestures start and end. A single arm copies an arm hanging
    straight down (not held a little out to the side, as a humanoid's must be), so its base faces forward."""
    from robogest.generators.poses import REST, dofs_to_rotations, pose
    from robogest.motion.human_motion import HumanMotion
    from robogest.retarget import DirectionIK
    from robogest.robot.config import load_robot_config

    robot = load_robot_config(yaml_path)
    frames = np.tile(pose(both_flex=0.05, both_elbow=0.25) if single_arm else REST, (40, 1))
    motion = HumanMotion(20.0, dofs_to_rotations(frames), np.tile([0.0, 1.0, 0.0], (len(frames), 1)))
    # a firm pull to the start pose keeps the joints the vectors hardly need (a wrist roll, a gripper) where they are
    q = DirectionIK(robot, iterations=30, rest_weight=0.02).retarget(motion, q0=robot.rest_q_rad).q_rad[-1]
    margin = np.minimum(0.05, 0.25 * (robot.q_max_rad - robot.q_min_rad))
    q = np.clip(np.round(q, 3), robot.q_min_rad + margin, robot.q_max_rad - margin)
    guesses.append(
        "rest pose = the arm's image of a person standing at rest ("
        + ", ".join(f"{n} {v:+.2f}" for n, v in zip(robot.joint_names, q, strict=True))
        + " rad); set rest_rad and the MJCF's home key together"
    )
    return dict(zip(robot.joint_names, (float(v) for v in q), strict=True))


def _face_forward(mj: ET.Element, m, d, arm: _Arm, guesses: list[str]) -> None:
    """robogest robots face +X: turn the whole robot about Z when its arm reaches sideways at joint zero."""

    def world(role: str) -> np.ndarray:
        body, pos = arm.points[role]
        b = m.body(body).id
        return d.xpos[b] + d.xmat[b].reshape(3, 3) @ pos

    v = world("hand") - world("shoulder")
    if np.linalg.norm(v[:2]) < 0.5 * np.linalg.norm(v):
        return  # the arm stands up at zero: nothing says where its front is
    yaw = math.atan2(v[1], v[0])
    if abs(yaw) < 0.05:
        return
    c, s = math.cos(-yaw / 2), math.sin(-yaw / 2)
    rz = np.array([[math.cos(-yaw), -math.sin(-yaw), 0], [math.sin(-yaw), math.cos(-yaw), 0], [0, 0, 1]])
    for body in mj.find("worldbody").findall("body"):
        pos = np.array([float(x) for x in body.get("pos", "0 0 0").split()])
        w, x, y, z = (float(t) for t in body.get("quat", "1 0 0 0").split())
        quat = [c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w]  # (about Z by -yaw) * quat
        body.set("pos", " ".join(f"{t:.6g}" for t in rz @ pos))
        body.set("quat", " ".join(f"{t:.6g}" for t in quat))
    guesses.append(f"the arm reaches {math.degrees(yaw):+.0f} deg from +X at joint zero: turned to face +X")


def _chain(m, body: int, joints: set[int]) -> list[int]:
    """Actuated joints from the root down to ``body``, root first."""
    out = []
    while body > 0:
        out += [j for j in range(m.body_jntadr[body], m.body_jntadr[body] + m.body_jntnum[body]) if j in joints][::-1]
        body = int(m.body_parentid[body])
    return out[::-1]


def _find_arms(m, d, joints: list[str], guesses: list[str]) -> list[_Arm]:
    """Chains from the root to each leaf; an arm is one whose joints reach 2+ distinct points in space."""
    jids = {m.joint(j).id for j in joints}
    leaves = [b for b in range(1, m.nbody) if not any(m.body_parentid[c] == b for c in range(1, m.nbody))]
    arms: list[_Arm] = []
    for leaf in leaves:
        chain = _chain(m, leaf, jids)
        # points where the chain turns: consecutive joint anchors closer than 1 cm are one point (a 2-DoF shoulder)
        pts: list[tuple[int, np.ndarray]] = []
        for j in chain:
            if not pts or np.linalg.norm(d.xanchor[j] - pts[-1][1]) > 0.01:
                pts.append((j, d.xanchor[j].copy()))
        if len(pts) < 2:
            continue
        names = [m.joint(j).name for j in chain] + [m.body(leaf).name]
        side = next((s for s, pat in _SIDE_PATTERNS.items() if any(pat.search(n) for n in names)), "")
        tip = _tip(m, d, leaf, pts[-1][1])
        roles = _roles(m, d, pts, tip, guesses)
        points = {}
        for role, (jid, pos) in roles.items():
            body = int(m.jnt_bodyid[jid]) if jid >= 0 else leaf
            xmat = d.xmat[body].reshape(3, 3)
            points[role] = (m.body(body).name, xmat.T @ (pos - d.xpos[body]))
        arms.append(_Arm(side, [m.joint(j).name for j in chain], points))
    if not arms:
        return []
    sides = {a.side for a in arms}
    if len(arms) == 1 or not sides >= {"l", "r"}:
        arm = max(arms, key=lambda a: len(a.joints))
        arm.side = "r"
        guesses.append(f"one arm ({arm.joints[0]} ... {arm.joints[-1]}), mapped to the human RIGHT arm")
        return [arm]
    picked = [max((a for a in arms if a.side == s), key=lambda a: len(a.joints)) for s in ("l", "r")]
    guesses.append(f"two arms from the link names: left {picked[0].joints}, right {picked[1].joints}")
    return picked


def _tip(m, d, leaf: int, last: np.ndarray) -> np.ndarray:
    """The end of the last link: its geoms' point farthest from the last joint (the link's origin if it has none)."""
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == leaf]
    best, far = d.xpos[leaf].copy(), float(np.linalg.norm(d.xpos[leaf] - last))
    for g in geoms:
        c = d.geom_xpos[g]
        v = c - last
        n = float(np.linalg.norm(v))
        p = c + v / n * float(np.max(m.geom_size[g])) if n > 1e-9 else c
        if np.linalg.norm(p - last) > far:
            best, far = p, float(np.linalg.norm(p - last))
    return best


#: Words in a joint's name, or in the name of the link it moves, that say which human joint it is.
_ROLE_WORDS = {
    "shoulder": ("shoulder", "upper_arm", "upperarm"),
    "elbow": ("elbow", "forearm", "lower_arm", "lowerarm"),
    "wrist": ("wrist", "hand"),
}


def _roles(
    m, d, pts: list[tuple[int, np.ndarray]], tip: np.ndarray, guesses: list[str]
) -> dict[str, tuple[int, np.ndarray]]:
    """shoulder / elbow / wrist among the chain's points (by joint or link name if they say, else by order), hand at
    the tip."""
    names = [f"{m.joint(j).name} {m.body(m.jnt_bodyid[j]).name}".lower() for j, _ in pts]

    def said(role: str, i: int) -> bool:
        return any(w in names[i] for w in _ROLE_WORDS[role])

    roles: dict[str, tuple[int, np.ndarray]] = {}
    # the last point called a shoulder (a shoulder_pan turns the base below the shoulder_lift), the first elbow/wrist
    by_name = {r: next((i for i in range(len(names)) if said(r, i)), None) for r in ("elbow", "wrist")}
    by_name["shoulder"] = next((i for i in reversed(range(len(names))) if said("shoulder", i)), None)
    if by_name["shoulder"] is not None and by_name["elbow"] is not None and by_name["shoulder"] < by_name["elbow"]:
        if by_name["wrist"] is not None and by_name["wrist"] <= by_name["elbow"]:
            by_name["wrist"] = None
        roles = {r: pts[i] for r, i in by_name.items() if i is not None}
        how = "from the joint and link names"
    else:
        # a base turning about the vertical sits below the shoulder: skip it when more points follow
        first = 1 if len(pts) >= 3 and abs(d.xaxis[pts[0][0]][2]) > 0.9 else 0
        rest = pts[first:]
        for r, p in zip(("shoulder", "elbow", "wrist"), rest, strict=False):
            roles[r] = p
        how = "from the chain's order (base yaw skipped)" if first else "from the chain's order"
    roles["hand"] = (-1, tip)
    guesses.append(
        "sites "
        + ", ".join(
            f"{r}_site at joint {m.joint(roles[r][0]).name!r}" for r in ("shoulder", "elbow", "wrist") if r in roles
        )
        + f", hand_site at the end of the last link ({how})"
    )
    return roles


def _add_sites(mj: ET.Element, arms: list[_Arm]) -> list[tuple[str, str, str, str, float]]:
    """Sites on the bodies; the retarget vectors (human from, human to, site from, site to, weight) between them."""
    bodies = {b.get("name"): b for b in mj.iter("body")}
    world = mj.find("worldbody")
    vectors = []
    for arm in arms:
        prefix = f"{arm.side}_" if len(arms) > 1 else ""
        for role, (body, pos) in arm.points.items():
            parent = bodies.get(body, world)
            site = ET.Element(
                "site", name=f"{prefix}{role}_site", pos=" ".join(f"{x:.5g}" for x in pos), size="0.006", group="5"
            )
            parent.insert(0, site)
        roles = [r for r in ("shoulder", "elbow", "wrist", "hand") if r in arm.points]
        for a, b in itertools.pairwise(roles):
            vectors.append(
                (
                    f"{arm.side}_{a}",
                    f"{arm.side}_{b}",
                    f"{prefix}{a}_site",
                    f"{prefix}{b}_site",
                    0.5 if b == "hand" else 1.0,
                )
            )
    return vectors


# --- output files -----------------------------------------------------------------------------------------------


def _relpath(path: Path, start: Path) -> str:
    import os

    return os.path.relpath(path.resolve(), start.resolve())


def _header(urdf: Path, guesses: list[str]) -> str:
    lines = "\n".join(f"  - {g}" for g in guesses)
    return (
        f"<!--\n  Written by `robogest robots import-urdf` from {urdf.name}. Guessed (edit to taste):\n{lines}\n"
        "  Actuators: servo-like position control sized from each joint's <limit effort velocity>.\n-->\n"
    )


def _scene(m, d, name: str, robot_file: str) -> str:
    """Floor under the robot's lowest point, a light, a skybox and the front camera framing the robot."""
    if m.ngeom:  # world-axis bounding box of every geom: its local box turned by the geom's orientation
        rot = d.geom_xmat.reshape(-1, 3, 3)
        centre = d.geom_xpos + np.einsum("gij,gj->gi", rot, m.geom_aabb[:, :3])
        half = np.einsum("gij,gj->gi", np.abs(rot), m.geom_aabb[:, 3:])
        lo, hi = (centre - half).min(axis=0), (centre + half).max(axis=0)
    else:
        lo, hi = np.zeros(3), np.zeros(3)
    floor = min(0.0, float(lo[2]))
    centre = 0.5 * (lo + hi)
    size = float(max(np.linalg.norm(hi - lo), 0.2))
    pos = centre + size * np.array([1.1, -0.8, 0.55])
    f = centre - pos
    f /= np.linalg.norm(f)
    x = np.cross(f, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, f)

    def v(a) -> str:
        return " ".join(f"{t:.4g}" for t in a)

    light = centre + size * np.array([0.6, 0.4, 2.0])
    return f"""<!-- Scene for {name}: floor, light, skybox, "front" camera (written by robogest robots import-urdf). -->
<mujoco model="{name} scene">
  <include file="{robot_file}"/>
  <statistic center="{v(centre)}" extent="{size:.3g}"/>
  <visual>
    <headlight diffuse="0.5 0.5 0.5" ambient="0.3 0.3 0.3" specular="0 0 0"/>
    <global azimuth="150" elevation="-20" offwidth="1280" offheight="960"/>
    <quality shadowsize="1024" offsamples="2"/>
  </visual>
  <asset>
    <texture type="skybox" builtin="gradient" rgb1="0.3 0.5 0.7" rgb2="0 0 0" width="256" height="256"/>
    <texture type="2d" name="floor" builtin="checker" mark="edge" rgb1="0.45 0.35 0.25" rgb2="0.4 0.3 0.2"
             markrgb="0.6 0.5 0.4" width="300" height="300"/>
    <material name="floor" texture="floor" texuniform="true" texrepeat="8 8"/>
  </asset>
  <worldbody>
    <light pos="{v(light)}" dir="-0.3 -0.2 -1" directional="true" diffuse="0.6 0.6 0.6"/>
    <geom name="floor" type="plane" size="0 0 0.05" pos="0 0 {floor:.4g}" material="floor"/>
    <camera name="front" pos="{v(pos)}" xyaxes="{v(x)} {v(y)}" fovy="45"/>
  </worldbody>
</mujoco>
"""


def _yaml(name, urdf, m, joints, rest, velocity, arms, vectors, flip, fixed, guesses, model) -> str:
    rows = []
    for jn in joints:
        lo, hi = m.jnt_range[m.joint(jn).id]
        v = round(VELOCITY_SHARE * velocity[jn], 2)
        rows.append(
            f"  - {{name: {jn}, lower_rad: {lo:.10g}, upper_rad: {hi:.10g}, max_velocity_rad_s: {v:g}, "
            f"max_acceleration_rad_s2: {ACCELERATION_RAD_S2:g}, rest_rad: {rest[jn]:.6g}}}"
        )
    vecs = [
        f"  - {{human: [{h0}, {h1}], robot: [{s0}, {s1}]" + (f", weight: {w:g}}}" if w != 1 else "}")
        for h0, h1, s0, s1, w in vectors
    ]
    unmapped = [j for j in joints if not any(j in a.joints for a in arms)]
    notes = "\n".join(f"#   - {g}" for g in guesses)
    frame = "retarget_frame_rpy_rad: [3.141592653589793, 0.0, 0.0]\n" if flip else ""
    servos = "\n".join(f"#     {jn}: {{id: {i + 1}, model: STS3215}}" for i, jn in enumerate(joints))
    return f"""# {name}: imported from {urdf.name} by `robogest robots import-urdf`. Check it with
# `robogest robots validate {name}` after every edit.
#
# Guessed (edit to taste; the MJCF's home keyframe must equal rest_rad):
{notes}
# Velocity limits: {VELOCITY_SHARE:.0%} of the URDF's; accelerations {
        ACCELERATION_RAD_S2:g} rad/s^2 (gentle for small servos).
# Joints no retarget vector moves ({", ".join(unmapped) or "none"}) hold their rest pose.{
        chr(10) + "# Welded (not driven): " + ", ".join(fixed) if fixed else ""
    }
name: {name}
description: imported from {urdf.name}
model: {model.as_posix()}
joints:
{chr(10).join(rows)}
{frame}retarget:
{chr(10).join(vecs)}
# To drive real servos, add a bus section (ids, models, offsets; see the shipped robots), e.g.:
# bus:
#   family: feetech
#   protocol: 0
#   servos:
{servos}
"""
