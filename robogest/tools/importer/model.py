"""The robot's MJCF, built from a description: compiled by MuJoCo, then given what robogest needs and a
description lacks: servo-like position actuators, sites for the retargeting vectors, contact exclusions for parts
that touch by construction, the front facing +X, the feet on the floor, a ``home`` keyframe and a lit scene.

Actuators are modelled like the shipped servos: force clipped at the joint's ``effort`` (its stall torque),
``kp = effort / 0.1 rad``, back-EMF damping ``effort / velocity`` (so the no-load speed is the description's
velocity), armature and friction scaled from the STS3215's.
"""

from __future__ import annotations

import itertools
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError

if TYPE_CHECKING:
    import mujoco

    from robogest.tools.importer.parts import Limb

#: Servo model the actuators are scaled from when the description gives no effort/velocity: STS3215 at 12 V.
DEFAULT_EFFORT_NM = 2.94
DEFAULT_VELOCITY_RAD_S = 4.72
#: A mesh whose extent is larger than this is in millimetres (no servo robot's part is 3 m long).
MM_EXTENT_M = 3.0


def child(el: ET.Element, tag: str) -> ET.Element:
    """``el``'s first ``<tag>`` child, added if it has none (the additions go into the existing one)."""
    found = el.find(tag)
    return found if found is not None else ET.SubElement(el, tag)


def compile_xml(mj: ET.Element, source: object) -> mujoco.MjModel:
    """The MjModel of an MJCF tree; MuJoCo's complaint as one InputError line naming the description."""
    import mujoco

    try:
        return mujoco.MjModel.from_xml_string(ET.tostring(mj, encoding="unicode"))
    except ValueError as e:
        raise InputError(f"{source}: MuJoCo cannot load it: {' '.join(str(e).split())}") from None


def urdf_to_mjcf(root: ET.Element, meshdir: str, source: object) -> ET.Element:
    """MuJoCo's URDF reader, keeping the visuals (a link with visuals but no collision collides with them)."""
    for link in root.iter("link"):
        if link.find("collision") is None and link.find("visual") is not None:
            for vis in link.findall("visual"):
                col = ET.SubElement(link, "collision")
                col.extend(c for c in vis if c.tag in ("origin", "geometry"))
    comp = child(child(root, "mujoco"), "compiler")
    comp.attrib.update(discardvisual="false", strippath="false", fusestatic="false", meshdir=meshdir)
    return normalise_mjcf(root, source)


def normalise_mjcf(mj: ET.Element, source: object) -> ET.Element:
    """The model (MJCF, or a URDF with its ``<mujoco>`` extension) as MuJoCo writes it back as MJCF: angles in
    radians (an MJCF's default unit is degrees, and the ranges, sites and keyframe added here are radians),
    orientations as quaternions, nothing left to a ``<compiler>`` setting that would read the additions
    differently."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_string(ET.tostring(mj, encoding="unicode"))
        spec.compile()
        return ET.fromstring(spec.to_xml())
    except ValueError as e:
        raise InputError(f"{source}: MuJoCo cannot load it: {' '.join(str(e).split())}") from None


def fix_millimetres(mj: ET.Element, m: mujoco.MjModel, warnings: list[str]) -> bool:
    """Meshes drawn in millimetres (an extent over :data:`MM_EXTENT_M`) are scaled by 0.001; True if any was."""
    scaled = []
    for i in range(m.nmesh):
        adr, n = m.mesh_vertadr[i], m.mesh_vertnum[i]
        v = m.mesh_vert[adr : adr + n]
        if n and float(np.ptp(v, axis=0).max()) > MM_EXTENT_M:
            scaled.append(m.mesh(i).name)
    if not scaled:
        return False
    for el in mj.iter("mesh"):
        if el.get("name") in scaled:
            s = [float(x) for x in el.get("scale", "1 1 1").split()]
            el.set("scale", " ".join(f"{x * 0.001:g}" for x in s))
    warnings.append(f"meshes {scaled[:3]}{'...' if len(scaled) > 3 else ''} are in millimetres: scaled by 0.001")
    return True


def weld_free_joints(mj: ET.Element) -> bool:
    """Remove free joints (a floating base): robogest's robots stand welded. True if there was one."""
    found = False
    for body in mj.iter("body"):
        for j in list(body):
            if j.tag == "freejoint" or (j.tag == "joint" and j.get("type") == "free"):
                body.remove(j)
                found = True
    return found


def actuate(
    mj: ET.Element, m: mujoco.MjModel, joints: list[str], velocity: dict[str, float], warnings: list[str]
) -> None:
    """A servo-like position actuator on every hinge (replacing any the model had); damping, armature and
    friction scaled from its torque."""
    defaulted = []
    for old in mj.findall("actuator"):
        mj.remove(old)
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
        el.set("damping", f"{effort / velocity[jn]:.4g}")  # back-EMF: no-load speed = the velocity limit
        el.set("armature", f"{0.006 * effort / DEFAULT_EFFORT_NM:.4g}")  # the STS3215's rotor inertia, scaled
        el.set("frictionloss", f"{0.02 * effort:.4g}")
        el.set("limited", "true")
        lo, hi = m.jnt_range[j]
        el.set("range", f"{lo:.10g} {hi:.10g}")
        ET.SubElement(acts, "position", name=jn, joint=jn, kp=f"{effort / 0.1:.4g}", kv=f"{0.07 * effort:.4g}",
                      ctrlrange=f"{lo:.10g} {hi:.10g}", forcerange=f"{-effort:.4g} {effort:.4g}")  # fmt: skip
    if defaulted:
        warnings.append(f"{len(defaulted)} joints have no effort limit (e.g. {defaulted[0]!r}): sized as an STS3215 "
                        f"({DEFAULT_EFFORT_NM} N*m)")  # fmt: skip


def own_position_actuators(m: mujoco.MjModel, joints: list[str]) -> bool:
    """Every hinge has exactly one position actuator of its own, with a control and force range: keep them."""
    import mujoco

    for jn in joints:
        jid = m.joint(jn).id
        acts = [
            a
            for a in range(m.nu)
            if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] == jid
        ]
        if len(acts) != 1:
            return False
        a = acts[0]
        kp = m.actuator_gainprm[a, 0]
        if not (m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE and kp > 0 and m.actuator_forcelimited[a]):
            return False
    return bool(m.nu == len(joints))


def adopt_actuators(mj: ET.Element, m: mujoco.MjModel, joints: list[str], warnings: list[str]) -> None:
    """Keep the model's own position servos, with their control range cut to the joint's range (a servo is never
    sent past its joint) and, where the joint has none, damping and armature sized from the servo's force limit."""
    act_of = {m.joint(int(m.actuator_trnid[a, 0])).name: a for a in range(m.nu)}
    sized = []
    for el in mj.iter("joint"):
        jn = el.get("name")
        if jn not in joints:
            continue
        j, a = m.joint(jn).id, act_of[jn]
        effort = float(m.actuator_forcerange[a][1])
        if m.dof_damping[m.jnt_dofadr[j]] <= 0 or m.dof_armature[m.jnt_dofadr[j]] <= 0:
            el.set("damping", f"{effort / DEFAULT_VELOCITY_RAD_S:.4g}")
            el.set("armature", f"{0.006 * effort / DEFAULT_EFFORT_NM:.4g}")
            sized.append(jn)
    lo_hi = {jn: m.jnt_range[m.joint(jn).id] for jn in joints}
    for a_el in (x for acts in mj.findall("actuator") for x in acts):
        jn = a_el.get("joint")
        if jn in lo_hi:
            a_el.set("ctrlrange", f"{lo_hi[jn][0]:.10g} {lo_hi[jn][1]:.10g}")
            a_el.attrib.pop("inheritrange", None)
            a_el.set("ctrllimited", "true")
    warnings.append("the model's own position servos are kept (control ranges cut to the joint ranges)")
    if sized:
        warnings.append(f"{len(sized)} joints had no damping or armature (e.g. {sized[0]!r}): sized from their "
                        "servo's force limit, like an STS3215")  # fmt: skip


def start_pose(m: mujoco.MjModel, joints: list[str], keyframe: dict[str, float] | None = None) -> dict[str, float]:
    """Where held joints stand and the rest search starts: a standing keyframe's angle, else the pose the
    description is drawn in (joint zero, moved into the range where it lies outside)."""
    rest = {}
    for jn in joints:
        lo, hi = (float(x) for x in m.jnt_range[m.joint(jn).id])
        q = keyframe.get(jn, 0.0) if keyframe else 0.0
        rest[jn] = min(max(q, lo), hi)
    return rest


def pose_data(m: mujoco.MjModel, pose: dict[str, float]) -> mujoco.MjData:
    import mujoco

    d = mujoco.MjData(m)
    for jn, q in pose.items():
        d.qpos[m.joint(jn).qposadr[0]] = q
    mujoco.mj_forward(m, d)
    return d


def exclude_touching(mj: ET.Element, m: mujoco.MjModel, pose: dict[str, float], warnings: list[str]) -> None:
    """Parts that already overlap in the start pose (meshes meeting at a servo horn) are a modelling artefact, not
    a collision to avoid: exclude those body pairs from contact, and a welded base from the links its joints turn."""
    d = pose_data(m, pose)
    robot = m.body_rootid[m.geom_bodyid] != 0
    pairs = sorted({
        tuple(sorted((m.body(m.geom_bodyid[c.geom1]).name, m.body(m.geom_bodyid[c.geom2]).name)))
        for c in d.contact[: d.ncon] if robot[c.geom1] and robot[c.geom2] and c.dist < 0
    })  # fmt: skip
    # MuJoCo skips contacts between a body and its parent, but not when the parent is welded to the world
    joined = {
        (m.body(int(m.body_parentid[b])).name, m.body(b).name)
        for b in range(1, m.nbody)
        if m.body_parentid[b] > 0 and m.body_weldid[m.body_parentid[b]] == 0 and m.body_jntnum[b] > 0
    }
    if pairs:
        warnings.append(f"{len(pairs)} body pairs overlap at the start pose (e.g. {pairs[0]}): their contacts are "
                        "excluded (<contact><exclude>)")  # fmt: skip
    near = _near_pairs(m)
    if near:
        warnings.append(f"{len(near)} body pairs at most {NEAR_HINGES} joints apart (a hand and the gear beside its "
                        "wrist) cannot meet in a gesture: their contacts are excluded")  # fmt: skip
    if pairs or joined or near:
        contact = child(mj, "contact")
        for a, b in sorted(set(pairs) | joined | near):
            ET.SubElement(contact, "exclude", body1=a, body2=b)


#: Bodies with geoms this many hinge joints apart or fewer are neighbours by construction (servo, horn, bracket).
NEAR_HINGES = 2


def _near_pairs(m: mujoco.MjModel) -> set[tuple[str, str]]:
    """Body pairs with geoms, not parent and child (MuJoCo skips those), at most :data:`NEAR_HINGES` hinges apart."""
    with_geoms = sorted({int(b) for b in m.geom_bodyid if m.body_rootid[b] != 0})
    up = {}
    for b in with_geoms:  # body -> {ancestor: hinges between}
        path, n, a = {}, 0, b
        while a > 0:
            path[a] = n
            n += int(m.body_jntnum[a])
            a = int(m.body_parentid[a])
        path[0] = n
        up[b] = path
    out = set()
    for i, a in enumerate(with_geoms):
        for b in with_geoms[i + 1 :]:
            if m.body_parentid[a] == b or m.body_parentid[b] == a:
                continue
            common = next(x for x in up[a] if x in up[b])
            hinges = up[a][common] + up[b][common]
            if 0 < hinges <= NEAR_HINGES and common > 0:
                out.add(tuple(sorted((m.body(a).name, m.body(b).name))))
    return out


def add_sites(mj: ET.Element, limbs: Sequence[Limb]) -> list[tuple[str, str, str, str, float]]:
    """Sites on the bodies; the retarget vectors (human from, human to, site from, site to, weight) between them.
    One arm is mapped to the human right arm; the head's neck->head and head->nose directions follow it."""
    bodies = {b.get("name"): b for b in mj.iter("body")}
    world = child(mj, "worldbody")
    arms = [lb for lb in limbs if lb.part != "head"]
    vectors = []
    for limb in limbs:
        side = "" if limb.part == "head" else ("l" if limb.part.startswith("left") else "r")
        prefix = f"{side}_" if len(arms) > 1 and side else ""
        for role, (body, pos) in limb.points.items():
            site = ET.Element("site", name=f"{prefix}{role}_site", pos=" ".join(f"{x:.5g}" for x in pos),
                              size="0.006", group="5")  # fmt: skip
            bodies.get(body, world).insert(0, site)
        if limb.part == "head":
            vectors += [
                ("neck", "head", "neck_site", "head_site", 0.5),
                ("head", "nose", "head_site", "face_site", 1.0),
            ]
            continue
        roles = [r for r in ("shoulder", "elbow", "wrist", "hand") if r in limb.points]
        for a, b in itertools.pairwise(roles):
            vectors.append((f"{side}_{a}", f"{side}_{b}", f"{prefix}{a}_site", f"{prefix}{b}_site",
                            0.5 if b == "hand" else 1.0))  # fmt: skip
    return vectors


def turn_and_stand(mj: ET.Element, yaw: float, lift_m: float) -> None:
    """Turn the whole robot by ``-yaw`` about Z (its front to +X) and raise it by ``lift_m`` (feet on the floor)."""
    c, s = math.cos(-yaw / 2), math.sin(-yaw / 2)
    rz = np.array([[math.cos(-yaw), -math.sin(-yaw), 0], [math.sin(-yaw), math.cos(-yaw), 0], [0, 0, 1]])
    for body in child(mj, "worldbody").findall("body"):
        pos = rz @ np.array([float(x) for x in body.get("pos", "0 0 0").split()]) + [0.0, 0.0, lift_m]
        if body.get("quat") is None and any(body.get(k) for k in ("euler", "axisangle", "xyaxes", "zaxis")):
            raise InputError(f"body {body.get('name')!r}: orientation given as euler/axisangle; write it as quat")
        w, x, y, z = (float(t) for t in body.get("quat", "1 0 0 0").split())
        body.set("pos", " ".join(f"{t:.6g}" for t in pos))
        body.set("quat", " ".join(f"{t:.6g}" for t in [c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w]))


def geom_boxes(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """``(G, 3)`` lower and upper corners of each geom's world-axis bounding box (its local box, turned)."""
    rot = d.geom_xmat.reshape(-1, 3, 3)
    centre = d.geom_xpos + np.einsum("gij,gj->gi", rot, m.geom_aabb[:, :3])
    half = np.einsum("gij,gj->gi", np.abs(rot), m.geom_aabb[:, 3:])
    return centre - half, centre + half


def lowest_point(m: mujoco.MjModel, d: mujoco.MjData) -> float:
    """The lowest point of the robot's geoms (world z)."""
    robot = m.body_rootid[m.geom_bodyid] != 0
    return float(geom_boxes(m, d)[0][robot, 2].min()) if robot.any() else 0.0


def header(source: str, guesses: list[str]) -> str:
    lines = "\n".join(f"  - {g.replace('--', '- -')}" for g in guesses)
    return (
        f"<!--\n  Written by `robogest robots import` from {source}. Guessed (edit to taste):\n{lines}\n"
        "  Actuators: servo-like position control sized from each joint's effort and velocity limits.\n-->\n"
    )


def scene(m: mujoco.MjModel, d: mujoco.MjData, name: str, robot_file: str) -> str:
    """Floor under the robot's lowest point, a light and a skybox. No camera: videos and renders of a scene without
    one are filmed by :func:`robogest.backends.render.framing_camera`, facing the robot and framing its upper body
    at any frame size (a fixed camera written here framed the whole robot, pedestal and legs, from one side)."""
    if m.ngeom:
        glo, ghi = geom_boxes(m, d)
        lo, hi = glo.min(axis=0), ghi.max(axis=0)
    else:
        lo, hi = np.zeros(3), np.zeros(3)
    floor = min(0.0, float(lo[2]))
    centre = 0.5 * (lo + hi)
    size = max(float(np.linalg.norm(hi - lo)), 0.2)

    def v(a: np.ndarray) -> str:
        return " ".join(f"{t:.4g}" for t in a)

    light = centre + size * np.array([0.6, 0.4, 2.0])
    return f"""<!-- Scene for {name}: floor, light, skybox (written by robogest robots import). -->
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
  </worldbody>
</mujoco>
"""
