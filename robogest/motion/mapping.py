"""Map a motion on any humanoid skeleton onto :data:`~robogest.motion.skeleton.CANONICAL`.

Method. Source global rotations ``G_s`` (relative to the source rest pose) come from forward kinematics. A constant
axis change ``A`` (a signed axis permutation, read off the source rest pose: its up and left directions) turns the
source world into the canonical one (Y up, +X left, facing +Z), so Z-up files and files facing -Z work. Each canonical
joint ``j`` takes the global orientation of one source joint ``s(j)``::

    G_c[j] = A G_s[s(j)] A^-1 C_j

- Trunk and head (pelvis, spine*, neck, head, nose): ``C_j = I``. The source's rest posture counts as upright and
  facing forward, so the head's facing and the chest's orientation carry over exactly.
- Arm chain (collar, shoulder, elbow, wrist): ``C_j = between(d_c, A d_s)`` with ``d_c`` the canonical rest bone and
  ``d_s`` the source rest segment that ``s(j)`` rotates (from ``s(j)`` towards the next mapped joint). The canonical
  bone then points exactly where the source bone points, whatever the source rest pose (A-pose, T-pose, bones along
  other axes); the minimal rotation adds no twist about the bone.

Canonical locals are ``G_c[parent]^-1 G_c[j]``, so source joints that the canonical skeleton lacks (Spine3, Neck1,
twist joints) compose into the canonical joint below them. Map a canonical joint to the *last* source joint before the
next mapped one (``b_l_arm_twist``, not ``b_l_arm``) so that its rotation includes the twist.

The pelvis position is scaled so that the source's standing pelvis height (pelvis above the lowest rest joint, when the
skeleton has legs) becomes :data:`~robogest.motion.skeleton.CANONICAL_PELVIS_HEIGHT_M`; skeletons without legs keep
their metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion
from robogest.motion.skeleton import CANONICAL, CANONICAL_PELVIS_HEIGHT_M, Skeleton

if TYPE_CHECKING:
    from robogest.motion.bvh import BvhData

#: Canonical joints every map must provide.
REQUIRED_JOINTS: tuple[str, ...] = (
    "pelvis",
    "spine2",
    "neck",
    "head",
    "l_collar",
    "l_shoulder",
    "l_elbow",
    "l_wrist",
    "r_collar",
    "r_shoulder",
    "r_elbow",
    "r_wrist",
)
#: Canonical joint -> its child whose direction the joint's bone alignment matches.
_BONE_CHILD = {
    "l_collar": "l_shoulder",
    "l_shoulder": "l_elbow",
    "l_elbow": "l_wrist",
    "l_wrist": "l_hand",
    "r_collar": "r_shoulder",
    "r_shoulder": "r_elbow",
    "r_elbow": "r_wrist",
    "r_wrist": "r_hand",
}


def _sided(common: dict[str, str], left: dict[str, str]) -> dict[str, str]:
    """Expand ``{"l_x": "Left..."}`` entries into both sides (Left/Right, _l_/_r_, left_/right_)."""
    out = dict(common)
    swaps = (("Left", "Right"), ("_l_", "_r_"), ("left_", "right_"))
    for k, v in left.items():
        out[k] = v
        rv = v
        for a, b in swaps:
            rv = rv.replace(a, b)
        out["r_" + k[2:]] = rv
    return out


_TRINITY_LIKE = _sided(
    {"pelvis": "Hips", "spine": "Spine1", "spine1": "Spine2", "spine2": "Spine3", "neck": "Neck1", "head": "Head"},
    {
        "l_collar": "LeftShoulder",
        "l_shoulder": "LeftArm",
        "l_elbow": "LeftForeArm",
        "l_wrist": "LeftHand",
        "l_hand": "LeftHandMiddle1",
    },
)

#: ``{map name: {canonical joint: source joint}}``. Source names match case-insensitively and ignore a namespace
#: prefix (``mixamorig:Hips`` matches ``Hips``). ``spine``, ``spine1``, ``nose`` and the hands are optional; the hand
#: entry only sets the direction of the hand in the source rest pose.
NAME_MAPS: dict[str, dict[str, str]] = {
    "canonical": {n: n for n in CANONICAL.names},
    "genea2023": _sided(
        {
            "pelvis": "b_root",
            "spine": "b_spine1",
            "spine1": "b_spine2",
            "spine2": "b_spine3",
            "neck": "b_neck0",
            "head": "b_head",
        },
        {
            "l_collar": "b_l_shoulder",
            "l_shoulder": "b_l_arm_twist",
            "l_elbow": "b_l_forearm",
            "l_wrist": "b_l_wrist",
            "l_hand": "b_l_middle1",
        },
    ),
    "genea2020": dict(_TRINITY_LIKE),
    "zeggs": dict(_TRINITY_LIKE),
    "beat": dict(_TRINITY_LIKE),
    "mixamo": _sided(
        {"pelvis": "Hips", "spine": "Spine", "spine1": "Spine1", "spine2": "Spine2", "neck": "Neck", "head": "Head"},
        {
            "l_collar": "LeftShoulder",
            "l_shoulder": "LeftArm",
            "l_elbow": "LeftForeArm",
            "l_wrist": "LeftHand",
            "l_hand": "LeftHandMiddle1",
        },
    ),
    "smplx": _sided(
        {"pelvis": "pelvis", "spine": "spine1", "spine1": "spine2", "spine2": "spine3", "neck": "neck", "head": "head"},
        {
            "l_collar": "left_collar",
            "l_shoulder": "left_shoulder",
            "l_elbow": "left_elbow",
            "l_wrist": "left_wrist",
            "l_hand": "left_middle1",
        },
    ),
}


def _norm(name: str) -> str:
    return name.rsplit(":", 1)[-1].strip().lower()


def _resolve(names: tuple[str, ...], name_map: dict[str, str]) -> tuple[dict[str, int], list[str]]:
    """Canonical joint -> source index for the entries present, and the required canonical joints missing."""
    lookup: dict[str, int] = {}
    for i, n in enumerate(names):
        lookup.setdefault(_norm(n), i)
    idx = {c: lookup[_norm(s)] for c, s in name_map.items() if c in CANONICAL.names and _norm(s) in lookup}
    return idx, [c for c in REQUIRED_JOINTS if c not in idx]


def detect_name_map(names: tuple[str, ...]) -> str | None:
    """Key of the first :data:`NAME_MAPS` entry whose required joints all exist in ``names``, else None."""
    for key, m in NAME_MAPS.items():
        if not _resolve(names, m)[1]:
            return key
    return None


def _select_map(
    names: tuple[str, ...], name_map: str | dict[str, str] | None, source: str
) -> tuple[dict[str, int], str]:
    fix_hint = "pass name_map= (a key of NAME_MAPS or a {canonical joint: source joint} dict)"
    if name_map is None:
        key = detect_name_map(names)
        if key is None:
            lines = [f"  {k}: {', '.join(m[c] for c in REQUIRED_JOINTS)}" for k, m in NAME_MAPS.items()]
            raise InputError(
                f"{source}: no known skeleton recognised (joints: {', '.join(names[:12])}"
                f"{', ...' if len(names) > 12 else ''}). Expected one of these joint sets:\n"
                + "\n".join(lines)
                + f"\nRename the joints or {fix_hint}."
            )
        name_map = key
    if isinstance(name_map, str):
        if name_map not in NAME_MAPS:
            raise InputError(f"{source}: unknown name map {name_map!r}; known: {', '.join(NAME_MAPS)}")
        label, mapping = name_map, NAME_MAPS[name_map]
    else:
        label, mapping = "custom", dict(name_map)
        unknown = [c for c in mapping if c not in CANONICAL.names]
        if unknown:
            raise InputError(
                f"{source}: name_map keys must be canonical joints ({', '.join(CANONICAL.names)}); got {unknown}"
            )
    idx, missing = _resolve(names, mapping)
    if missing:
        want = ", ".join(f"{c}->{mapping.get(c, '?')}" for c in missing)
        raise InputError(
            f"{source}: the {label} name map needs joints the file lacks ({want}). "
            f"The file has: {', '.join(names)}. Fix: {fix_hint}."
        )
    return idx, label


def _axis_change(up: np.ndarray, left: np.ndarray) -> np.ndarray:
    """Rotation matrix ``(3, 3)`` taking the source's (snapped) left, up, forward axes to +X, +Y, +Z."""
    iu = int(np.argmax(np.abs(up)))
    e_up = np.zeros(3)
    e_up[iu] = np.sign(up[iu])
    rest = np.abs(left).copy()
    rest[iu] = -1.0
    il = int(np.argmax(rest))
    e_left = np.zeros(3)
    e_left[il] = np.sign(left[il]) or 1.0
    e_fwd = np.cross(e_left, e_up)
    return np.stack([e_left, e_up, e_fwd])  # rows: A @ e_left = X, A @ e_up = Y, A @ e_fwd = Z


def _descendant_path(parents: tuple[int, ...], top: int, bottom: int) -> list[int] | None:
    """Joints from ``top``'s child down to ``bottom`` (inclusive), or None if ``bottom`` is not below ``top``."""
    path = []
    j = bottom
    while j >= 0 and j != top:
        path.append(j)
        j = parents[j]
    return path[::-1] if j == top else None


def map_to_canonical(
    motion: HumanMotion,
    name_map: str | dict[str, str] | None = None,
    source: str = "motion",
    pelvis_pos_m: np.ndarray | None = None,
    end_sites_m: dict[int, np.ndarray] | None = None,
) -> HumanMotion:
    """Retarget a motion on an arbitrary humanoid skeleton onto :data:`CANONICAL` (method in the module docstring).

    Parameters
    ----------
    motion : HumanMotion
        Source motion; its skeleton's offsets (metres) define the source rest pose.
    name_map : str or dict, optional
        Key of :data:`NAME_MAPS` or ``{canonical joint: source joint}``; default: detected from the joint names.
    source : str
        Name of the input, for error messages.
    pelvis_pos_m : ndarray [shape=(T, 3)], metres, optional
        Exact source world position of the mapped pelvis (e.g. with BVH position channels); default from FK.
    end_sites_m : dict of int to ndarray [shape=(3,)], metres, optional
        Source ``End Site`` offsets, used for the hand direction when no hand joint is mapped.

    Returns
    -------
    HumanMotion
        On :data:`CANONICAL`, same frame rate.
    """
    sk = motion.skeleton
    idx, _ = _select_map(sk.names, name_map, source)
    end_sites_m = end_sites_m or {}
    cn = CANONICAL.names
    _check_nesting(sk, idx, source)
    from robogest.motion.bvh import rest_positions

    p0 = rest_positions(sk)  # (J_s, 3) metres, source rest pose, root at the origin
    up = p0[idx["head"]] - p0[idx["pelvis"]]
    left = p0[idx["l_shoulder"]] - p0[idx["r_shoulder"]]
    a_mat = _axis_change(up, left)
    q_a = R.from_matrix(a_mat)

    g_s = sk.global_rotations(motion.rotations)  # (T, J_s, 4)
    n_frames = motion.n_frames
    g_c = np.empty((n_frames, CANONICAL.n_joints, 4))
    align: dict[str, np.ndarray] = {}
    rest = _RestPose(sk, idx, p0, a_mat, end_sites_m, rest_positions(CANONICAL), source)
    for j, name in enumerate(cn):
        parent = CANONICAL.parents[j]
        if name not in idx:
            g_c[:, j] = g_c[:, parent] if parent >= 0 else R.IDENTITY
            continue
        align[name] = rest.alignment(j, align)
        g_c[:, j] = R.mul(R.mul(R.mul(q_a, g_s[:, idx[name]]), R.conj(q_a)), align[name])

    local = np.empty_like(g_c)
    for j, p in enumerate(CANONICAL.parents):
        local[:, j] = g_c[:, j] if p < 0 else R.mul(R.conj(g_c[:, p]), g_c[:, j])
    root = _canonical_root(motion, idx, p0, a_mat, pelvis_pos_m, end_sites_m)
    return HumanMotion(fps=motion.fps, rotations=R.normalize(local), root_pos_m=root, skeleton=CANONICAL)


def _check_nesting(sk: Skeleton, idx: dict[str, int], source: str) -> None:
    """Each mapped joint must sit below its canonical parent's source joint, or the composition is meaningless."""
    cn = CANONICAL.names
    for c, s in idx.items():
        p = CANONICAL.parents[cn.index(c)]
        while p >= 0 and cn[p] not in idx:
            p = CANONICAL.parents[p]
        if p >= 0 and s != idx[cn[p]] and _descendant_path(sk.parents, idx[cn[p]], s) is None:
            raise InputError(
                f"{source}: name map puts {c}->{sk.names[s]} outside {cn[p]}->{sk.names[idx[cn[p]]]}'s subtree. "
                "Fix the name_map."
            )


@dataclass(frozen=True)
class _RestPose:
    """The source rest pose seen from the canonical skeleton: what turns each mapped source joint's frame so that
    its bone points along the canonical bone (the rest-pose alignment of the module docstring)."""

    sk: Skeleton
    idx: dict[str, int]  # canonical joint -> source joint
    p0: np.ndarray  # (J_s, 3) metres, source rest positions
    a_mat: np.ndarray  # (3, 3) source axes -> canonical axes
    end_sites_m: dict[int, np.ndarray]
    rest_c: np.ndarray  # (J_c, 3) metres, canonical rest positions
    source: str

    def alignment(self, j: int, align: dict[str, np.ndarray]) -> np.ndarray:
        """Quaternion (4,) for canonical joint ``j`` (mapped); ``align`` holds those of its mapped ancestors, which
        a hand or a bone without a direction continues."""
        cn = CANONICAL.names
        name, parent = cn[j], CANONICAL.parents[j]
        if name in _BONE_CHILD:
            child = _BONE_CHILD[name]
            d_s = self.bone_direction(self.idx[name], child)
            if d_s is None or np.linalg.norm(d_s) < 1e-9:
                if child in self.idx:
                    raise InputError(
                        f"{self.source}: {self.sk.names[self.idx[name]]} and {self.sk.names[self.idx[child]]} "
                        f"coincide in the rest pose, so the {name} bone has no direction. Fix the name_map."
                    )
                return align[cn[parent]]  # hand continues the forearm
            d_c = self.rest_c[cn.index(child)] - self.rest_c[j]
            return R.between(d_c, self.a_mat @ d_s)
        if name in ("l_hand", "r_hand"):
            return align[cn[parent]]
        return R.IDENTITY

    def bone_direction(self, s: int, child: str) -> np.ndarray | None:
        """Source rest direction (metres) from joint ``s`` towards canonical joint ``child``'s source joint; for a
        wrist without a mapped hand, its End Site or the mean of its children's offsets."""
        d_s = self.segment(s, self.idx[child]) if child in self.idx else None
        if d_s is None and child not in self.idx:  # wrist without a mapped hand joint
            kids = [k for k, p in enumerate(self.sk.parents) if p == s]
            if s in self.end_sites_m and np.linalg.norm(self.end_sites_m[s]) > 1e-6:
                d_s = self.end_sites_m[s]
            elif kids:
                d_s = np.mean(self.sk.offsets_m[kids], axis=0)
        return d_s

    def segment(self, j_src: int, target: int) -> np.ndarray | None:
        """The first non-zero rest offset from ``j_src`` along the path down to ``target`` (None if not below)."""
        path = _descendant_path(self.sk.parents, j_src, target)
        for k in path or []:
            d: np.ndarray = self.p0[k] - self.p0[j_src]
            if np.linalg.norm(d) > 1e-6:
                return d
        return None


def _canonical_root(
    motion: HumanMotion,
    idx: dict[str, int],
    p0: np.ndarray,
    a_mat: np.ndarray,
    pelvis_pos_m: np.ndarray | None,
    end_sites_m: dict[int, np.ndarray],
) -> np.ndarray:
    """Root position (T, 3), canonical world metres: the source pelvis in canonical axes, scaled to the canonical
    pelvis height when the source has legs (its pelvis sits well above its lowest point)."""
    pelvis = motion.positions()[:, idx["pelvis"]] if pelvis_pos_m is None else np.asarray(pelvis_pos_m, float)
    heights = p0 @ a_mat[1]  # (J_s,) rest height along the source up axis
    if end_sites_m:
        heights = np.concatenate([heights, [p0[j] @ a_mat[1] + o @ a_mat[1] for j, o in end_sites_m.items()]])
    drop = heights[idx["pelvis"]] - heights.min()
    trunk = heights[idx["head"]] - heights[idx["pelvis"]]
    k = CANONICAL_PELVIS_HEIGHT_M / drop if drop > 0.8 * trunk else 1.0  # legs present: normalise pelvis height
    root: np.ndarray = k * pelvis @ a_mat.T  # (T, 3) canonical world, metres
    return root


def map_bvh_to_canonical(
    data: BvhData, name_map: str | dict[str, str] | None = None, source: str = "BVH"
) -> HumanMotion:
    """:func:`map_to_canonical` for a parsed BVH, using its position channels for the exact pelvis position."""
    sk = data.motion.skeleton
    idx, _ = _select_map(sk.names, name_map, source)
    pelvis = idx["pelvis"]
    chain = []
    j = pelvis
    while j >= 0:
        chain.append(j)
        j = sk.parents[j]
    chain = chain[::-1]  # root ... pelvis
    g_s = data.motion.rotations
    pos = data.motion.root_pos_m.copy()  # (T, 3)
    g = g_s[:, chain[0]]
    for j in chain[1:]:
        pos = pos + R.rotate(g, data.translations_m[:, j])
        g = R.mul(g, g_s[:, j])
    return map_to_canonical(data.motion, name_map, source, pelvis_pos_m=pos, end_sites_m=data.end_sites_m)
