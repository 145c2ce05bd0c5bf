"""The compiled model as :mod:`~robogest.tools.importer.parts` reads it: bodies, hinge chains from the root to each
leaf, where they sit at a pose, and the words in joint and link names that say what a chain is and its side."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

from robogest.tools.importer.model import geom_boxes

if TYPE_CHECKING:
    import mujoco

#: Words in joint or link names that say what a chain is (used after the tree, to break ties and name sides).
WORDS = {
    "head": re.compile(r"head|neck|eye|jaw|mouth|brow|lid|face|cam", re.I),
    "leg": re.compile(r"hip|knee|ank|foot|feet|leg|thigh|shin|toe|calf", re.I),
    "arm": re.compile(r"arm|sho|elb|wrist|hand|bicep|omoplate|clav", re.I),
    "finger": re.compile(r"finger|thumb|index|middle|ring|pinky|grip|claw|jaw|eye|mouth|lid|brow", re.I),
}
SIDES = {
    "left": re.compile(r"(^|[_\W\d])(l|left)([_\W\d]|$)|^left|left$|^l[A-Z]", re.I),
    "right": re.compile(r"(^|[_\W\d])(r|right)([_\W\d]|$)|^right|right$|^r[A-Z]", re.I),
}


class Tree:
    """The compiled model's bodies, hinge joints and the points they sit at, at the pose in ``d``."""

    def __init__(self, m: mujoco.MjModel, d: mujoco.MjData, joints: list[str]) -> None:
        self.m, self.d = m, d
        self.jids = [m.joint(j).id for j in joints]
        self.jset = set(self.jids)
        kids: dict[int, list[int]] = {}
        for b in range(1, m.nbody):
            kids.setdefault(int(m.body_parentid[b]), []).append(b)
        self.kids = kids
        self.leaves = [b for b in range(1, m.nbody) if b not in kids]
        robot = m.body_rootid[m.geom_bodyid] != 0 if m.ngeom else np.zeros(0, bool)
        self.glo, self.ghi = geom_boxes(m, d)
        self.robot_geoms = np.flatnonzero(robot)
        pts = np.vstack([self.glo[robot], self.ghi[robot], d.xpos[1:]]) if m.nbody > 1 else np.zeros((1, 3))
        self.lo, self.hi = pts.min(axis=0), pts.max(axis=0)
        self.height = max(float(self.hi[2] - self.lo[2]), 1e-3)

    def name(self, j: int) -> str:
        return str(self.m.joint(j).name)

    def chain(self, body: int) -> list[int]:
        """Hinge joints from the root down to ``body``, root first."""
        m, out = self.m, []
        while body > 0:
            adr = m.body_jntadr[body]
            out += [j for j in range(adr, adr + m.body_jntnum[body]) if j in self.jset][::-1]
            body = int(m.body_parentid[body])
        return out[::-1]

    def low(self, body: int) -> float:
        g = [i for i in self.robot_geoms if self.m.geom_bodyid[i] == body]
        return float(self.glo[g, 2].min()) if g else float(self.d.xpos[body][2])

    def tip(self, leaf: int, last: np.ndarray) -> np.ndarray:
        """The end of a leaf link: its geoms' point farthest from ``last`` (the link's origin if it has none)."""
        m, d = self.m, self.d
        best: np.ndarray = d.xpos[leaf].copy()
        far = float(np.linalg.norm(d.xpos[leaf] - last))
        for g in range(m.ngeom):
            if m.geom_bodyid[g] != leaf:
                continue
            v = d.geom_xpos[g] - last
            n = float(np.linalg.norm(v))
            p = d.geom_xpos[g] + v / n * float(np.max(m.geom_size[g])) if n > 1e-9 else d.geom_xpos[g]
            if np.linalg.norm(p - last) > far:
                best, far = p, float(np.linalg.norm(p - last))
        return best

    def local(self, body: int, world: np.ndarray) -> tuple[str, np.ndarray]:
        """Body ``body``'s name and the point ``world`` in its frame."""
        xmat = self.d.xmat[body].reshape(3, 3)
        local: np.ndarray = xmat.T @ (world - self.d.xpos[body])
        return str(self.m.body(body).name), local


def ordered(tree: Tree, joints: set[int]) -> list[int]:
    """``joints`` in the model's joint order."""
    return [j for j in tree.jids if j in joints]


def text_of(tree: Tree, joints: list[int]) -> str:
    """The names of ``joints`` and of the links they move, for the name patterns."""
    m = tree.m
    return " ".join(f"{m.joint(j).name} {m.body(m.jnt_bodyid[j]).name}" for j in joints)


def side_of(text: str) -> str | None:
    """ "left" or "right" when the names say exactly one of them, else None."""
    hits = [s for s, pat in SIDES.items() if any(pat.search(w) for w in text.split())]
    return hits[0] if len(hits) == 1 else None
