"""S2AG's pose graph (§3.1.4): 10 upper-body joints, 9 unit edge directions, and the way back to canonical
rotations. Numpy only."""

from __future__ import annotations

import numpy as np

from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M

#: The 10 upper-body joints as canonical joint names: root, spine, neck, head, then each arm's shoulder, elbow,
#: wrist. "spine" is ``spine2`` (where neck and collars attach); "head" is ``nose``, the head's tip, so the head's
#: nod and turn are part of the neck->head edge.
JOINTS = ("pelvis", "spine2", "neck", "nose", "l_shoulder", "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist")
#: The 9 edges ``(source, destination)`` as indices into :data:`JOINTS`, directed from the root outwards.
EDGES = ((0, 1), (1, 2), (2, 3), (1, 4), (4, 5), (5, 6), (1, 7), (7, 8), (8, 9))
#: Edges of each body part for the second STGCN level: trunk, left arm, right arm.
BODY_PARTS = ((0, 1, 2), (3, 4, 5), (6, 7, 8))
N_EDGES = len(EDGES)
#: Frames each side of a frame in the temporal neighbourhood of both STGCN levels (§3.1.4: "past two and future two").
TEMPORAL_REACH = 2
#: Correction rounds for the two-bone trunk in :func:`directions_to_motion`.
TRUNK_ITERATIONS = 4


def edge_adjacency(hops: int = 2) -> np.ndarray:
    """Level-1 spatial adjacency ``A1`` over the 9 edges, self loops included.

    Two edges are adjacent when they share a vertex (1 hop) or both touch the ends of a third edge (2 hops): the
    distance in the line graph of the joint tree is at most ``hops``.

    Returns
    -------
    ndarray [shape=(9, 9)], {0, 1}
    """
    share = np.array([[bool(set(a) & set(b)) for b in EDGES] for a in EDGES], dtype=np.int64)  # (9, 9) line graph
    reach = np.eye(N_EDGES, dtype=np.int64)
    for _ in range(hops):
        reach = ((reach @ share) > 0).astype(np.int64)
    return reach.astype(np.float32)


def part_adjacency() -> np.ndarray:
    """Level-2 adjacency ``A2`` over (trunk, left arm, right arm): arms touch the trunk, not each other; self loops.

    Returns
    -------
    ndarray [shape=(3, 3)], {0, 1}
    """
    return np.array([[1, 1, 1], [1, 1, 0], [1, 0, 1]], dtype=np.float32)


def _rest_positions() -> np.ndarray:
    rest = np.tile(R.IDENTITY, (1, CANONICAL.n_joints, 1))  # (1, J, 4)
    pos: np.ndarray = CANONICAL.forward_kinematics(rest, np.zeros((1, 3)))[0]  # (J, 3)
    return pos


_IDX = [CANONICAL.index(n) for n in JOINTS]
_REST = _rest_positions()
#: Bone length ``b_i`` of each edge in the canonical rest pose, metres (eq. 11).
BONE_LENGTHS = np.array([np.linalg.norm(_REST[_IDX[d]] - _REST[_IDX[s]]) for s, d in EDGES])


def positions_to_directions(pos: np.ndarray) -> np.ndarray:
    """Joint positions ``(..., 10, 3)`` (the :data:`JOINTS`) -> unit edge directions ``(..., 9, 3)``."""
    src, dst = [s for s, _ in EDGES], [d for _, d in EDGES]
    v = pos[..., dst, :] - pos[..., src, :]  # (..., 9, 3)
    unit: np.ndarray = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)
    return unit


def motion_to_directions(motion: HumanMotion) -> np.ndarray:
    """Canonical motion -> unit edge directions ``(T, 9, 3)`` in the world frame (Y up, facing +Z)."""
    pos = motion.skeleton.forward_kinematics(motion.rotations, motion.root_pos_m)  # (T, J, 3)
    return positions_to_directions(pos[:, _IDX])


def expmaps_to_directions(poses: np.ndarray) -> np.ndarray:
    """Canonical exponential maps ``(T, J * 3)`` (a take's poses) -> unit edge directions ``(T, 9, 3)``."""
    rot = R.from_axis_angle(np.asarray(poses, np.float64).reshape(poses.shape[0], CANONICAL.n_joints, 3))  # (T,J,4)
    pos = CANONICAL.forward_kinematics(rot, np.zeros((poses.shape[0], 3)))  # (T, J, 3)
    return positions_to_directions(pos[:, _IDX])


def directions_to_positions(
    dirs: np.ndarray, lengths: np.ndarray = BONE_LENGTHS, root: np.ndarray | None = None
) -> np.ndarray:
    """Eq. 11: scale each direction to its bone length and chain from the root.

    Parameters
    ----------
    dirs : ndarray [shape=(T, 9, 3)]
        Edge vectors (normalised here).
    lengths : ndarray [shape=(9,)], metres
    root : ndarray [shape=(3,)], optional
        Root position (default: the origin).

    Returns
    -------
    ndarray [shape=(T, 10, 3)], metres
    """
    u = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-9)
    pos = np.zeros((dirs.shape[0], len(JOINTS), 3))
    if root is not None:
        pos[:, 0] = root
    for i, (s, d) in enumerate(EDGES):  # EDGES lists every source before its destinations
        pos[:, d] = pos[:, s] + lengths[i] * u[:, i]
    return pos


def _swing(parent_global: np.ndarray, offset: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Local rotation (``(T, 4)``) turning bone ``offset`` from where the parent frame points it to ``target``."""
    cur = R.rotate(parent_global, np.broadcast_to(offset, target.shape))  # (T, 3)
    return R.normalize(R.mul(R.conj(parent_global), R.mul(R.between(cur, target), parent_global)))


def directions_to_motion(dirs: np.ndarray, fps: float) -> HumanMotion:
    """Unit edge directions ``(T, 9, 3)`` -> canonical :class:`HumanMotion` (for the shared retargeting).

    Each edge's swing (the smallest rotation from where the bone points with an identity local rotation to the
    target direction) goes into the canonical joint that moves it: ``spine2``/``neck``/collar/shoulder/elbow for
    their edges; the root->spine edge spans three canonical bones and its swing is split in two equal halves over
    ``spine`` and ``spine1`` (corrected iteratively for the fixed pelvis->spine offset); the collar is aimed so the
    shoulder lies on the ray of its edge. Approximations: twist about a bone is not represented (zero twist out),
    the pelvis, head, wrists and hands keep identity local rotations (so the hands' orientation is lost, the
    head's follows the neck), and edge lengths are the canonical ones. The root stays at its rest position.
    """
    dirs = np.asarray(dirs, np.float64)
    t = dirs.shape[0]
    u = dirs / np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-9)
    off = CANONICAL.offsets_m
    ix = CANONICAL.index
    local = np.tile(R.IDENTITY, (t, CANONICAL.n_joints, 1))  # (T, J, 4)
    ident = np.tile(R.IDENTITY, (t, 1))  # (T, 4)
    # trunk: pelvis -> spine2 over spine and spine1 (the pelvis->spine offset is fixed with an identity pelvis);
    # the swing is split in halves and corrected a few times, since the fixed first offset bends less
    o_spine, o_spine1, o_spine2 = off[ix("spine")], off[ix("spine1")], off[ix("spine2")]
    total = R.between(np.tile(o_spine1 + o_spine2, (t, 1)), u[:, 0])  # (T, 4)
    for _ in range(TRUNK_ITERATIONS):
        half = R.slerp(ident, total, 0.5)  # (T, 4)
        reached = o_spine + R.rotate(half, o_spine1) + R.rotate(R.mul(half, half), o_spine2)  # (T, 3)
        total = R.normalize(R.mul(R.between(reached, u[:, 0]), total))
    half = R.slerp(ident, total, 0.5)
    local[:, ix("spine")] = half
    local[:, ix("spine1")] = half
    g_spine1 = R.mul(half, half)
    local[:, ix("spine2")] = _swing(g_spine1, off[ix("neck")], u[:, 1])
    g_spine2 = R.mul(g_spine1, local[:, ix("spine2")])
    # head edge neck -> nose: the neck carries the swing, the head keeps identity
    local[:, ix("neck")] = _swing(g_spine2, off[ix("head")] + off[ix("nose")], u[:, 2])
    p_spine2 = o_spine + R.rotate(half, o_spine1) + R.rotate(g_spine1, o_spine2)
    for side, e_sh, e_el, e_wr in (("l", 3, 4, 5), ("r", 6, 7, 8)):
        collar, shoulder, elbow, wrist = (ix(f"{side}_{n}") for n in ("collar", "shoulder", "elbow", "wrist"))
        p_collar = p_spine2 + R.rotate(g_spine2, off[collar])  # (T, 3)
        # the shoulder goes where the edge's ray from spine2 meets the collar bone's sphere: |w + λu| = |offset|
        w = p_spine2 - p_collar  # (T, 3)
        wu = np.sum(w * u[:, e_sh], axis=-1)  # (T,)
        disc = wu**2 - np.sum(w * w, axis=-1) + np.sum(off[shoulder] ** 2)
        lam = -wu + np.sqrt(np.maximum(disc, 0.0))  # (T,), metres along the ray
        target = w + lam[:, None] * u[:, e_sh]  # collar -> wanted shoulder position
        local[:, collar] = _swing(g_spine2, off[shoulder], target)
        g = R.mul(g_spine2, local[:, collar])
        local[:, shoulder] = _swing(g, off[elbow], u[:, e_el])
        g = R.mul(g, local[:, shoulder])
        local[:, elbow] = _swing(g, off[wrist], u[:, e_wr])
    root = np.tile([0.0, CANONICAL_PELVIS_HEIGHT_M, 0.0], (t, 1))  # (T, 3)
    return HumanMotion(fps=fps, rotations=R.normalize(local), root_pos_m=root, skeleton=CANONICAL)
