"""``robogest robots import``: a URDF, xacro or MJCF description becomes a robogest robot (an MJCF with sites,
servos, a home keyframe and a scene, and a YAML with held joints and a retargeting proposal) in one step."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.fileio import write_error
from robogest.tools.importer import model as mdl
from robogest.tools.importer.description import Description, confined, read_description
from robogest.tools.importer.meshes import stage_meshes
from robogest.tools.importer.parts import Parts, find_parts
from robogest.tools.importer.write import Staging, YamlParts, check_replaceable, yaml_text

if TYPE_CHECKING:
    import mujoco

#: Human pose the rest search copies: arms hanging, elbows a little bent (a single desk arm: straight down).
REST_ITERATIONS = 30


@dataclass
class ImportResult:
    """What :func:`import_description` wrote and what it guessed (one sentence each)."""

    yaml_path: Path
    mjcf_path: Path
    scene_path: Path
    parts: Parts | None = None
    guesses: list[str] = field(default_factory=list)


def model_folder(out_yaml: Path, name: str) -> Path:
    """``sim/NAME/`` beside a ``robots/`` folder, else ``NAME/`` beside the YAML."""
    return (out_yaml.parent.parent / "sim" / name) if out_yaml.parent.name == "robots" else (out_yaml.parent / name)


def previous_overrides(out_yaml: Path) -> dict:
    """The overrides an earlier import recorded in ``out_yaml`` (importing again keeps them)."""
    from robogest.fileio import load_yaml, read_text_capped

    if not out_yaml.is_file():
        return {}
    try:
        raw = load_yaml(read_text_capped(out_yaml, what="robot file"))
    except Exception:  # an unreadable old file is replaced, not consulted
        return {}
    rec = raw.get("import") if isinstance(raw, dict) else None
    return {k: rec[k] for k in ("arms", "head", "hold", "forward") if rec.get(k)} if isinstance(rec, dict) else {}


def import_description(
    src: str | Path,
    out_yaml: str | Path,
    name: str | None = None,
    overwrite: bool = False,
    overrides: dict | None = None,
    search_paths: Sequence[Path] = (),
) -> ImportResult:
    """Import ``src`` (URDF, xacro or MJCF) as the robot ``out_yaml``; nothing is left on disk if it fails.

    ``overrides``: ``arms`` ({"left": [joints], "right": [...]}), ``head`` ([joints]), ``hold`` ({joint: rad}),
    ``forward`` ("+x", "-x", "+y", "-y"); missing keys come from the ``import:`` record of an existing
    ``out_yaml``. Raises InputError (bad description, outputs that exist without ``overwrite``),
    MissingDependencyError (xacro or DAE without the import extra).
    """
    src, out_yaml = Path(src), Path(out_yaml)
    name = name or out_yaml.stem
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise InputError(f"robot name {name!r}: use letters, digits, '_', '-' or '.' (it names files)")
    model_dir = model_folder(out_yaml, name)
    check_replaceable(model_dir, out_yaml, name, overwrite)
    overrides = {**previous_overrides(out_yaml), **(overrides or {})}
    desc = read_description(src, search_paths)
    if desc.kind == "mjcf":
        _mjcf_includes(desc)
    staging = Staging(model_dir, out_yaml)
    try:
        return _build(desc, name, out_yaml, model_dir, staging, overrides)
    except OSError as e:  # reads are InputErrors already: this is a write (a full disk)
        staging.abort()
        raise write_error(model_dir, e) from None
    except BaseException:
        staging.abort()
        raise


def _build(
    desc: Description, name: str, out_yaml: Path, model_dir: Path, staging: Staging, overrides: dict
) -> ImportResult:
    """The import's steps, in order: the model compiled with named, limited hinges; its parts found; sites,
    servos, contact exclusions; turned to face +X and stood on the floor; then the draft written, the rest pose
    settled with its IK, and the final files published."""
    guesses = desc.warnings
    assets = staging.dir / "assets"
    stage_meshes(desc, assets)
    mj, keyframe = _model_tree(desc, assets)
    floating = mdl.weld_free_joints(mj) or desc.floating
    for old in mj.findall("keyframe"):
        mj.remove(old)
    m, joints = _hinged_model(mj, desc, guesses)
    start = mdl.start_pose(m, joints, keyframe)
    start.update({j: float(q) for j, q in (overrides.get("hold") or {}).items() if j in start})
    parts = _parts(m, start, joints, overrides, desc, guesses)
    vectors = mdl.add_sites(mj, [*parts.arms, *([parts.head] if parts.head else [])])
    velocity = _velocities(desc, joints)
    m = _servos(mj, m, desc, joints, velocity, guesses)
    has_legs = any(v == "leg" for v in parts.held.values())
    m = _stand(mj, m, desc, parts, start, floating or has_legs, guesses)
    flip = len(parts.arms) == 1 and parts.head is None and not has_legs
    if flip:
        guesses.append("a single arm stands on its base, like the shipped desk arms: human directions are turned "
                       "half a turn about the forward axis (retarget_frame_rpy_rad)")  # fmt: skip
    ranges = {jn: _range(m, jn) for jn in joints}
    yml = YamlParts(name, desc.path.name, "", joints, ranges, velocity, start, parts.held, vectors,
                    _import_record(desc, parts, overrides), desc.servo_models, guesses, flip)  # fmt: skip
    out = _Outputs(mj, m, desc, staging, yml)
    draft = staging.dir / f"{name}.draft.yaml"
    out.write(start, draft, out.scene_path.name)
    rest = _settle_rest(draft, parts, start, single_arm=flip)
    guesses.append("rest pose = the robot's image of a person standing at rest, arms hanging, elbows a little bent")
    draft.unlink()
    final = out.write(rest, out_yaml, _rel(model_dir / "scene.xml", out_yaml.parent))
    staging.publish(final)
    return ImportResult(out_yaml, model_dir / f"{name}.xml", model_dir / "scene.xml", parts, guesses)


def _model_tree(desc: Description, assets: Path) -> tuple[ET.Element, dict[str, float]]:
    """The description as an MJCF tree reading its meshes from ``assets`` (a URDF converted by MuJoCo, an MJCF
    normalised), and the joint angles of an MJCF's standing keyframe (empty for a URDF)."""
    if desc.kind == "urdf":
        return mdl.urdf_to_mjcf(desc.root, str(assets), desc.path), {}
    mj = desc.root
    comp = mdl.child(mj, "compiler")
    for k in ("assetdir", "meshdir", "texturedir"):
        comp.attrib.pop(k, None)
    comp.set("meshdir", str(assets))
    comp.set("texturedir", str(assets))
    mj = mdl.normalise_mjcf(mj, desc.path)
    return mj, _standing_keyframe(mj, desc)


def _hinged_model(mj: ET.Element, desc: Description, guesses: list[str]) -> tuple[mujoco.MjModel, list[str]]:
    """The model compiled (millimetre meshes scaled), every joint named and every hinge limited (one turn where
    it had no range), and its hinge joints' names; InputError if it has none."""
    import mujoco

    m = mdl.compile_xml(mj, desc.path)
    if mdl.fix_millimetres(mj, m, guesses):
        m = mdl.compile_xml(mj, desc.path)
    for i, el in enumerate(x for x in mdl.child(mj, "worldbody").iter("joint") if not x.get("name")):
        el.set("name", f"joint_{i}")
    m = mdl.compile_xml(mj, desc.path)
    hinges = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    joints = [m.joint(j).name for j in hinges]
    if not joints:
        raise InputError(f"{desc.path}: no revolute or continuous joints; robogest drives hinge joints")
    unlimited = [m.joint(j).name for j in hinges if not m.jnt_limited[j]]
    for el in (x for x in mdl.child(mj, "worldbody").iter("joint") if x.get("name") in unlimited):
        el.set("range", f"{-math.pi:.9f} {math.pi:.9f}")  # one turn, as a URDF continuous joint gets
        el.set("limited", "true")
    if unlimited:
        guesses.append(f"{len(unlimited)} hinges have no range (e.g. {unlimited[0]!r}): limited to one turn [-pi, pi]")
    return mdl.compile_xml(mj, desc.path), joints


def _parts(
    m: mujoco.MjModel,
    start: dict[str, float],
    joints: list[str],
    overrides: dict,
    desc: Description,
    guesses: list[str],
) -> Parts:
    """The robot's parts at the start pose (:func:`find_parts`, its errors naming the description), each told in
    ``guesses``."""
    try:
        parts = find_parts(m, mdl.pose_data(m, start), joints, overrides)
    except InputError as e:
        raise InputError(f"{desc.path}: {e}") from None
    for part, js, why in parts.rows:
        guesses.append(f"{part}: {', '.join(js)} ({why})")
    if len(parts.arms) == 1:
        guesses.append(f"one arm ({parts.arms[0].joints[0]} ... {parts.arms[0].joints[-1]}), mapped to the human "
                       "RIGHT arm")  # fmt: skip
    return parts


def _servos(
    mj: ET.Element,
    m: mujoco.MjModel,
    desc: Description,
    joints: list[str],
    velocity: dict[str, float],
    guesses: list[str],
) -> mujoco.MjModel:
    """An MJCF's own position servos kept when each hinge has one, else servo-like ones for every hinge; the
    model recompiled."""
    if desc.kind == "mjcf" and mdl.own_position_actuators(m, joints):
        mdl.adopt_actuators(mj, m, joints, guesses)
    else:
        if desc.kind == "mjcf":
            guesses.append("the model's actuators are not one position servo per hinge: replaced by servo-like ones")
        mdl.actuate(mj, m, joints, velocity, guesses)
    return mdl.compile_xml(mj, desc.path)


def _stand(
    mj: ET.Element,
    m: mujoco.MjModel,
    desc: Description,
    parts: Parts,
    start: dict[str, float],
    on_floor: bool,
    guesses: list[str],
) -> mujoco.MjModel:
    """Contacts excluded between parts that touch at the start pose; the robot turned to face +X and, when it
    stands (``on_floor``: a floating base or legs), raised so that its lowest point touches the floor; a
    simulation option if it has none. The model recompiled."""
    mdl.exclude_touching(mj, m, start, guesses)
    yaw = math.atan2(parts.forward[1], parts.forward[0])
    lift = -mdl.lowest_point(m, mdl.pose_data(m, start)) if on_floor else 0.0
    mdl.turn_and_stand(mj, yaw, lift)
    if abs(yaw) > 1e-6:
        guesses.append(f"the robot faces {parts.forward_reason}: turned {math.degrees(-yaw):+.0f} deg about Z to "
                       "face +X (override with --forward +x|-x|+y|-y)")  # fmt: skip
    else:
        guesses.append(f"the robot faces {parts.forward_reason} (override with --forward +x|-x|+y|-y)")
    if abs(lift) > 1e-6:
        guesses.append(f"stands with its lowest point on the floor (raised {lift:+.3f} m)")
    if mj.find("option") is None:
        ET.SubElement(mj, "option", timestep="0.002", integrator="implicitfast")
    return mdl.compile_xml(mj, desc.path)


def _range(m: mujoco.MjModel, joint: str) -> tuple[float, float]:
    lo, hi = (float(x) for x in m.jnt_range[m.joint(joint).id])
    return lo, hi


def _import_record(desc: Description, parts: Parts, overrides: dict) -> dict[str, object]:
    """The YAML's ``import:`` record: the source and the overrides that importing again keeps (empty ones left
    out)."""
    arms = {a.part.split()[0]: a.joints for a in parts.arms if a.part in ("left arm", "right arm")}
    record: dict[str, object] = {
        "source": str(desc.path.resolve()),
        "arms": arms,
        "head": parts.head.joints if parts.head else [],
        "hold": {j: float(q) for j, q in (overrides.get("hold") or {}).items()},
        "forward": overrides.get("forward"),
    }
    return {k: v for k, v in record.items() if v}


@dataclass
class _Outputs:
    """The files an import writes for a rest pose: the scene, the MJCF with its ``home`` keyframe, the YAML."""

    mj: ET.Element
    m: mujoco.MjModel
    desc: Description
    staging: Staging
    yml: YamlParts  # its model and rest are set by each write

    def __post_init__(self) -> None:
        self.mjcf_path = self.staging.dir / f"{self.yml.name}.xml"
        self.scene_path = self.staging.dir / "scene.xml"
        self.key = ET.SubElement(ET.SubElement(self.mj, "keyframe"), "key", name="home")

    def write(self, rest: dict[str, float], yaml_path: Path, model_rel: str) -> str:
        """Scene and MJCF (keyframe ``home`` at ``rest``) into the staging folder; the YAML text (naming the scene
        as ``model_rel``) also there when ``yaml_path`` is in it (the draft). Returns the YAML text."""
        m = self.m
        d = mdl.pose_data(m, rest)
        self.scene_path.write_text(mdl.scene(m, d, self.yml.name, self.mjcf_path.name))
        self.key.set("qpos", " ".join(f"{q:.6g}" for q in d.qpos))
        self.key.set("ctrl", " ".join(f"{rest[m.joint(m.actuator_trnid[a, 0]).name]:.6g}" for a in range(m.nu)))
        comp = mdl.child(self.mj, "compiler")
        comp.set("meshdir", "assets")
        comp.set("texturedir", "assets")
        ET.indent(self.mj)
        text = ET.tostring(self.mj, encoding="unicode")
        self.mjcf_path.write_text(mdl.header(self.desc.path.name, self.yml.guesses) + text + "\n")
        text = yaml_text(dataclasses.replace(self.yml, model=model_rel, rest=rest))
        if yaml_path.parent == self.staging.dir:
            yaml_path.write_text(text)
        return text


def _rel(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()


def _velocities(desc: Description, joints: list[str]) -> dict[str, float]:
    """Each joint's velocity limit: the URDF's ``<limit velocity>``, else an STS3215's."""
    out = dict.fromkeys(joints, mdl.DEFAULT_VELOCITY_RAD_S)
    if desc.kind == "urdf":
        for j in desc.root.iter("joint"):
            lim, name = j.find("limit"), j.get("name")
            if name in out and lim is not None:
                try:
                    v = float(lim.get("velocity", "0"))
                except ValueError:
                    continue
                if math.isfinite(v) and v > 0:
                    out[name] = v
    return out


def _mjcf_includes(desc: Description) -> None:
    """A menagerie ``scene.xml`` names the robot with ``<include file="robot.xml">``: import that file instead (the
    scene is written anew); other includes are inlined, each confined to the description's tree."""
    from robogest.fileio import read_text_capped

    root, base = desc.root, desc.path.resolve().parent
    incs = [el for el in root.iter("include")]
    world = root.find("worldbody")
    if incs and world is not None and not any(b.tag == "body" for b in world):
        target = confined(base / incs[0].get("file", ""), desc.roots, "included file", desc.path)
        desc.warnings.append(f"{desc.path.name} is a scene: the robot is read from {target.name}")
        desc.path = target
        desc.root = ET.fromstring(read_text_capped(target, what="MJCF include"))
        root, base = desc.root, target.parent
    _drop_scene_contacts(desc)
    for _ in range(8):
        parents = [(p, el) for p in root.iter() for el in list(p) if el.tag == "include"]
        if not parents:
            break
        for parent, el in parents:
            path = confined(base / el.get("file", ""), desc.roots, "included file", desc.path)
            inc = ET.fromstring(read_text_capped(path, what="MJCF include"))
            i = list(parent).index(el)
            parent.remove(el)
            for k, child in enumerate(list(inc)):
                parent.insert(i + k, child)


def _drop_scene_contacts(desc: Description) -> None:
    """Contact pairs naming geoms the robot file lacks (its scene's floor) go with the scene."""
    geoms = {g.get("name") for g in desc.root.iter("geom")}
    bodies = {b.get("name") for b in desc.root.iter("body")}
    dropped = 0
    for contact in desc.root.findall("contact"):
        for el in list(contact):
            names = [(el.get(k), geoms) for k in ("geom1", "geom2")] + [(el.get(k), bodies) for k in ("body1", "body2")]
            if any(n is not None and n not in known for n, known in names):
                contact.remove(el)
                dropped += 1
    if dropped:
        desc.warnings.append(f"{dropped} contact pairs with the scene (its floor) dropped: the scene is written anew")


def _standing_keyframe(mj: ET.Element, desc: Description) -> dict[str, float]:
    """Joint angles of the model's standing keyframe (``home``, ``stand``..., else its first), by joint name."""
    keys = [(k, q) for kf in mj.findall("keyframe") for k in kf.findall("key") if (q := k.get("qpos"))]
    if not keys:
        return {}
    key, text = next(
        ((k, q) for k, q in keys if re.search(r"home|stand|init|default", k.get("name", ""), re.I)), keys[0]
    )
    m = mdl.compile_xml(mj, desc.path)
    qpos = [float(x) for x in text.split()]
    if len(qpos) != m.nq:
        return {}
    import mujoco

    desc.warnings.append(f"held joints stand as in the model's keyframe {key.get('name', '(first)')!r}")
    return {
        m.joint(j).name: qpos[m.jnt_qposadr[j]] for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
    }


def _settle_rest(yaml_path: Path, parts: Parts, start: dict[str, float], single_arm: bool) -> dict[str, float]:
    """The rest pose: the robot's retargeted image of a person standing with arms hanging (collision-free, inside
    the limits by a margin), held joints where they stand. A single desk arm copies an arm hanging straight down.

    An arm whose elbow bends sideways at joint zero needs its upper-arm twist turned a quarter turn before the
    elbow can bend forward; the IK cannot find that from zero (the twist does nothing while the arm is straight),
    so it also starts from the twist at +-pi/2, and each arm keeps the start that copies the person best."""
    from robogest.generators.poses import REST, dofs_to_rotations, pose
    from robogest.motion.human_motion import HumanMotion
    from robogest.retarget import DirectionIK
    from robogest.robot.config import load_robot_config

    robot = load_robot_config(yaml_path)
    ik = DirectionIK(robot, iterations=REST_ITERATIONS, rest_weight=0.02)
    index = {n: i for i, n in enumerate(robot.joint_names)}
    q = robot.rest_q_rad.copy()
    for arm in parts.arms:
        joints = [index[j] for j in arm.joints]
        sites = {s for role in arm.points for s in (f"{role}_site", f"l_{role}_site", f"r_{role}_site")}
        vecs = [k for k, v in enumerate(robot.retarget) if v.robot[0] in sites and v.robot[1] in sites
                and v.human[0][0] == ("l" if arm.part.startswith("left") else "r")]  # fmt: skip
        best: np.ndarray | None = None
        best_err = np.inf
        # arms held a little further out where hanging closer would touch the body (a hand on a hip gear)
        for abd in (0.0, 0.15, 0.3):
            human = pose(both_flex=0.05, both_elbow=0.25) if single_arm else REST + pose(both_abd=abd)
            motion = HumanMotion(20.0, dofs_to_rotations(np.tile(human, (20, 1))), np.tile([0.0, 1.0, 0.0], (20, 1)))
            for turn in [0.0] + ([np.pi / 2, -np.pi / 2] if arm.twists else []):
                q0 = robot.rest_q_rad.copy()
                if turn:
                    k = index[arm.twists[0]]
                    q0[k] = np.clip(q0[k] + turn, robot.q_min_rad[k], robot.q_max_rad[k])
                res = ik.retarget(motion, q0=q0)
                err = float(res.direction_error_rad[-1][vecs].sum()) if vecs else 0.0
                err += 10.0 * ik.in_collision(res.q_rad[-1])  # a rest pose touching itself is a last resort
                if err < best_err - 1e-3:
                    best, best_err = res.q_rad[-1], err
            if best_err < 10.0 or single_arm:
                break
        assert best is not None  # the first try's error (direction errors, a collision flag) is finite
        q[joints] = best[joints]
        if parts.head is not None and arm is parts.arms[0]:
            head = [index[j] for j in parts.head.joints]
            q[head] = best[head]
    margin = np.minimum(0.05, 0.25 * (robot.q_max_rad - robot.q_min_rad))
    q = np.clip(np.round(q, 3), robot.q_min_rad + margin, robot.q_max_rad - margin)
    rest = dict(zip(robot.joint_names, (float(v) for v in q), strict=True))
    rest.update({j: start[j] for j in parts.held})  # held joints stand where they are
    return rest
