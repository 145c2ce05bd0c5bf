"""Read a robot description (URDF, xacro or MJCF) into one XML tree, confined to the description's own folders.

Real descriptions are messy; each repair here is one warning line, never an internal error: a joint whose
``lower`` is above its ``upper`` (a reversed servo range), ``velocity="0"`` or ``effort="0"``, missing or zero
inertials, gazebo and transmission plugins, a ``world`` link or a ``floating`` joint.

Every file read (the description, xacro includes, meshes) must lie inside the description's tree (the folder of
the file and the package folders above it) or a folder the user names (``--search-path``), after resolving
symlinks and ``..``; anything else is refused naming the path.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from robogest.errors import InputError, MissingDependencyError
from robogest.extras import install_command
from robogest.fileio import read_text_capped

#: Servo model names a description may mention (links, joints, meshes, transmissions), per bus family.
SERVO_WORDS = {
    "dynamixel": re.compile(
        r"(?<![a-z0-9])((?:2X[LC]|X[LCMHWD]|MX|AX|RX|EX|PH|PM|H[45]2)[-_]?\d{2,3}"
        r"(?:[-_][A-Z]\d{2,3})?)",
        re.I,
    ),
    "feetech": re.compile(r"(?<![a-z0-9])((?:STS|SCS|SMS|SM|HLS)[-_]?\d{3,4}[A-Z]?)", re.I),
}
#: How far above the description a ``package://NAME`` or ``$(find NAME)`` folder is searched.
PACKAGE_LEVELS = 4


@dataclass
class Description:
    """One description, read: ``root`` is a URDF ``<robot>`` (xacro expanded) or an MJCF ``<mujoco>``."""

    path: Path
    kind: str  # "urdf" or "mjcf"
    root: ET.Element
    roots: list[Path]  # folders whose files may be read
    warnings: list[str] = field(default_factory=list)
    servo_models: dict[str, str] = field(default_factory=dict)  # joint -> servo model named near it
    floating: bool = False  # a floating base (a URDF floating joint or free root, an MJCF freejoint)


def allowed_roots(path: Path, search_paths: Sequence[Path]) -> list[Path]:
    """The description's tree, then the folders the user names. The tree is the nearest ROS package at or above the
    file (a folder with ``package.xml`` or ``manifest.xml``, where ``urdf/`` sits beside ``meshes/``), else the
    folder above the file's (``robot/urdf/x.urdf`` with ``robot/meshes/``) unless that is a home folder, ``/tmp``,
    ``/`` or above one of them (``/home``): then the file's own folder."""
    here = path.resolve().parent
    shared = [Path.home().resolve(), Path("/tmp").resolve(), Path("/var/tmp")]

    def too_wide(folder: Path) -> bool:  # a shared folder or one above it (/home holds every user's home)
        return folder == Path(folder.anchor) or any(folder == f or folder in f.parents for f in shared)

    tree = next(
        (f for f in [here, *here.parents][:PACKAGE_LEVELS] if not too_wide(f) and ((f / "package.xml").is_file() or
         (f / "manifest.xml").is_file())),
        here if too_wide(here.parent) else here.parent,
    )  # fmt: skip
    return [tree] + [Path(p).resolve() for p in search_paths]


def confined(path: Path, roots: list[Path], what: str, source: Path) -> Path:
    """``path`` with symlinks and ``..`` resolved, if it lies inside one of ``roots``; else an InputError."""
    real = Path(os.path.realpath(path))
    if not any(real == r or r in real.parents for r in roots):
        raise InputError(
            f"{source}: {what} {path} lies outside the description's folders ({roots[0]} and the package folders "
            "above it); robogest reads nothing else: copy it there or name its folder with --search-path DIR"
        )
    return real


def find_package(name: str, roots: list[Path]) -> Path | None:
    """The folder of ROS package ``name`` (``package://NAME``, ``$(find NAME)``) without a ROS installation: one of
    ``roots``, a folder directly below one, or a package (``package.xml``) beside the description's own; a package
    found beside it joins ``roots``."""
    for r in roots:
        if r.name == name:
            return r
        if (r / name).is_dir():
            return (r / name).resolve()
    sibling = roots[0].parent / name
    if (sibling / "package.xml").is_file() or (sibling / "manifest.xml").is_file():
        roots.append(sibling.resolve())
        return roots[-1]
    return None


def read_description(path: Path, search_paths: Sequence[Path] = ()) -> Description:
    """Read ``path`` (``.urdf``, ``.xacro``/``.urdf.xacro``, ``.xml``/``.mjcf``) and repair what real descriptions
    get wrong; an unreadable or foreign file is one :class:`InputError` naming it."""
    path = Path(path)
    roots = allowed_roots(path, list(search_paths))
    text = read_text_capped(path, what="description")
    if path.name.lower().endswith(".xacro") or "xmlns:xacro" in text[:4000]:
        text = _expand_xacro(path, roots)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputError(f"{path}: not valid XML ({e}); pass a URDF, xacro or MJCF file") from None
    if root.tag == "robot":
        desc = Description(path, "urdf", root, roots)
        _repair_urdf(desc)
    elif root.tag == "mujoco":
        desc = Description(path, "mjcf", root, roots)
    else:
        raise InputError(f"{path}: the root element is <{root.tag}>, not <robot> (URDF) or <mujoco> (MJCF)")
    desc.servo_models = _servo_models(desc)
    return desc


@contextmanager
def _confined_xacro(roots: list[Path], source: Path) -> Iterator[ModuleType]:
    """xacro with its file reads confined and capped, and ``$(find PKG)`` searched above the file (no ROS)."""
    try:
        import xacro
        from xacro import substitution_args
    except ImportError:
        raise MissingDependencyError(
            f"{source}: reading xacro needs the import extra: {install_command('import')}"
        ) from None
    parse, find, load_yaml = xacro.parse, substitution_args._eval_find, xacro.load_yaml

    def confined_parse(inp: str | None, filename: str | None = None) -> Any:
        if inp is None:
            assert filename is not None  # xacro names the file whenever it passes no text
            real = confined(Path(filename), roots, "xacro include", source)
            inp = read_text_capped(real, what="xacro include")
        return parse(inp, filename)

    def confined_find(pkg: str) -> str:
        found = find_package(pkg, roots)
        if found is None:
            raise InputError(f"{source}: $(find {pkg}): no folder {pkg!r} in or above the description; "
                             "name the folder that holds it with --search-path DIR")  # fmt: skip
        return str(found)

    def confined_yaml(filename: str) -> Any:
        confined(Path(xacro.abs_filename_spec(filename)), roots, "xacro yaml file", source)
        return load_yaml(filename)

    xacro.parse, substitution_args._eval_find, xacro.load_yaml = confined_parse, confined_find, confined_yaml
    try:
        yield xacro
    finally:
        xacro.parse, substitution_args._eval_find, xacro.load_yaml = parse, find, load_yaml


def _expand_xacro(path: Path, roots: list[Path]) -> str:
    import contextlib
    import io

    with _confined_xacro(roots, path) as xacro:
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err):
                doc = xacro.process_file(str(path))
        except InputError:
            raise
        except Exception as e:  # xacro raises XacroException, NameError, ExpatError... for a broken file
            inner: BaseException | None = e
            while inner is not None and not isinstance(inner, InputError):  # ours, wrapped by xacro
                inner = getattr(inner, "exc", None) or inner.__cause__ or inner.__context__
            if inner is not None:
                raise inner from None
            raise InputError(
                f"{path}: xacro cannot expand it: {' '.join(str(e).split()) or type(e).__name__}"
            ) from None
    expanded: str = doc.toxml()
    return expanded


def _limit(j: ET.Element) -> ET.Element:
    lim = j.find("limit")
    return lim if lim is not None else ET.SubElement(j, "limit")


def _num(el: ET.Element, key: str, default: float) -> float:
    try:
        v = float(el.get(key, default))
    except ValueError:
        return default
    return v if math.isfinite(v) else default


def _repair_urdf(desc: Description) -> None:
    """Repairs, one warning each; the joint kinds MuJoCo cannot drive are welded."""
    root, warn = desc.root, desc.warnings.append
    dropped = [el for el in list(root) if el.tag in ("gazebo", "transmission", "ros2_control")]
    for el in dropped:
        root.remove(el)
    if dropped:
        warn(f"{len(dropped)} gazebo/transmission/ros2_control elements ignored (simulator plugins)")
    fixed = _JointRepairs()
    for j in root.iter("joint"):
        name = j.get("name", "?")
        _repair_kind(desc, j, name, fixed)
        if j.get("type") == "revolute":
            _repair_limits(j, name, fixed, warn)
    if fixed.reversed:
        warn(f"joints {fixed.reversed} have lower above upper (a reversed servo range?): the two are swapped")
    if fixed.no_velocity:
        warn(f"joints {fixed.no_velocity} give no velocity limit: sized as an STS3215 (4.72 rad/s)")
    if fixed.welded:
        warn(f"prismatic/planar joints {fixed.welded} (grippers?) welded in place: robogest drives hinges only")
    if desc.floating:
        warn("the base floats (a floating joint): it stands welded at standing height, feet on the floor")
    light = [lk for link in root.iter("link") if (lk := _repair_inertial(link)) is not None]
    if light:
        warn(
            f"links {light} have zero mass or zero inertia: given a small one (the sim needs it; retargeting does not)"
        )


@dataclass
class _JointRepairs:
    """Joints :func:`_repair_urdf` changed, by what it did (told in one warning each)."""

    reversed: list[str] = field(default_factory=list)  # lower above upper: swapped
    no_velocity: list[str] = field(default_factory=list)  # sized as the default servo
    no_effort: list[str] = field(default_factory=list)  # effort set to 0 (sized later)
    welded: list[str] = field(default_factory=list)  # prismatic/planar made fixed


def _repair_kind(desc: Description, j: ET.Element, name: str, fixed: _JointRepairs) -> None:
    """A continuous joint becomes a revolute one of one turn (warned at once); a floating one makes the base float
    (welded standing later); prismatic and planar joints are welded (robogest drives hinges only)."""
    kind = j.get("type")
    if kind == "continuous":
        j.set("type", "revolute")
        lim = _limit(j)
        lim.set("lower", f"{-math.pi:.9f}")
        lim.set("upper", f"{math.pi:.9f}")
        desc.warnings.append(f"continuous joint {name!r}: limited to one turn [-pi, pi]")
    elif kind == "floating":
        desc.floating = True
        j.set("type", "fixed")
    elif kind in ("prismatic", "planar"):
        j.set("type", "fixed")
        fixed.welded.append(name)


def _repair_limits(j: ET.Element, name: str, fixed: _JointRepairs, warn: Callable[[str], None]) -> None:
    """A revolute joint's ``<limit>``: a reversed range swapped, an empty one widened to [-pi/2, pi/2] (warned at
    once), and a missing velocity or effort noted (the servo sizing fills them in)."""
    lim = _limit(j)
    lo, hi = _num(lim, "lower", 0.0), _num(lim, "upper", 0.0)
    if lo > hi:
        lim.set("lower", repr(hi))
        lim.set("upper", repr(lo))
        fixed.reversed.append(name)
    elif lo == hi:
        lim.set("lower", "-1.5707963")
        lim.set("upper", "1.5707963")
        warn(f"joint {name!r} has no range (lower = upper = {lo:g}): given [-pi/2, pi/2]; check it")
    if _num(lim, "velocity", 0.0) <= 0:
        fixed.no_velocity.append(name)
    if _num(lim, "effort", 0.0) <= 0:
        lim.set("effort", "0")
        fixed.no_effort.append(name)


def _repair_inertial(link: ET.Element) -> str | None:
    """A link's ``<inertial>`` without mass removed (MuJoCo gives a massless link a small mass of its own), one
    without a positive inertia given a small one; the link's name if either was done, else None."""
    inertial = link.find("inertial")
    if inertial is None:
        return None
    mass = inertial.find("mass")
    if mass is None or _num(mass, "value", 0.0) <= 0:
        link.remove(inertial)
        return link.get("name", "?")
    inertia = inertial.find("inertia")
    if inertia is not None and min(_num(inertia, k, 0.0) for k in ("ixx", "iyy", "izz")) > 0:
        return None
    if inertia is not None:
        inertial.remove(inertia)
    m = _num(mass, "value", 0.01)
    ET.SubElement(inertial, "inertia", ixx=f"{m * 1e-4:g}", iyy=f"{m * 1e-4:g}", izz=f"{m * 1e-4:g}",
                  ixy="0", ixz="0", iyz="0")  # fmt: skip
    return link.get("name", "?")


def _servo_models(desc: Description) -> dict[str, str]:
    """Servo models named near each joint: in the joint's or its child link's name, its meshes, or a
    ``<transmission>`` naming it (URDF); the family is the first word list that matches."""
    found: dict[str, str] = {}
    text_of: dict[str, str] = {}
    if desc.kind == "urdf":
        links = {ln.get("name"): ln for ln in desc.root.iter("link")}
        for j in desc.root.iter("joint"):
            child = j.find("child")
            link = links.get(child.get("link")) if child is not None else None
            own = [] if link is None else [link.get("name", ""), *(m.get("filename", "") for m in link.iter("mesh"))]
            text_of[j.get("name", "")] = " ".join([j.get("name", ""), *own])
    else:
        for body in desc.root.iter("body"):
            for j in body.findall("joint"):
                text_of[j.get("name", "")] = " ".join([j.get("name", ""), body.get("name", "")]
                                                      + [g.get("mesh", "") for g in body.findall("geom")])  # fmt: skip
    for jn, text in text_of.items():
        for family, pat in SERVO_WORDS.items():
            m = pat.search(text)
            if m:
                found[jn] = f"{family}:{m.group(1).upper().replace('_', '-')}"
                break
    return found
