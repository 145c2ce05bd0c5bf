"""Synthetic humanoid descriptions written by the tests (nothing copied from public robots): a pelvis with legs and
feet, a waist, a neck with pan and tilt, arms of 3 or 4 DoF with 2-DoF wrists, an optional gripper; X- or
Y-forward; meshes written with trimesh as STL (upper-case extension), OBJ or DAE; as URDF, xacro or MJCF.

Geometry (X-forward, Z up, metres): legs of 0.2 + 0.2 from hips 0.06 m to each side, a torso 0.25 tall above a
waist, arms hanging at joint zero from shoulders 0.13 m to each side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

INERTIA = '<inertial><mass value="{m}"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'


@dataclass
class Options:
    forward: str = "x"  # "x": the description faces +X; "y": it faces +Y (left is -X)
    arm_dof: int = 4  # 3: shoulder pitch/roll + elbow; 4: + an upper-arm twist; both with a 2-DoF wrist
    gripper: bool = False
    hand_mesh: str = ""  # "", "STL" (file hand.stl named HAND.STL), "obj", "dae"
    floating: bool = False  # a world link and a floating joint above the pelvis
    messy: bool = False  # reversed limits, velocity/effort 0, zero inertials, gazebo/transmission, fixed links
    servo: str = ""  # a servo model named in the link names (e.g. "XM430")
    sideways_elbow: bool = False  # the elbow bends sideways at joint zero (its axis along X): the twist must turn


def _p(o: Options, x: float, y: float, z: float) -> str:
    """A position or axis in the description's frame: X-forward as written, or turned so that +X faces +Y."""
    if o.forward == "y":
        x, y = -y, x
    return f"{x:.4g} {y:.4g} {z:.4g}"


class _Writer:
    def __init__(self, o: Options, mesh_ref: str):
        self.o, self.mesh_ref = o, mesh_ref
        self.links: list[str] = []
        self.joints: list[str] = []

    def link(self, name: str, size: tuple[float, float, float], centre: tuple[float, float, float], mass=0.1,
             mesh: bool = False) -> None:  # fmt: skip
        o = self.o
        sx, sy, sz = size if o.forward == "x" else (size[1], size[0], size[2])
        geo = f'<mesh filename="{self.mesh_ref}"/>' if mesh else f'<box size="{sx:.4g} {sy:.4g} {sz:.4g}"/>'
        vis = f'<origin xyz="{_p(o, *centre)}"/><geometry>{geo}</geometry>'
        inertial = INERTIA.format(m=0 if (o.messy and name.endswith("head")) else mass)
        self.links.append(f'<link name="{name}">{inertial}<visual>{vis}</visual></link>')

    def joint(self, name, parent, child, at, axis, lo=-1.6, hi=1.6, kind="revolute", velocity=4.0, effort=3.0):
        o = self.o
        lim = (
            f'<limit lower="{lo}" upper="{hi}" effort="{effort}" velocity="{velocity}"/>' if kind == "revolute" else ""
        )
        self.joints.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{_p(o, *at)}"/><axis xyz="{_p(o, *axis)}"/>{lim}</joint>'
        )


def urdf_body(o: Options, mesh_ref: str = "") -> str:
    """The links and joints (no ``<robot>`` element) of the humanoid."""
    w = _Writer(o, mesh_ref)
    servo = f"_{o.servo}" if o.servo else ""
    if o.floating:
        w.links.append('<link name="world"/>')
        w.joints.append('<joint name="float" type="floating"><parent link="world"/><child link="pelvis"/></joint>')
    w.link("pelvis", (0.08, 0.16, 0.06), (0, 0, 0), 0.5)
    for side, s in (("left", 1), ("right", -1)):
        w.link(f"{side}_hip{servo}", (0.03, 0.03, 0.03), (0, 0, 0))
        w.link(f"{side}_thigh", (0.04, 0.04, 0.18), (0, 0, -0.1))
        w.link(f"{side}_shin", (0.04, 0.04, 0.18), (0, 0, -0.1))
        w.link(f"{side}_foot", (0.12, 0.06, 0.02), (0.03, 0, -0.04))
        knee = (-0.1, 2.2) if not (o.messy and side == "left") else (2.2, -0.1)  # a reversed servo range
        w.joint(f"{side}_hip_roll", "pelvis", f"{side}_hip{servo}", (0, s * 0.06, -0.04), (1, 0, 0), -0.5, 0.5)
        w.joint(f"{side}_hip_pitch", f"{side}_hip{servo}", f"{side}_thigh", (0, 0, -0.02), (0, 1, 0), -1.5, 1.5)
        w.joint(f"{side}_knee", f"{side}_thigh", f"{side}_shin", (0, 0, -0.2), (0, 1, 0), *knee)
        w.joint(f"{side}_ankle", f"{side}_shin", f"{side}_foot", (0, 0, -0.2), (0, 1, 0), -0.8, 0.8)
    w.link("waist_link", (0.03, 0.03, 0.03), (0, 0, 0.02))
    w.link("torso", (0.1, 0.2, 0.25), (0, 0, 0.14), 0.8)
    w.joint("waist_yaw", "pelvis", "waist_link", (0, 0, 0.04), (0, 0, 1), -1.0, 1.0)
    w.joint("waist_roll", "waist_link", "torso", (0, 0, 0.02), (1, 0, 0), -0.5, 0.5)
    w.link("neck", (0.03, 0.03, 0.03), (0, 0, 0.01))
    w.link("head", (0.1, 0.1, 0.1), (0.01, 0, 0.06), 0.2)
    w.joint("neck_yaw", "torso", "neck", (0, 0, 0.28), (0, 0, 1), -1.2, 1.2)
    w.joint("neck_pitch", "neck", "head", (0, 0, 0.03), (0, 1, 0), -0.6, 0.6)
    for side, s in (("left", 1), ("right", -1)):
        w.link(f"{side}_shoulder", (0.03, 0.03, 0.03), (0, 0, 0))
        w.link(f"{side}_upper_arm{servo}", (0.035, 0.035, 0.12), (0, 0, -0.07))
        w.link(f"{side}_forearm", (0.03, 0.03, 0.1), (0, 0, -0.06))
        w.link(f"{side}_wrist", (0.02, 0.02, 0.02), (0, 0, 0))
        w.link(f"{side}_hand", (0.03, 0.02, 0.06), (0, 0, -0.04), 0.05, mesh=bool(mesh_ref))
        roll = (-0.3, 1.6) if s > 0 else (-1.6, 0.3)
        w.joint(f"{side}_shoulder_pitch", "torso", f"{side}_shoulder", (0, s * 0.13, 0.24), (0, 1, 0), -2.5, 2.5)
        w.joint(f"{side}_shoulder_roll", f"{side}_shoulder", f"{side}_upper_arm{servo}", (0, 0, 0), (1, 0, 0), *roll)
        if o.arm_dof == 4:
            w.link(f"{side}_upper_arm_twist", (0.03, 0.03, 0.02), (0, 0, -0.01))
            w.joint(f"{side}_upper_arm_yaw", f"{side}_upper_arm{servo}", f"{side}_upper_arm_twist", (0, 0, -0.05),
                    (0, 0, 1), -1.5, 1.5)  # fmt: skip
            elbow_parent, elbow_at = f"{side}_upper_arm_twist", (0, 0, -0.1)
        else:
            elbow_parent, elbow_at = f"{side}_upper_arm{servo}", (0, 0, -0.15)
        elbow_axis = (s, 0, 0) if o.sideways_elbow else (0, 1, 0)
        w.joint(f"{side}_elbow", elbow_parent, f"{side}_forearm", elbow_at, elbow_axis, -2.2, 0.1)
        w.joint(f"{side}_wrist_pitch", f"{side}_forearm", f"{side}_wrist", (0, 0, -0.13), (0, 1, 0), -1.2, 1.2)
        w.joint(f"{side}_wrist_roll", f"{side}_wrist", f"{side}_hand", (0, 0, -0.01), (0, 0, 1), -1.5, 1.5,
                velocity=0 if o.messy else 4.0, effort=0 if o.messy else 3.0)  # fmt: skip
        if o.gripper:
            w.link(f"{side}_finger", (0.01, 0.01, 0.03), (0, 0, -0.015), 0.01)
            w.joint(f"{side}_gripper", f"{side}_hand", f"{side}_finger", (0.012, 0, -0.07), (0, 1, 0), -0.5, 0.5)
    extra = ""
    if o.messy:
        w.link("imu", (0.01, 0.01, 0.01), (0, 0, 0), 0.01)
        w.joints.append('<joint name="imu_fixed" type="fixed"><parent link="torso"/><child link="imu"/>'
                        '<origin xyz="0 0 0.1"/></joint>')  # fmt: skip
        extra = ('<gazebo reference="torso"><material>Gazebo/Grey</material></gazebo><transmission name="t1">'
                 '<type>SimpleTransmission</type><joint name="left_elbow"/></transmission>')  # fmt: skip
    return "\n".join(w.links + w.joints) + extra


def write_mesh(path: Path, kind: str) -> None:
    """A hand-sized box as a mesh file (``kind``: stl, obj, dae), written with trimesh."""
    import trimesh

    box = trimesh.creation.box(extents=[0.03, 0.02, 0.06])
    box.apply_translation([0, 0, -0.04])
    box.export(str(path), file_type=kind)


def write_urdf(folder: Path, o: Options) -> Path:
    """``folder/robot_description/urdf/robot.urdf`` with its meshes in ``robot_description/meshes``."""
    pkg = folder / "robot_description"
    (pkg / "urdf").mkdir(parents=True)
    ref = ""
    if o.hand_mesh:
        (pkg / "meshes").mkdir()
        kind = o.hand_mesh.lower()
        write_mesh(pkg / "meshes" / f"hand.{kind}", kind)
        name = f"HAND.{o.hand_mesh}" if o.hand_mesh.isupper() else f"hand.{kind}"
        ref = f"package://robot_description/meshes/{name}"
    path = pkg / "urdf" / "robot.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="toy_humanoid">\n{urdf_body(o, ref)}\n</robot>\n')
    return path


def write_xacro(folder: Path, o: Options) -> Path:
    """A xacro description: the body is a macro in an included file found with ``$(find robot_description)``, its
    hand meshes named ``package://robot_description/...``; the shoulder height is a property."""
    pkg = folder / "robot_description"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    (pkg / "package.xml").write_text("<package><name>robot_description</name></package>\n")
    write_mesh(pkg / "meshes" / "hand.stl", "stl")
    body = urdf_body(o, "package://robot_description/meshes/hand.stl").replace("0.24", "${shoulder_z}")
    (pkg / "urdf" / "body.xacro").write_text(
        '<?xml version="1.0"?>\n<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        f'<xacro:macro name="body" params="">\n{body}\n</xacro:macro>\n</robot>\n'
    )
    path = pkg / "urdf" / "robot.urdf.xacro"
    path.write_text(
        '<?xml version="1.0"?>\n<robot name="toy_humanoid" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        '<xacro:property name="shoulder_z" value="${0.2 + 0.04}"/>\n'
        '<xacro:include filename="$(find robot_description)/urdf/body.xacro"/>\n<xacro:body/>\n</robot>\n'
    )
    return path


def write_mjcf(folder: Path, o: Options, degrees: bool = False, actuators: bool = True) -> Path:
    """A menagerie-style ``robot.xml`` (a free joint, its own position actuators, a standing keyframe) and a
    ``scene.xml`` that includes it, made from the URDF by MuJoCo's own reader (angles in degrees if ``degrees``);
    returns the scene."""
    import xml.etree.ElementTree as ET

    import mujoco

    compiler = '<mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>'
    spec = mujoco.MjSpec.from_string(f'<robot name="toy_humanoid">{urdf_body(o)}{compiler}</robot>')
    spec.compile()
    mj = ET.fromstring(spec.to_xml())
    pelvis = next(b for b in mj.find("worldbody") if b.tag == "body")
    pelvis.insert(0, ET.Element("freejoint", name="root"))
    pelvis.set("pos", "0 0 0.5")
    acts = ET.SubElement(mj, "actuator")
    names = [j.get("name") for j in mj.iter("joint")]
    for jn in names if actuators else []:
        ET.SubElement(acts, "position", name=f"{jn}_servo", joint=jn, kp="30", forcerange="-3 3",
                      ctrlrange="-3.2 3.2")  # fmt: skip
    key = ET.SubElement(ET.SubElement(mj, "keyframe"), "key", name="stand")
    key.set("qpos", " ".join(["0 0 0.5 1 0 0 0"] + ["0"] * len(names)))
    if o.hand_mesh:  # an asset named after its file, as menagerie models write them
        (folder / "assets").mkdir()
        write_mesh(folder / "assets" / "hand.stl", "stl")
        mj.find("compiler").set("meshdir", "assets")
        asset = mj.find("asset") if mj.find("asset") is not None else ET.SubElement(mj, "asset")
        ET.SubElement(asset, "mesh", file="hand.stl")
        hand = next(b for b in mj.iter("body") if b.get("name") == "left_hand")
        ET.SubElement(hand, "geom", type="mesh", mesh="hand", contype="0", conaffinity="0")
    if degrees:  # MJCF's default angle unit: ranges in degrees, no compiler setting
        mj.find("compiler").attrib.pop("angle", None)
        for j in mj.find("worldbody").iter("joint"):
            if j.get("range"):
                j.set("range", " ".join(f"{math.degrees(float(x)):.6g}" for x in j.get("range").split()))
    (folder / "robot.xml").write_text(ET.tostring(mj, encoding="unicode"))
    scene = folder / "scene.xml"
    scene.write_text('<mujoco model="scene"><include file="robot.xml"/><worldbody><light pos="0 0 3"/>'
                     '<geom name="floor" type="plane" size="2 2 0.1"/></worldbody></mujoco>')  # fmt: skip
    return scene


#: Joints a person gestures with, per arm (4-DoF arms), and those that must stay still.
ARM = ["shoulder_pitch", "shoulder_roll", "upper_arm_yaw", "elbow", "wrist_pitch", "wrist_roll"]
LEG = ["hip_roll", "hip_pitch", "knee", "ankle"]
QUARTER = math.pi / 2
