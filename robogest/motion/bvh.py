"""BVH import and export.

:func:`load_bvh_raw` reads any BVH skeleton as-is (metres, Y or Z up as written); :func:`load_bvh` also maps it onto
:data:`~robogest.motion.skeleton.CANONICAL` (see :mod:`robogest.motion.mapping`); :func:`save_bvh` writes a motion
in centimetres, the unit most BVH tools (Blender, MotionBuilder, the GENEA/BEAT tools) expect.

BVH conventions implemented here: a joint's ``CHANNELS`` may list position and rotation channels in any order;
rotation channels ``Zrotation Xrotation Yrotation`` mean the local rotation matrix ``Rz @ Rx @ Ry`` (intrinsic
rotations in the listed order), angles in degrees; a position channel replaces that component of the joint's
``OFFSET`` (the Blender reading).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robogest.errors import InputError
from robogest.fileio import atomic_path
from robogest.motion import rotations as R
from robogest.motion.human_motion import HumanMotion, check_take
from robogest.motion.skeleton import Skeleton

#: File centimetres per metre used by :func:`save_bvh`.
BVH_EXPORT_UNITS_PER_M = 100.0
_AXES = "XYZ"
#: Frame times accepted, seconds (1 to 1000 frames per second); others are typos or unit mix-ups.
FRAME_TIME_RANGE_S = (1e-3, 1.0)
#: Largest BVH read, bytes, and largest frames x joints it may expand to (1 h at 120 fps of 100 joints is 4.3e7),
#: checked before the arrays are allocated.
MAX_BVH_BYTES = 2 * 1024**3
MAX_FRAME_JOINTS = 60_000_000


@dataclass
class BvhData:
    """Everything a BVH file says, in metres; kept for the canonical mapping, which needs more than a ``HumanMotion``.

    Attributes
    ----------
    motion : HumanMotion
        Source skeleton (root offset zero) with local rotations; ``root_pos_m`` is the root joint's world position.
    translations_m : ndarray [shape=(T, J, 3)], metres
        Per-frame local translation of every joint (the ``OFFSET`` with any position channels substituted).
    end_sites_m : dict of int to ndarray [shape=(3,)], metres
        ``End Site`` offset per joint index that has one.
    scale : float
        Metres per file unit that was applied.
    """

    motion: HumanMotion
    translations_m: np.ndarray
    end_sites_m: dict[int, np.ndarray]
    scale: float


def _err(path: Path, msg: str, fix: str) -> InputError:
    return InputError(f"{path}: {msg}. {fix}")


def _read_lines(path: Path) -> list[str]:
    if not path.is_file():
        raise InputError(f"{path}: no such BVH file. Check the path.")
    size = path.stat().st_size
    if size > MAX_BVH_BYTES:
        raise _err(path, f"{size / 1024**3:.1f} GiB is larger than the {MAX_BVH_BYTES / 1024**3:.0f} GiB robogest "
                   "reads", "Split the take into shorter files")  # fmt: skip
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e}). Check the file permissions.") from None
    return text.splitlines()


def _float(tok: str, path: Path, line_no: int) -> float:
    try:
        return float(tok)
    except ValueError:
        raise _err(path, f"line {line_no}: {tok!r} is not a number", "Repair or re-export the file") from None


def _count(tok: str, path: Path, line_no: int) -> int:
    """A whole number >= 0 (a frame or channel count); a huge or fractional one is one line, not an OverflowError."""
    v = _float(tok, path, line_no)
    if not (0 <= v < 2**53 and v == int(v)):
        shown = tok if len(tok) <= 20 else f"{tok[:10]}...({len(tok)} characters)"
        raise _err(path, f"line {line_no}: {shown} is not a count", "Repair or re-export the file")
    return int(v)


@dataclass
class _Hierarchy:
    """The ``HIERARCHY`` section read so far, one line at a time (:func:`_parse_hierarchy`).

    ``stack`` holds the open ``{`` blocks: a joint index, or ``"end"`` inside an End Site; ``pending`` is the
    joint (or End Site) whose ``{`` comes next.
    """

    path: Path
    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)  # file units, one (x, y, z) per joint
    channels: list[list[str]] = field(default_factory=list)
    end_sites: dict[int, list[float]] = field(default_factory=dict)  # joint -> its End Site offset
    stack: list[int | str] = field(default_factory=list)
    pending: int | str | None = None

    def bad(self, ln: int, msg: str) -> InputError:
        return _err(self.path, f"line {ln}: {msg}", "Repair or re-export the file")

    def read_line(self, toks: list[str], ln: int) -> None:
        """One non-empty line of the section (its keyword not ``MOTION``)."""
        kw = toks[0].upper()
        if kw == "HIERARCHY":
            return
        if kw in ("ROOT", "JOINT"):
            self.open_joint(toks, ln)
            toks = toks[2:]
        elif kw == "END":
            if not self.stack:
                raise self.bad(ln, "End Site outside a joint")
            self.pending = "end"
            toks = toks[2:]
        elif kw == "OFFSET":
            self.offset(toks, ln)
            return
        elif kw == "CHANNELS":
            self.channel_list(toks, ln)
            return
        self.braces(toks, ln)  # possibly on the same line as ROOT/JOINT/End Site

    def open_joint(self, toks: list[str], ln: int) -> None:
        """``ROOT name`` (only outside every block) or ``JOINT name`` (only inside a joint)."""
        if len(toks) < 2:
            raise self.bad(ln, f"{toks[0]} without a name")
        if (toks[0].upper() == "ROOT") != (not self.stack) or (self.stack and self.stack[-1] == "end"):
            raise self.bad(ln, f"{toks[0]} {toks[1]} is misplaced")
        self.names.append(toks[1])
        self.parents.append(int(self.stack[-1]) if self.stack else -1)
        self.offsets.append([0.0, 0.0, 0.0])
        self.channels.append([])
        self.pending = len(self.names) - 1

    def offset(self, toks: list[str], ln: int) -> None:
        """``OFFSET x y z`` of the innermost joint or End Site."""
        if len(toks) < 4 or not self.stack:
            raise self.bad(ln, "OFFSET needs 3 numbers inside a joint")
        vals = [_float(t, self.path, ln) for t in toks[1:4]]
        top = self.stack[-1]
        if top == "end":
            self.end_sites[int(self.stack[-2])] = vals
        else:
            self.offsets[int(top)] = vals

    def channel_list(self, toks: list[str], ln: int) -> None:
        """``CHANNELS n name...`` of the innermost joint: n names, each an axis and position/rotation."""
        if len(toks) < 2 or not self.stack or self.stack[-1] == "end":
            raise self.bad(ln, "CHANNELS outside a joint")
        n = _count(toks[1], self.path, ln)
        chans = [c.capitalize() for c in toks[2 : 2 + n]]
        bad = [c for c in chans if len(c) != 9 or c[0] not in _AXES or c[1:] not in ("position", "rotation")]
        if len(chans) != n or bad:
            raise self.bad(ln, f"bad CHANNELS list {toks[2:]}")
        self.channels[int(self.stack[-1])] = chans

    def braces(self, toks: list[str], ln: int) -> None:
        """``{`` opens the pending joint's block, ``}`` closes the innermost; anything else is an error."""
        for t in toks:
            if t == "{":
                if self.pending is None:
                    raise self.bad(ln, "unexpected '{'")
                self.stack.append(self.pending)
                self.pending = None
            elif t == "}":
                if not self.stack:
                    raise self.bad(ln, "unbalanced '}'")
                self.stack.pop()
            else:
                raise self.bad(ln, f"unexpected {t!r} in HIERARCHY")


def _parse_hierarchy(lines: list[str], path: Path) -> tuple[_Hierarchy, int]:
    """The skeleton (joint names, parents, file-unit offsets, channel names, end sites) and the index of the
    ``MOTION`` line."""
    first = next((ln.strip() for ln in lines if ln.strip()), "")
    if first.upper() != "HIERARCHY":
        raise _err(path, "not a BVH file (it does not start with HIERARCHY)", "Pass a .bvh motion-capture file")
    h = _Hierarchy(path)
    motion_line = -1
    for i, line in enumerate(lines):
        toks = line.split()
        if not toks:
            continue
        if toks[0].upper() == "MOTION":
            motion_line = i
            break
        h.read_line(toks, i + 1)
    if not h.names:
        raise _err(path, "no ROOT joint in HIERARCHY", "Repair or re-export the file")
    if motion_line < 0:
        raise _err(path, "no MOTION section", "The file is truncated; re-export it")
    if h.stack:
        raise _err(path, "unbalanced braces in HIERARCHY", "Repair or re-export the file")
    return h, motion_line


def _parse_motion(lines: list[str], start: int, n_channels: int, n_joints: int, path: Path) -> tuple[np.ndarray, float]:
    """Frame values ``(T, C)`` in file units/degrees and the frame time in seconds."""
    header: dict[str, tuple[str, int]] = {}
    i = start + 1
    while i < len(lines) and len(header) < 2:
        s = lines[i].strip()
        if s:
            key, _, val = s.partition(":")
            key = " ".join(key.split()).lower()
            if key not in ("frames", "frame time"):
                raise _err(path, f"line {i + 1}: expected 'Frames:' and 'Frame Time:'", "Repair or re-export the file")
            header[key] = (val.strip(), i + 1)
        i += 1
    if len(header) < 2:
        raise _err(path, "MOTION section lacks 'Frames:' or 'Frame Time:'", "The file is truncated; re-export it")
    n_frames = _count(header["frames"][0], path, header["frames"][1])
    frame_time = _float(header["frame time"][0], path, header["frame time"][1])
    lo, hi = FRAME_TIME_RANGE_S
    if not lo <= frame_time <= hi:
        raise _err(
            path,
            f"Frame Time {frame_time:g} s is outside {lo:g}..{hi:g} s (1 to 1000 frames per second)",
            "Set the frame time in seconds (e.g. 0.0333333 for 30 fps)",
        )
    rows = [(j + 1, ln) for j, ln in enumerate(lines[i:], start=i) if ln.strip()]
    if n_frames <= 0:
        raise _err(path, "the file has no frames", "Export at least one frame")
    check_take(n_frames, 1.0 / frame_time, str(path))
    if len(rows) != n_frames:
        raise _err(
            path,
            f"frame count mismatch: the header says Frames: {n_frames} but {len(rows)} data lines follow",
            "Fix the 'Frames:' line or re-export the file",
        )
    if n_frames * max(1, n_joints) > MAX_FRAME_JOINTS:
        raise _err(
            path,
            f"{n_frames} frames x {n_joints} joints is more than the {MAX_FRAME_JOINTS:.0e} robogest reads at once",
            "Split the take into shorter files",
        )
    data = np.empty((n_frames, n_channels))  # (T, C); filled row by row so no token list of the whole file is built
    for k, (ln, line) in enumerate(rows):
        t = line.split()
        if len(t) != n_channels:
            raise _err(
                path,
                f"line {ln}: {len(t)} values but the HIERARCHY declares {n_channels} channels",
                "Repair or re-export the file",
            )
        try:
            data[k] = np.array(t, dtype=np.float64)
        except ValueError:
            for v in t:
                _float(v, path, ln)
            raise  # pragma: no cover - one token above must have failed
    if not np.isfinite(data).all():
        bad = int(np.argwhere(~np.isfinite(data))[0, 0])
        raise _err(path, f"line {rows[bad][0]}: non-finite value", "Repair or re-export the file")
    return data, frame_time


def _fps(frame_time: float) -> float:
    """Frame rate, snapped to the nearest integer when the frame time was printed with few digits (0.03333)."""
    fps = 1.0 / frame_time
    return float(round(fps)) if abs(fps - round(fps)) < 5e-4 * fps else fps


def rest_positions(skeleton: Skeleton) -> np.ndarray:
    """Rest-pose joint positions ``(J, 3)`` (same unit as the offsets), root at the origin."""
    pos = np.zeros((skeleton.n_joints, 3))
    for j, p in enumerate(skeleton.parents):
        pos[j] = skeleton.offsets_m[j] + (pos[p] if p >= 0 else 0.0)
    return pos


def _detect_scale(offsets: np.ndarray, parents: list[int], end_sites: dict) -> float:
    """Metres per file unit from the rest-pose size: up to 5 units → metres, up to 500 → cm, else mm."""
    pos = rest_positions(Skeleton(tuple(str(i) for i in range(len(parents))), tuple(parents), offsets))
    pts = np.vstack([pos, *[pos[j] + np.asarray(o) for j, o in end_sites.items()]])
    size = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    if size <= 5.0:
        return 1.0
    return 0.01 if size <= 500.0 else 0.001


def read_bvh(path: str | os.PathLike, scale: float | None = None) -> BvhData:
    """Parse a BVH file into a :class:`BvhData` (source skeleton, metres).

    Parameters
    ----------
    path : path-like
    scale : float, optional
        Metres per file unit (0.01 for centimetres). Default: guessed from the rest-pose size.
    """
    path = Path(path)
    lines = _read_lines(path)
    h, motion_line = _parse_hierarchy(lines, path)
    names, parents, offsets_l, channels, end_l = h.names, h.parents, h.offsets, h.channels, h.end_sites
    n_ch = sum(len(c) for c in channels)
    data, frame_time = _parse_motion(lines, motion_line, n_ch, len(names), path)
    offsets = np.array(offsets_l, dtype=np.float64)  # (J, 3) file units
    if scale is None:
        scale = _detect_scale(offsets, parents, end_l)
    if not scale > 0:
        raise InputError(f"{path}: scale must be positive metres per file unit, got {scale}")
    n_frames, n_joints = data.shape[0], len(names)
    rot = np.empty((n_frames, n_joints, 4))
    trans = np.broadcast_to(offsets, (n_frames, n_joints, 3)).copy()  # (T, J, 3) file units
    rot[:] = R.IDENTITY
    by_order: dict[str, tuple[list[int], list[np.ndarray]]] = {}  # rotation order -> (joints, their 3 columns)
    col = 0
    for j, chans in enumerate(channels):
        cols = np.arange(col, col + len(chans))
        col += len(chans)
        rot_idx = [k for k, c in enumerate(chans) if c.endswith("rotation")]
        for k, c in enumerate(chans):
            if c.endswith("position"):
                trans[:, j, _AXES.index(c[0])] = data[:, cols[k]]
        if not rot_idx:
            continue
        order = "".join(chans[k][0] for k in rot_idx)
        if len(order) != 3 or len(set(order)) != 3:
            raise _err(path, f"joint {names[j]!r}: rotation channels {order} are not a permutation of XYZ", "Re-export")
        joints, col_lists = by_order.setdefault(order, ([], []))
        joints.append(j)
        col_lists.append(cols[rot_idx])
    for order, (joints, col_lists) in by_order.items():
        ang = np.deg2rad(data[:, np.stack(col_lists)])  # (T, J_order, 3) radians
        rot[:, joints] = R.from_euler(order, ang)
    trans *= scale
    offsets_m = offsets * scale
    offsets_m[0] = 0.0  # the root's world position lives in root_pos_m
    skeleton = Skeleton(tuple(names), tuple(parents), offsets_m)
    motion = HumanMotion(fps=_fps(frame_time), rotations=rot, root_pos_m=trans[:, 0].copy(), skeleton=skeleton)
    end_sites = {j: np.asarray(o, dtype=np.float64) * scale for j, o in end_l.items()}
    return BvhData(motion=motion, translations_m=trans, end_sites_m=end_sites, scale=float(scale))


def load_bvh_raw(path: str | os.PathLike, scale: float | None = None) -> HumanMotion:
    """BVH motion on its own skeleton (metres), not mapped to the canonical one.

    Position channels of non-root joints are not kept (the skeleton's offsets are used); the root's are.
    """
    return read_bvh(path, scale).motion


def load_bvh(
    path: str | os.PathLike, name_map: str | dict[str, str] | None = None, scale: float | None = None
) -> HumanMotion:
    """BVH motion mapped onto :data:`~robogest.motion.skeleton.CANONICAL`.

    Parameters
    ----------
    path : path-like
    name_map : str or dict, optional
        A key of :data:`~robogest.motion.mapping.NAME_MAPS` or a ``{canonical joint: source joint}`` dict.
        Default: detected from the joint names.
    scale : float, optional
        Metres per file unit; default guessed from the skeleton size (m, cm or mm).
    """
    from robogest.motion.mapping import map_bvh_to_canonical

    return map_bvh_to_canonical(read_bvh(path, scale), name_map=name_map, source=str(path))


def save_bvh(motion: HumanMotion, path: str | os.PathLike, order: str = "ZXY") -> None:
    """Write ``motion`` as BVH in centimetres (metres × :data:`BVH_EXPORT_UNITS_PER_M`), atomically.

    The root gets 6 channels (position, then rotation), every other joint 3 rotation channels in ``order``
    (``"ZXY"`` or ``"XYZ"``, any permutation works). Joints without children get an ``End Site`` half their own
    offset further along, so that Blender-style readers draw them with a length.
    """
    order = order.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise InputError(f"BVH rotation order must be a permutation of XYZ, got {order!r}")
    path = Path(path)
    sk = motion.skeleton
    u = BVH_EXPORT_UNITS_PER_M
    children: list[list[int]] = [[] for _ in range(sk.n_joints)]
    for j, p in enumerate(sk.parents):
        if p >= 0:
            children[p].append(j)
    rot_ch = " ".join(f"{a}rotation" for a in order)
    out: list[str] = ["HIERARCHY"]

    def write(j: int, depth: int) -> None:
        ind = "\t" * depth
        kw = "ROOT" if sk.parents[j] < 0 else "JOINT"
        off = sk.offsets_m[j] * u
        out.append(f"{ind}{kw} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        if sk.parents[j] < 0:
            out.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition {rot_ch}")
        else:
            out.append(f"{ind}\tCHANNELS 3 {rot_ch}")
        for c in children[j]:
            write(c, depth + 1)
        if not children[j]:
            end = 0.5 * off if np.linalg.norm(off) > 0 else np.array([0.0, 1.0, 0.0])
            out.extend([f"{ind}\tEnd Site", f"{ind}\t{{", f"{ind}\t\tOFFSET {end[0]:.6f} {end[1]:.6f} {end[2]:.6f}"])
            out.append(f"{ind}\t}}")
        out.append(f"{ind}}}")

    roots = [j for j, p in enumerate(sk.parents) if p < 0]
    if len(roots) != 1:
        raise InputError(f"cannot write {path}: BVH needs exactly one root joint, the skeleton has {len(roots)}")
    write(roots[0], 0)
    # BVH lists channels depth-first; order the joint columns the same way.
    dfs: list[int] = []
    stack = [roots[0]]
    while stack:
        j = stack.pop()
        dfs.append(j)
        stack.extend(reversed(children[j]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's gimbal-lock warning: the angles still reproduce the rotation
        eul = np.rad2deg(R.to_euler(order, motion.rotations[:, dfs]))  # (T, J, 3) degrees, depth-first joints
    root_cm = motion.root_pos_m * u  # (T, 3)
    frames = np.concatenate([root_cm, eul.reshape(motion.n_frames, -1)], axis=1)  # (T, 3 + 3J)
    out += ["MOTION", f"Frames: {motion.n_frames}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in frames)
    text = "\n".join(out) + "\n" + body + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
