"""Joints grouped by limb, with one colour per group and a line style per joint, and a legend with one column
per group: eleven or thirty lines in default colours cannot be told apart, a limb's colour can."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend

    from robogest.robot.config import RobotConfig

#: Groups in legend order, with their colours.
GROUP_COLOURS = {
    "left arm": "tab:blue",
    "right arm": "tab:orange",
    "arm": "tab:red",
    "head": "tab:green",
    "waist": "tab:purple",
    "legs": "tab:brown",
    "other": "tab:gray",
}
_LINE_STYLES = ("-", "--", ":", "-.")
#: Name parts that say which group a joint belongs to, checked in this order (``hip`` is a leg's, not the waist's).
_GROUP_WORDS = (
    ("head", {"head", "neck", "eye", "eyes", "jaw", "ear", "ears", "mouth", "face"}),
    ("legs", {"hip", "knee", "ankle", "leg", "foot", "toe", "thigh", "shin", "calf"}),
    ("waist", {"torso", "waist", "spine", "trunk", "chest", "abdomen", "base", "body", "pelvis"}),
    ("arm", {"shoulder", "elbow", "wrist", "hand", "arm", "forearm", "finger", "thumb", "gripper", "claw"}),
)


@dataclass(frozen=True)
class JointStyle:
    """How one joint is drawn: its group, colour (RGB in [0, 1]) and line style."""

    group: str
    colour: tuple[float, float, float]
    line_style: str


def joint_group(name: str) -> str:
    """The limb a joint belongs to, from its name: ``l_elbow`` -> left arm, ``head_pan`` -> head, ``knee`` -> legs.
    A side with no limb word (``l_foo``) is not guessed to be an arm: it goes to ``other``."""
    words = [w for w in re.split(r"[^a-z0-9]+", name.lower()) if w]
    side = ""
    if words and (words[0] in ("l", "left") or words[-1] in ("l", "left") or "left" in words):
        side = "left"
    elif words and (words[0] in ("r", "right") or words[-1] in ("r", "right") or "right" in words):
        side = "right"
    for group, vocab in _GROUP_WORDS:
        if vocab.intersection(words) or any(w.startswith(tuple(vocab)) for w in words if len(w) > 3):
            return f"{side} arm" if group == "arm" and side else group
    return "other"


def joint_groups(joint_names: list[str], robot: RobotConfig | None = None) -> dict[str, list[int]]:
    """Joint indices per group, groups in :data:`GROUP_COLOURS` order (empty ones left out).

    An imported robot's YAML records which joints are its arms and head (``import: arms:, head:``); those win over
    the names.
    """
    known: dict[str, str] = {}
    record = robot.import_record if robot is not None else None
    if record is not None:
        for side, names in record.arms.items():
            known.update({n: f"{side} arm" for n in names})
        known.update({n: "head" for n in record.head})
    groups: dict[str, list[int]] = {g: [] for g in GROUP_COLOURS}
    for j, name in enumerate(joint_names):
        groups[known.get(name) or joint_group(name)].append(j)
    return {g: idx for g, idx in groups.items() if idx}


def joint_styles(joint_names: list[str], robot: RobotConfig | None = None) -> list[JointStyle]:
    """One style per joint: the group's colour, line styles cycling within the group, then darker and lighter
    shades of the colour once the four line styles are used up (a humanoid leg has six joints)."""
    from matplotlib.colors import to_rgb

    styles: dict[int, JointStyle] = {}  # every joint is in a group ("other" at least)
    for group, idx in joint_groups(joint_names, robot).items():
        r, g, b = to_rgb(GROUP_COLOURS[group])
        for k, j in enumerate(idx):
            shade = (k // len(_LINE_STYLES)) % 3  # 0: the colour, 1: darker, 2: lighter
            mix, towards = ((0.0, 0.0), (0.4, 0.0), (0.45, 1.0))[shade]
            colour = (r + (towards - r) * mix, g + (towards - g) * mix, b + (towards - b) * mix)
            styles[j] = JointStyle(group, colour, _LINE_STYLES[k % len(_LINE_STYLES)])
    return [styles[j] for j in range(len(joint_names))]


def column_legend(
    fig: Figure, columns: dict[str, list[tuple[Artist, str]]], *, fontsize: float | str, frameon: bool
) -> Legend:
    """A figure legend below the axes with one column per key of ``columns`` (``header -> [(handle, label)]``),
    the header in bold on top: entries are padded with blanks so that no group runs on into the next column;
    ``fontsize`` and ``frameon`` as for ``Figure.legend``."""
    from matplotlib.lines import Line2D

    height = 1 + max(len(v) for v in columns.values())
    handles: list[Artist] = []
    labels: list[str] = []
    headers: set[int] = set()
    for header, entries in columns.items():
        headers.add(len(labels))
        blank = [(Line2D([], [], linestyle="none"), "")] * (height - 1 - len(entries))
        for h, label in [(Line2D([], [], linestyle="none"), header), *entries, *blank]:
            handles.append(h)
            labels.append(label)
    legend = fig.legend(
        handles, labels, ncols=len(columns), loc="outside lower center", fontsize=fontsize, frameon=frameon
    )
    for i, text in enumerate(legend.get_texts()):
        if i in headers:
            text.set_fontweight("bold")
    return legend
