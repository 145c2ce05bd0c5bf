"""A small anatomical pose space on the canonical skeleton, so gestures can be authored as angles.

Gesture units are written as a handful of joint angles (arm raise, elbow bend, head nod...) rather
than as 17 quaternions; :func:`dofs_to_rotations` turns a ``(T, D)`` angle track into canonical local
rotations. Right-arm rotations are the mirror image (across the body's YZ plane) of the left-arm
formula, so a value means the same movement on either side.
"""

from __future__ import annotations

import numpy as np

from robogest.motion import rotations as R
from robogest.motion.skeleton import CANONICAL

#: Degrees of freedom, radians. Arm angles: ``abd`` raises the arm sideways from hanging (0) to
#: horizontal (pi/2); ``flex`` swings it forward; ``twist`` rotates it inwards about its own axis
#: (forearm towards the body midline); ``elbow`` bends the forearm forward; ``wrist`` bends the hand
#: like the elbow; ``shrug`` lifts the collar bone. Head: ``pitch`` > 0 looks down, ``yaw`` > 0 looks
#: to the character's left, ``roll`` > 0 tilts the head towards the left shoulder. Spine angles are
#: spread evenly over the three spine joints.
DOF_NAMES = (
    "spine_pitch", "spine_yaw", "spine_roll",
    "head_pitch", "head_yaw", "head_roll",
    "l_abd", "l_flex", "l_twist", "l_elbow", "l_wrist", "l_shrug",
    "r_abd", "r_flex", "r_twist", "r_elbow", "r_wrist", "r_shrug",
)  # fmt: skip
DOF = {n: i for i, n in enumerate(DOF_NAMES)}
N_DOF = len(DOF_NAMES)

ARM_DOFS = tuple(i for n, i in DOF.items() if n[:2] in ("l_", "r_"))
HEAD_DOFS = (DOF["head_pitch"], DOF["head_yaw"], DOF["head_roll"])
SPINE_DOFS = (DOF["spine_pitch"], DOF["spine_yaw"], DOF["spine_roll"])


def pose(**angles_rad: float) -> np.ndarray:
    """A ``(D,)`` DOF vector from keyword angles; ``both_x=`` sets ``l_x`` and ``r_x``."""
    v = np.zeros(N_DOF)
    for k, a in angles_rad.items():
        if k.startswith("both_"):
            v[DOF["l_" + k[5:]]] = a
            v[DOF["r_" + k[5:]]] = a
        elif k in DOF:
            v[DOF[k]] = a
        else:
            raise KeyError(f"unknown pose angle {k!r}; use one of {', '.join(DOF_NAMES)} or both_<arm angle>")
    return v


#: Arms hanging at the sides, elbows slightly bent, head level: the safe rest pose.
REST = pose(both_abd=0.12, both_flex=0.05, both_elbow=0.25, both_twist=0.15)
#: Speaking posture between strokes: forearms forward, hands in front of the belly.
READY = pose(both_abd=0.22, both_flex=0.30, both_twist=0.35, both_elbow=1.15, both_wrist=0.1)


def _axis_quat(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotations about a principal axis, ``angle (T,)`` -> ``(T, 4)``."""
    q = np.zeros((*angle.shape, 4))
    q[..., 0] = np.cos(0.5 * angle)
    q[..., 1 + axis] = np.sin(0.5 * angle)
    return q


_X, _Y, _Z = 0, 1, 2


def _left_arm(d: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Collar, shoulder, elbow, wrist local rotations ``(T, 4)`` for a left arm with ``side``'s angles."""
    g = {n: d[:, DOF[f"{side}_{n}"]] for n in ("abd", "flex", "twist", "elbow", "wrist", "shrug")}
    collar = _axis_quat(_Z, g["shrug"])
    # Lower from T-pose by (pi/2 - abd), swing forward by flex, twist about the bone first.
    shoulder = R.mul(
        R.mul(_axis_quat(_X, -g["flex"]), _axis_quat(_Z, g["abd"] - 0.5 * np.pi)),
        _axis_quat(_X, g["twist"]),
    )
    elbow = _axis_quat(_Y, -g["elbow"])
    wrist = _axis_quat(_Y, -g["wrist"])
    return collar, shoulder, elbow, wrist


def _mirror(q: np.ndarray) -> np.ndarray:
    """Reflect rotations across the YZ plane (x -> -x): (w, x, y, z) -> (w, x, -y, -z)."""
    mirrored: np.ndarray = q * np.array([1.0, 1.0, -1.0, -1.0])
    return mirrored


def dofs_to_rotations(dofs: np.ndarray) -> np.ndarray:
    """Angle tracks to canonical local rotations.

    Parameters
    ----------
    dofs : ndarray [shape=(T, D)], radians
        Columns in :data:`DOF_NAMES` order.

    Returns
    -------
    ndarray [shape=(T, J, 4)]
        Local unit quaternions on :data:`CANONICAL`.
    """
    dofs = np.asarray(dofs, dtype=np.float64)
    t = dofs.shape[0]
    rot = np.zeros((t, CANONICAL.n_joints, 4))
    rot[..., 0] = 1.0
    idx = CANONICAL.index
    spine = R.mul(
        R.mul(_axis_quat(_Y, dofs[:, DOF["spine_yaw"]] / 3), _axis_quat(_X, dofs[:, DOF["spine_pitch"]] / 3)),
        _axis_quat(_Z, -dofs[:, DOF["spine_roll"]] / 3),
    )
    for name in ("spine", "spine1", "spine2"):
        rot[:, idx(name)] = spine
    rot[:, idx("head")] = R.mul(
        R.mul(_axis_quat(_Y, dofs[:, DOF["head_yaw"]]), _axis_quat(_X, dofs[:, DOF["head_pitch"]])),
        _axis_quat(_Z, -dofs[:, DOF["head_roll"]]),
    )
    for side in ("l", "r"):
        parts: tuple[np.ndarray, ...] = _left_arm(dofs, side)
        if side == "r":
            parts = tuple(_mirror(p) for p in parts)
        for name, q in zip(("collar", "shoulder", "elbow", "wrist"), parts, strict=True):
            rot[:, idx(f"{side}_{name}")] = q
    return R.normalize(rot)
