"""The one loader of a robot's MuJoCo model (MJCF): the IK, the simulator and the checks all compile it here, so
they agree on what the model is (a floating base welded standing, one-line errors naming the file)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import ConfigError
from robogest.robot.config import RobotConfig

if TYPE_CHECKING:
    import mujoco


def load_mjcf(robot: RobotConfig) -> mujoco.MjModel:
    """``robot``'s MuJoCo model, compiled (``mujoco.MjModel``): the one loader of the IK, the simulator and the
    checks. ConfigError on one line naming the file when MuJoCo cannot load it (its parser's message spans lines).

    A floating base (a free joint on a body that carries the robot's joints, as menagerie humanoids have) is welded
    at standing height (:func:`weld_floating_base`): robogest gestures, it does not balance.
    """
    try:
        return weld_floating_base(compile_mjcf(robot.model_path), robot.model_path)
    except ValueError as e:
        msg = " ".join(str(e).split())
        raise ConfigError(
            f"{robot.path or robot.name}: key model: MuJoCo cannot load {robot.model_path}: {msg}"
        ) from None


def compile_mjcf(path: Path) -> mujoco.MjModel:
    """The MJCF file at ``path`` compiled as written (``mujoco.MjModel``, no base welded); MuJoCo's ValueError
    as it is. For checks that have a model path but no loaded robot; everything else uses :func:`load_mjcf`."""
    import mujoco

    return mujoco.MjModel.from_xml_path(str(path))


def _lowest_point_z(m: mujoco.MjModel, d: mujoco.MjData, geoms: np.ndarray) -> float:
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


def _spec_body(spec: mujoco.MjSpec, m: mujoco.MjModel, b: int) -> mujoco.MjsBody:
    """The spec's body for model body ``b`` (same order), named if it was not (contact excludes name bodies)."""
    body = spec.bodies[b]
    if not body.name:
        body.name = f"robogest_body_{b}"
    return body


def weld_floating_base(m: mujoco.MjModel, path: Path) -> mujoco.MjModel:
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
    drop_q: list[int] = []  # qpos and qvel entries of the removed free joints
    drop_v: list[int] = []
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


def joint_actuators(m: mujoco.MjModel, jid: int) -> list[int]:
    """Actuators of MuJoCo model ``m`` that drive joint ``jid`` directly (joint transmission)."""
    import mujoco

    return [
        a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] == jid
    ]
