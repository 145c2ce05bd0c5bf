"""Find a robot's body parts from its kinematic tree at the zero pose, names second.

Legs are the chains that end at the robot's lowest points (the feet); the upper body's chains are grouped into
limbs by the joints they share (what all of them share is the waist); the two limbs that reach farthest from
bases at one height are the arms, the limb above them the head; fingers, grippers, eyes and jaw are the joints off
an arm's or the head's main chain. Every guess carries its reason, and each can be overridden by name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from robogest.errors import InputError
from robogest.tools.importer.tree import SIDES, WORDS, Tree, ordered, side_of, text_of

if TYPE_CHECKING:
    import mujoco

_ROLE_WORDS = {
    "shoulder": re.compile(r"shoulder|sho(_|\b)|upper_?arm|omoplate", re.I),
    "elbow": re.compile(r"elbow|elb(_|\b)|forearm|lower_?arm|bicep", re.I),
    "wrist": re.compile(r"wrist", re.I),
}


@dataclass
class Limb:
    """One chain of the robot and the sites on it (site role -> body name, position in that body's frame)."""

    part: str  # "left arm", "right arm", "arm", "head"
    joints: list[str]
    points: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)
    reason: str = ""
    twists: list[str] = field(default_factory=list)  # joints turning about their own bone, shoulder first


@dataclass
class Parts:
    """What :func:`find_parts` found; ``held`` maps each held joint to the part it belongs to."""

    arms: list[Limb]
    head: Limb | None
    held: dict[str, str]
    forward: np.ndarray  # unit, horizontal: where the robot faces, in the description's frame
    forward_reason: str
    rows: list[tuple[str, list[str], str]] = field(default_factory=list)  # part, joints, reason (the table)


def find_parts(m: mujoco.MjModel, d: mujoco.MjData, joints: list[str], overrides: dict) -> Parts:
    """Legs, waist, arms, head, fingers of the model at the pose in ``d``; ``overrides`` (``arms: {left: [..],
    right: [..]}``, ``head: [..]``, ``forward: "+y"``) replace a guess. Raises InputError for an override naming a
    joint the model lacks, or when no arm is found."""
    tree = Tree(m, d, joints)
    known = set(joints)
    for part, names in [*((f"--arm {s}", v) for s, v in (overrides.get("arms") or {}).items()),
                        ("--head", overrides.get("head") or [])]:  # fmt: skip
        bad = [n for n in names if n not in known]
        if bad:
            raise InputError(f"{part}: {bad} are not hinge joints of the model; choose from {joints}")
    chains = {leaf: tree.chain(leaf) for leaf in tree.leaves}
    chains = {leaf: c for leaf, c in chains.items() if c}
    if not chains:
        raise InputError("no revolute or continuous joints; robogest drives hinge joints")
    table = _Table()
    feet, upper, legs, hips = _lower_body(tree, chains, table)
    limbs, trunk = _upper_limbs(tree, chains, upper, legs)
    arms, head = _pick(tree, limbs, overrides)
    if overrides.get("head"):
        head = (set(tree.m.joint(n).id for n in overrides["head"]), head[1] if head else [])
    picked: set[int] = set().union(*(a[0] for a in arms)) if arms else set()
    if not arms:
        raise InputError("found no chain of 2 or more joints spaced apart to map a human arm onto; "
                         "name the arm joints with --arm left=J1,J2,... --arm right=...")  # fmt: skip
    forward, why = _forward(tree, arms, feet, chains, legs, overrides.get("forward"))
    out_arms = _arm_limbs(tree, arms, forward, overrides)
    if len(out_arms) == 1 and not feet and head is None and not overrides.get("forward"):
        forward, why = _reach_forward(tree, out_arms[0], forward, why)
    for a in out_arms:
        table.rows.append((a.part, a.joints, a.reason))
    arm_ids = {tree.m.joint(n).id for a in out_arms for n in a.joints}
    head_limb = _head(tree, head, forward, arm_ids) if head else None
    fingers = picked - arm_ids
    if head is not None and head_limb is not None:
        table.rows.append(("head", head_limb.joints, head_limb.reason))
        fingers |= head[0] - {tree.m.joint(n).id for n in head_limb.joints}
    mapped = arm_ids | ({tree.m.joint(n).id for n in head_limb.joints} if head_limb else set())
    _hold_unmapped(tree, table, fingers - arm_ids, (trunk | hips) - mapped, mapped)
    _hold_given(table, overrides, known, joints)
    return Parts(out_arms, head_limb, table.held, forward, why, table.rows)


#: A limb found in the tree: its hinge joint ids and the leaf bodies its chains end at.
_Group = tuple[set[int], list[int]]


@dataclass
class _Table:
    """The parts table :func:`find_parts` fills: rows (part, joints, why) and each held joint's part."""

    rows: list[tuple[str, list[str], str]] = field(default_factory=list)
    held: dict[str, str] = field(default_factory=dict)


def _lower_body(
    tree: Tree, chains: dict[int, list[int]], table: _Table
) -> tuple[list[int], list[int], set[int], set[int]]:
    """The legs (held): chains ending at the lowest points of the robot, below the body where they meet (the
    pelvis), else chains named as legs. Returns the feet, the leaves of the upper body, the leg joints and the
    joints above the hips; when every chain reaches the floor there are no legs (nothing else to gesture with)."""
    floor = tree.lo[2] + 0.12 * tree.height
    feet = [leaf for leaf in chains if tree.low(leaf) < floor and len(chains) > 1]
    legs, hips = _legs(tree, feet, chains)
    why_legs = "held: the chain ends at the robot's lowest point (a foot)"
    if not legs:  # feet off the floor (a humanoid on a pedestal): legs by their names
        named = [lf for lf, c in chains.items()
                 if WORDS["leg"].search(text_of(tree, c)) and not WORDS["arm"].search(text_of(tree, c))]  # fmt: skip
        legs, hips = _legs(tree, named, chains)
        feet = named if legs else feet
        why_legs = "held: named as a leg (its foot does not reach the floor)"
    upper = [leaf for leaf in chains if not set(chains[leaf]) <= legs | hips]
    if not upper:  # everything reaches the floor: nothing to gesture with
        feet, upper, legs, hips = [], list(chains), set(), set()
    for side in ("left", "right", None):
        leg_feet = [f for f in feet if side_of(text_of(tree, [j for j in chains[f] if j in legs])) == side]
        js = ordered(tree, {j for f in leg_feet for j in chains[f]} & legs)
        if js:
            label = f"{side} leg" if side else "leg"
            table.rows.append((label, [tree.name(j) for j in js], why_legs))
            table.held.update(dict.fromkeys((tree.name(j) for j in js), "leg"))
    rest_legs = legs - {tree.m.joint(n).id for n in table.held}
    if rest_legs:
        table.rows.append(("leg", [tree.name(j) for j in ordered(tree, rest_legs)], "held: below the hips"))
        table.held.update(dict.fromkeys((tree.name(j) for j in rest_legs), "leg"))
    return feet, upper, legs, hips


def _upper_limbs(
    tree: Tree, chains: dict[int, list[int]], upper: list[int], legs: set[int]
) -> tuple[list[_Group], set[int]]:
    """The upper body's limbs and its trunk: what every chain shares is the waist; the rest splits into limbs by
    shared joints. A leaf whose joints all lie on another leaf's chain (a servo horn, a sensor) says nothing about
    the branches."""
    tips = [u for i, u in enumerate(upper) if not any(set(chains[u]) < set(chains[v]) or
                                                       (set(chains[u]) == set(chains[v]) and k < i)
                                                       for k, v in enumerate(upper))]  # fmt: skip
    trunk = set.intersection(*(set(chains[u]) for u in tips)) - legs
    limbs = _limbs(tree, {u: [j for j in chains[u] if j not in trunk and j not in legs] for u in upper})
    if len(limbs) <= 1 and trunk:  # one chain (a desk arm): the shared joints are the arm's
        limbs = _limbs(tree, {u: [j for j in chains[u] if j not in legs] for u in upper})
        trunk = set()
    return limbs, trunk


def _arm_limbs(
    tree: Tree, arms: list[tuple[set[int], list[int], str]], forward: np.ndarray, overrides: dict
) -> list[Limb]:
    """The picked arms as limbs with their sites, left before right; two arms that their names do not tell apart
    are told by where they sit (left of ``forward``)."""
    left_dir = np.cross([0.0, 0.0, 1.0], forward)
    given = {side: {tree.m.joint(n).id for n in names} for side, names in (overrides.get("arms") or {}).items()}
    out_arms = [
        _arm(tree, joints_, leaves, len(arms), label, given.get(label.split()[0])) for joints_, leaves, label in arms
    ]
    if len(out_arms) == 2 and out_arms[0].part == out_arms[1].part:  # no names: the side is where it sits
        a, b = out_arms
        base = [tree.d.xanchor[tree.m.joint(x.joints[0]).id] @ left_dir for x in (a, b)]
        a.part, b.part = ("left arm", "right arm") if base[0] > base[1] else ("right arm", "left arm")
        a.reason += "; side from where it sits"
        b.reason += "; side from where it sits"
    out_arms.sort(key=lambda a: a.part)
    return out_arms


def _hold_unmapped(tree: Tree, table: _Table, fingers: set[int], waist_ids: set[int], mapped: set[int]) -> None:
    """Hold what no arm or head moves: fingers, eyes and jaw; the waist (shared by every upper-body chain); and
    every other joint."""
    if fingers:
        table.rows.append(("fingers/eyes/jaw", [tree.name(j) for j in ordered(tree, fingers)],
                           "held: short chains after a wrist or on the head, or named so"))  # fmt: skip
        table.held.update(dict.fromkeys((tree.name(j) for j in fingers), "finger"))
    waist = ordered(tree, waist_ids)
    if waist:
        table.rows.append(("waist", [tree.name(j) for j in waist], "held: shared by every upper-body chain "
                           "(between pelvis and chest); map it with --arm/--head to move it"))  # fmt: skip
        table.held.update(dict.fromkeys((tree.name(j) for j in waist), "waist"))
    rest = [j for j in tree.jids if tree.name(j) not in table.held and j not in mapped]
    if rest:
        table.rows.append(("other", [tree.name(j) for j in rest], "held: on no arm or head chain"))
        table.held.update(dict.fromkeys((tree.name(j) for j in rest), "other"))


def _hold_given(table: _Table, overrides: dict, known: set[str], joints: list[str]) -> None:
    """The joints given with ``--hold`` that are not held already; InputError for one the model lacks."""
    for name, q in (overrides.get("hold") or {}).items():
        if name not in known:
            raise InputError(f"--hold {name}={q}: {name!r} is not a hinge joint of the model; choose from {joints}")
    given = [n for n in (overrides.get("hold") or {}) if table.held.get(n) is None]
    if given:
        table.rows.append(("held (given)", given, "held at the angle given with --hold"))
        table.held.update(dict.fromkeys(given, "given"))


def _legs(tree: Tree, feet: list[int], chains: dict[int, list[int]]) -> tuple[set[int], set[int]]:
    """The leg joints (every hinge in the subtrees below the body where the feet's chains meet) and the joints
    from the root down to that body (a waist above the hips when the root is the chest)."""
    if len(feet) < 2:
        return set(), set()
    m = tree.m
    paths = []
    for f in feet:
        path, b = [], f
        while b > 0:
            path.append(b)
            b = int(m.body_parentid[b])
        paths.append(path)
    common = set(paths[0]).intersection(*paths[1:])
    meet = next((b for b in paths[0] if b in common), 0)
    tops = {p[p.index(meet) - 1] if meet in p else p[-1] for p in paths}
    inside: set[int] = set()
    todo = list(tops)
    while todo:
        b = todo.pop()
        inside.add(b)
        todo += tree.kids.get(b, [])
    legs = {j for j in tree.jids if int(m.jnt_bodyid[j]) in inside}
    return legs, (set(tree.chain(meet)) if meet > 0 else set())


def _limbs(tree: Tree, exclusive: dict[int, list[int]]) -> list[tuple[set[int], list[int]]]:
    """Leaves whose chains share a joint are one limb: (joint ids, leaves)."""
    limbs: list[tuple[set[int], list[int]]] = []
    for leaf, js in exclusive.items():
        if not js:
            continue
        joined = [lb for lb in limbs if lb[0] & set(js)]
        merged = (set(js).union(*(lb[0] for lb in joined)), [leaf] + [x for lb in joined for x in lb[1]])
        limbs = [lb for lb in limbs if lb not in joined] + [merged]
    return limbs


def _reach(tree: Tree, joints: set[int], leaves: list[int]) -> tuple[np.ndarray, float]:
    first = ordered(tree, joints)[0]
    base = tree.d.xanchor[first]
    return base, max(float(np.linalg.norm(tree.tip(lf, base) - base)) for lf in leaves)


def _pick(
    tree: Tree, limbs: list[_Group], overrides: dict
) -> tuple[list[tuple[set[int], list[int], str]], _Group | None]:
    """The arms (up to two: (joints, leaves, label)) and the head (joints, leaves) among the limbs."""
    m = tree.m
    given = overrides.get("arms") or {}
    if given:
        arms = []
        for side, names in given.items():
            ids = {m.joint(n).id for n in names}
            leaves = [lf for js, lvs in limbs if js & ids for lf in lvs] or [int(m.jnt_bodyid[max(ids)])]
            arms.append((ids | {j for js, _ in limbs if js & ids for j in js}, leaves, f"{side} arm (given)"))
        rest = [lb for lb in limbs if not any(lb[0] & a[0] for a in arms)]
    else:
        scored = []
        for js, leaves in limbs:
            text = text_of(tree, ordered(tree, js))
            base, reach = _reach(tree, js, leaves)
            points = len({tuple(np.round(tree.d.xanchor[j], 2)) for j in js})
            named_other = (WORDS["head"].search(text) or WORDS["leg"].search(text)) and not WORDS["arm"].search(text)
            if points >= 2 and not named_other:
                scored.append((reach, base, js, leaves, text))
        scored.sort(key=lambda s: -s[0])
        arms = []
        if scored:
            a = scored[0]
            # its partner: the longest other limb whose base is at about the same height
            mate = next((s for s in scored[1:] if abs(s[1][2] - a[1][2]) < 0.15 * tree.height
                         and s[0] > 0.5 * a[0]), None)  # fmt: skip
            for s in [a] + ([mate] if mate else []):
                side = side_of(s[4])
                label = f"{side} arm" if mate and side else "arm"
                arms.append((s[2], s[3], label))
            if len(arms) == 2 and arms[0][2] == arms[1][2] != "arm":
                arms = [(js, lv, "arm") for js, lv, _ in arms]
        rest = [lb for lb in limbs if not any(lb[0] is a[0] for a in arms)]
    # the head: the limb that rises highest above the arms' bases, or one named so
    top = max((tree.d.xanchor[ordered(tree, a[0])[0]][2] for a in arms), default=tree.lo[2])
    heads = []
    for js, leaves in rest:
        base = tree.d.xanchor[ordered(tree, js)[0]]
        high = max(tree.d.xpos[lf][2] for lf in leaves)
        named = bool(WORDS["head"].search(text_of(tree, ordered(tree, js))))
        if named or (base[2] > top - 0.1 * tree.height and high > top):
            heads.append((named, high, js, leaves))
    heads.sort(key=lambda h: (h[0], h[1]), reverse=True)
    return arms, ((heads[0][2], heads[0][3]) if heads else None)


def _twist(tree: Tree, j: int, tip: np.ndarray) -> bool:
    """A joint turning about its own bone (axis along the way to the tip) bends nothing: not a site."""
    v = tip - tree.d.xanchor[j]
    n = np.linalg.norm(v)
    return bool(n > 1e-6 and abs(tree.d.xaxis[j] @ v / n) > 0.9)


def _arm(tree: Tree, joints: set[int], leaves: list[int], n_arms: int, label: str, given: set[int] | None) -> Limb:
    """The arm's main chain (to the leaf that reaches farthest: the hand), its shoulder/elbow/wrist/hand sites (a
    joint turning about its own bone is no site), and why. Joints past the wrist, or named as fingers, are not."""
    m = tree.m
    base = tree.d.xanchor[ordered(tree, joints)[0]]
    leaf = max(leaves, key=lambda lf: float(np.linalg.norm(tree.tip(lf, base) - base)))  # the hand
    chain = ordered(tree, set(tree.chain(leaf)) & joints)
    if given:  # the arm named on the command line: those joints and no others gesture
        chain = [j for j in chain if j in given]
    tip = tree.tip(leaf, tree.d.xanchor[chain[-1]])
    reach = float(np.linalg.norm(tip - base))
    named_fingers = [j for j in chain if WORDS["finger"].search(tree.name(j)) and not WORDS["arm"].search(tree.name(j))]
    chain = [j for j in chain if j not in named_fingers]
    tol = max(0.01, 0.08 * reach)
    groups: list[list[int]] = []
    lead: list[int] = []  # twists before the first point (a desk arm's base pan): arm joints, not sites
    for j in chain:
        if _twist(tree, j, tip):
            (groups[-1] if groups else lead).append(j)
            continue
        if groups and np.linalg.norm(tree.d.xanchor[j] - tree.d.xanchor[groups[-1][0]]) < tol:
            groups[-1].append(j)
        else:
            groups.append([j])
    if not groups:  # nothing but twists: the first one is the shoulder
        if not lead:
            named = sorted(tree.name(j) for j in (given or joints))
            raise InputError(f"{label}: joints {named} lie on no chain to a hand; name the arm's joints from the "
                             "shoulder outwards")  # fmt: skip
        groups, lead = [lead], []
    names = [" ".join(f"{tree.name(j)} {m.body(m.jnt_bodyid[j]).name}".lower() for j in g) for g in groups]
    said = {r: [i for i, n in enumerate(names) if pat.search(n)] for r, pat in _ROLE_WORDS.items()}
    roles: dict[str, int] = {}
    if said["shoulder"] and said["elbow"] and said["shoulder"][0] < said["elbow"][0]:
        elbow = said["elbow"][0]
        roles = {"shoulder": max(i for i in said["shoulder"] if i < elbow), "elbow": elbow}
        wrist = [i for i in said["wrist"] if i > roles["elbow"]]
        if wrist:
            roles["wrist"] = wrist[0]
        how = "roles from the joint and link names"
    else:
        first = 1 if len(groups) >= 4 and n_arms == 1 and abs(tree.d.xaxis[groups[0][0]][2]) > 0.9 else 0
        roles = {r: i + first for i, r in enumerate(("shoulder", "elbow", "wrist")) if i + first < len(groups)}
        how = "roles from the points where the chain bends, in order"
    last = max(roles.values())
    arm_joints = lead + [j for g in groups[: last + 1] for j in g]
    # a 2-DoF wrist whose second axis sits a little further on: named so, it still gestures
    arm_joints += [j for g in groups[last + 1 :] for j in g if _ROLE_WORDS["wrist"].search(tree.name(j))]
    points = {r: tree.local(int(m.jnt_bodyid[groups[i][0]]), tree.d.xanchor[groups[i][0]]) for r, i in roles.items()}
    points["hand"] = tree.local(leaf, tip)
    side = label.split()[0] if label.endswith("arm") and label != "arm" else ""
    where = ", ".join(f"{r} at {tree.name(groups[i][0])}" for r, i in roles.items())
    reason = f"{'named ' + side + '; ' if side else ''}{how}: {where}, hand at the end of {m.body(leaf).name}"
    part = f"{side} arm".strip() if side else "arm"
    twists = [tree.name(j) for j in arm_joints if _twist(tree, j, tip)]
    limb = Limb(part, [tree.name(j) for j in arm_joints], points, reason, twists)
    if label.endswith("(given)"):
        limb.part = label.removesuffix(" (given)")
        limb.reason = "given on the command line; " + reason
    return limb


def _head(tree: Tree, head: _Group, forward: np.ndarray, arm_ids: set[int]) -> Limb | None:
    """The head's main chain (what its leaves share; eyes and jaw branch off) and the neck/head/face sites."""
    js, leaves = head
    m = tree.m
    main = set.intersection(*(set(tree.chain(lf)) for lf in leaves)) & js if leaves else set(js)
    chain = [j for j in ordered(tree, main or js) if j not in arm_ids]
    chain = [j for j in chain if not re.search(r"eye|jaw|mouth|lid|brow", tree.name(j), re.I)] or chain
    if not chain:
        return None
    first, last = chain[0], chain[-1]
    size = max(0.04, 0.08 * tree.height)
    top = tree.d.xanchor[last] + np.array([0.0, 0.0, size])
    body = int(m.jnt_bodyid[last])
    points = {
        "neck": tree.local(int(m.body_parentid[m.jnt_bodyid[first]]), tree.d.xanchor[first]),
        "head": tree.local(body, top),
        "face": tree.local(body, top + size * (0.78 * forward + np.array([0.0, 0.0, 0.62]))),  # as a person's nose
    }
    return Limb("head", [tree.name(j) for j in chain], points, "the chain above the shoulders" +
                (" (named so)" if WORDS["head"].search(text_of(tree, chain)) else ""))  # fmt: skip


def _forward(
    tree: Tree,
    arms: list[tuple[set[int], list[int], str]],
    feet: list[int],
    chains: dict[int, list[int]],
    legs: set[int],
    given: str | None,
) -> tuple[np.ndarray, str]:
    """Where the robot faces in the description's frame: given; else from the arms' (or legs') left/right names;
    else from where the feet point; else +X."""
    axes = {"+x": (1, 0), "-x": (-1, 0), "+y": (0, 1), "-y": (0, -1)}
    if given:
        x, y = axes[given]
        return np.array([x, y, 0.0]), f"{given} (given with --forward)"
    d = tree.d
    for what, groups in (("arms", [(a[0], side_of(text_of(tree, ordered(tree, a[0])))) for a in arms]),
                         ("legs", [(set(chains[f]) & legs, side_of(text_of(tree, ordered(tree, set(chains[f]) & legs))))
                                   for f in feet])):  # fmt: skip
        sides = {s: [d.xanchor[ordered(tree, js)[0]] for js, s2 in groups if s2 == s and js] for s in SIDES}
        if sides["left"] and sides["right"]:
            lat = np.mean(sides["left"], axis=0) - np.mean(sides["right"], axis=0)
            lat[2] = 0
            if np.linalg.norm(lat) > 1e-3:
                front = np.cross(lat / np.linalg.norm(lat), [0.0, 0.0, 1.0])
                return _axis(front), f"{_label(_axis(front))}: the left {what} are on its left (from their names)"
    toes = []
    for f in feet:
        js = ordered(tree, set(chains[f]) & legs)
        if js:
            v = d.xpos[f] - d.xanchor[js[-1]]
            g = [i for i in tree.robot_geoms if tree.m.geom_bodyid[i] == f]
            if g:
                v = 0.5 * (tree.glo[g].min(axis=0) + tree.ghi[g].max(axis=0)) - d.xanchor[js[-1]]
            toes.append(v)
    if toes:
        v = np.mean(toes, axis=0)
        v[2] = 0
        if np.linalg.norm(v) > 0.005:
            return _axis(v), f"{_label(_axis(v))}: where the feet point"
    return np.array([1.0, 0.0, 0.0]), "+x: the convention (nothing in the description says otherwise)"


def _reach_forward(tree: Tree, arm: Limb, forward: np.ndarray, why: str) -> tuple[np.ndarray, str]:
    """A single arm that reaches sideways at joint zero faces where it reaches (nothing else says where its front
    is); one that stands up keeps ``forward``."""
    m, d = tree.m, tree.d

    def world(role: str) -> np.ndarray:
        body, pos = arm.points[role]
        b = m.body(body).id
        point: np.ndarray = d.xpos[b] + d.xmat[b].reshape(3, 3) @ pos
        return point

    v = world("hand") - world("shoulder")
    if np.linalg.norm(v[:2]) < 0.5 * np.linalg.norm(v):
        return forward, why
    v[2] = 0
    f = v / np.linalg.norm(v)
    return f, f"{np.degrees(np.arctan2(f[1], f[0])):+.0f} deg from +X: where the single arm reaches at joint zero"


def _axis(v: np.ndarray) -> np.ndarray:
    """The horizontal axis (+-x, +-y) nearest ``v``: descriptions face along one."""
    i = int(np.argmax(np.abs(v[:2])))
    out = np.zeros(3)
    out[i] = np.sign(v[i])
    return out


def _label(f: np.ndarray) -> str:
    i = int(np.argmax(np.abs(f[:2])))
    return ("+" if f[i] > 0 else "-") + "xy"[i]
