"""Mesh files of a description: found (``package://``, ``file://``, relative; names matched case-insensitively),
confined to the description's tree, converted once where MuJoCo cannot read them (DAE, PLY, GLB: trimesh), and
copied into the robot's ``assets/`` folder with the user's umask, never broader than the source's permissions."""

from __future__ import annotations

import os
import re
import stat
import xml.etree.ElementTree as ET
from pathlib import Path

from robogest.errors import InputError, MissingDependencyError
from robogest.extras import install_command
from robogest.fileio import read_bytes_capped
from robogest.tools.importer.description import Description, confined, find_package

#: Formats MuJoCo reads itself; others are converted to STL at import.
MUJOCO_MESHES = (".stl", ".obj", ".msh")
CONVERTIBLE = (".dae", ".ply", ".glb", ".gltf", ".off")
#: Largest mesh file copied, bytes (a detailed visual mesh is a few MB).
MAX_MESH_BYTES = 256 * 1024**2


def _candidates(ref: str, desc: Description, base: Path) -> list[Path]:
    """Where a reference may point: ``package://PKG/rest`` in the package PKG (searched in the description's
    tree and the search paths), else below the tree; ``file://`` and plain paths as written, relative to ``base``."""
    if ref.startswith("package://"):
        rel = ref[len("package://") :]
        pkg, _, rest = rel.partition("/")
        if pkg == "" and rest:  # package:///meshes/x.stl (CAD exporters): the description's own package
            return [base / rest] + [r / rest for r in desc.roots]
        if pkg in (".", "..") or not rest:
            raise InputError(f"{desc.path}: mesh {ref!r}: {pkg!r} is not a package name; write package://PKG/PATH")
        found = find_package(pkg, desc.roots)
        out = [found / rest] if found else []
        # descriptions often write package://meshes/x.stl for a folder meshes/ of their own tree
        return out + [r / rel for r in desc.roots] + [r / rest for r in desc.roots]
    path = Path(ref[len("file://") :] if ref.startswith("file://") else ref)
    return [path] if path.is_absolute() else [base / path]


def _case_insensitive(path: Path) -> Path | None:
    """``path`` with each missing component matched to a differently cased name in its folder (``.STL``)."""
    if path.exists():
        return path
    parent = _case_insensitive(path.parent) if path.parent != path else None
    if parent is None or not parent.is_dir():
        return None
    want = path.name.lower()
    try:
        return next((p for p in parent.iterdir() if p.name.lower() == want), None)
    except OSError:
        return None


def resolve(ref: str, desc: Description, base: Path, recased: list[str]) -> Path:
    """The confined, existing file a mesh reference names; InputError when it is missing or outside the tree."""
    cands = _candidates(ref, desc, base)
    for c in cands:
        if os.path.lexists(c):
            return confined(c, desc.roots, "mesh", desc.path)
    for c in cands:
        found = _case_insensitive(c)
        if found is not None:
            recased.append(ref)
            return confined(found, desc.roots, "mesh", desc.path)
    raise InputError(
        f"{desc.path}: mesh {ref!r} not found in the description's folders; put the meshes there (or name their "
        "folder with --search-path DIR)"
    )


def _write_copy(dst: Path, data: bytes, src: Path) -> None:
    """Write a new file with the user's umask and at most the source's read/write permissions (a root-only file
    never comes out world-readable)."""
    mask = os.umask(0)
    os.umask(mask)
    fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~mask & stat.S_IMODE(os.stat(src).st_mode))
    with os.fdopen(fd, "wb") as out:
        out.write(data)


def copy_confined(src: Path, dst: Path) -> None:
    """Copy a regular mesh file of at most :data:`MAX_MESH_BYTES` (:func:`_write_copy`)."""
    _write_copy(dst, read_bytes_capped(src, MAX_MESH_BYTES, what="mesh"), src)


def convert(src: Path, dst: Path) -> None:
    """A mesh MuJoCo cannot read (COLLADA, PLY, glTF) as binary STL, once, with trimesh (pycollada for DAE)."""
    try:
        import trimesh
    except ImportError:
        raise MissingDependencyError(
            f"mesh {src.name}: converting {src.suffix} meshes needs the import extra: {install_command('import')}"
        ) from None
    read_bytes_capped(src, MAX_MESH_BYTES, what="mesh")  # a regular file of a sane size, before trimesh opens it
    try:
        data = trimesh.load(str(src), force="mesh").export(None, file_type="stl")  # None: return the bytes
    except MemoryError:
        raise
    except Exception as e:  # trimesh and pycollada raise many kinds for a broken file
        raise InputError(
            f"mesh {src}: cannot convert it to STL ({type(e).__name__}: {e}); convert it yourself"
        ) from None
    _write_copy(dst, data, src)


def _refs(desc: Description) -> list[tuple[ET.Element, str, Path]]:
    """(element, attribute, folder it is relative to) for every file a description names."""
    folder = desc.path.resolve().parent
    if desc.kind == "urdf":
        return [(m, "filename", folder) for m in desc.root.iter("mesh")]
    comp = desc.root.find("compiler")
    asset = Path(comp.get("assetdir", "")) if comp is not None else Path()
    dirs = {
        tag: folder / (Path(comp.get(key, "")) if comp is not None and comp.get(key) else asset)
        for tag, key in (("mesh", "meshdir"), ("texture", "texturedir"), ("hfield", "assetdir"), ("skin", "meshdir"))
    }
    return [(el, "file", dirs[tag]) for tag in dirs for el in desc.root.iter(tag) if el.get("file")]


def stage_meshes(desc: Description, assets: Path) -> int:
    """Copy (or convert) every file the description names into ``assets`` and point the references at the copies
    (by bare name: the model's ``meshdir``/``texturedir`` is ``assets``). Returns how many files."""
    recased: list[str] = []
    staged: dict[Path, str] = {}
    converted = []
    for el, key, base in _refs(desc):
        ref = el.get(key, "")
        if desc.kind == "mjcf" and el.tag in ("mesh", "hfield", "skin") and not el.get("name"):
            el.set("name", Path(ref).stem)  # MuJoCo names an asset after its file; the copy's name differs
        src = resolve(ref, desc, base, recased)
        name = staged.get(src)
        if name is None:
            suffix = src.suffix.lower()
            stem = re.sub(r"[^A-Za-z0-9_.-]", "_", src.stem)
            if el.tag == "mesh" and suffix in CONVERTIBLE:
                name = f"{len(staged):03d}_{stem}.stl"
                assets.mkdir(parents=True, exist_ok=True)
                convert(src, assets / name)
                converted.append(src.name)
            elif el.tag == "mesh" and suffix not in MUJOCO_MESHES:
                raise InputError(f"{desc.path}: mesh {src.name}: MuJoCo reads STL and OBJ, robogest converts "
                                 f"{', '.join(CONVERTIBLE)}; convert {suffix} yourself")  # fmt: skip
            else:
                name = f"{len(staged):03d}_{stem}{suffix}"
                assets.mkdir(parents=True, exist_ok=True)
                copy_confined(src, assets / name)
            staged[src] = name
        el.set(key, name)
    if recased:
        desc.warnings.append(
            f"{len(recased)} mesh names differ in case from the files (e.g. {recased[0]!r}): matched ignoring case"
        )
    if converted:
        desc.warnings.append(f"meshes {sorted(set(converted))[:4]}... converted to STL once, at import (trimesh)")
    return len(staged)
