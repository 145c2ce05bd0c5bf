"""Safe file handling: output paths checked before any work, atomic output files, size-capped ``.npz`` reading.

A crash, Ctrl-C or a full disk never leaves a half-written file behind, and an output never replaces a
folder, a device node, a FIFO or a socket (through a symlink or not): robogest writes regular files only.
"""

from __future__ import annotations

import os
import stat
import tempfile
import zipfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from robogest.errors import InputError, RobogestError

if TYPE_CHECKING:
    import numpy as np

#: Largest ``.npz`` robogest reads, bytes of array data once loaded (a trajectory of 24 h at 1 kHz for 32 joints
#: is 0.7 GB): a crafted header cannot make it allocate more than this.
MAX_NPZ_BYTES = 2 * 1024**3
#: Largest text file (robot description, calibration, transcript, YAML) robogest reads whole, bytes: far above any
#: real one (a 54-joint humanoid URDF is ~0.2 MB), far below what would exhaust memory.
MAX_TEXT_BYTES = 64 * 1024**2
#: Most an ``.npz`` member of over :data:`NPZ_RATIO_FROM_BYTES` may expand when decompressed: recorded numbers
#: deflate 1-10x; a member expanding more (zeros deflate about 1000x) is a decompression bomb (a 1.5 MB file
#: allocated 1.5 GiB and played).
MAX_NPZ_RATIO = 100
NPZ_RATIO_FROM_BYTES = 1024**2


def check_output_path(path: str | os.PathLike, what: str = "output") -> Path:
    """Refuse an output robogest cannot or must not write; returns the path to write (symlinks resolved).

    Checked without writing anything: the path is not a folder, not a device, FIFO or socket (itself or behind a
    symlink), not a read-only file, and its nearest existing folder is a writable folder (missing folders below it
    are created when the file is written). ``what`` names the path in messages (e.g. ``"--save"``).

    Raises
    ------
    InputError
        Naming ``what``, the path and the fix.
    """
    text = os.fspath(path)
    if not text:
        raise InputError(f"{what}: empty output path; give a file name")
    check_name_lengths(text, what)
    real = Path(os.path.realpath(text))  # follows symlinks and '..': a link is written through, not replaced
    via = f" (via the symlink {text})" if os.path.islink(text) else ""
    if real.exists():
        mode = real.stat().st_mode
        if stat.S_ISDIR(mode):
            raise InputError(f"{what} {text}: is a folder{via}; give a file name inside it")
        if not stat.S_ISREG(mode):
            raise InputError(
                f"{what} {text}: is a device, FIFO or socket{via}, not a regular file; robogest writes regular "
                "files only (it replaces them atomically); give a file path"
            )
        if not mode & 0o222 or not os.access(real, os.W_OK):  # the mode too: root may write a 0444 file
            raise InputError(f"{what} {text}: the file is read-only{via}; make it writable or choose another path")
    _check_no_folders_through_a_link(text, real.parent, what)
    _check_writable_folder(real.parent, what, text)
    return real


def check_name_lengths(path: str | os.PathLike, what: str = "file") -> None:
    """Refuse a path with a name longer than its file system allows (255 bytes on most), before any work: the
    operating system's own error came as a traceback from the first ``stat``."""
    text = os.fspath(path)
    folder = Path(os.path.abspath(text)).parent
    while not os.path.isdir(folder):  # isdir, not exists: a too-long name on the way is False, not an OSError
        folder = folder.parent
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    for part in Path(text).parts:
        n = len(os.fsencode(part))
        if n > name_max:
            short = part if len(part) <= 40 else part[:20] + "..." + part[-12:]
            raise InputError(
                f"{what} {short}: the name is {n} bytes long, more than the {name_max} this file system allows; "
                "choose a shorter name"
            )


def _check_no_folders_through_a_link(text: str, folder: Path, what: str) -> None:
    """Missing folders of an output are made only where the path, as written, puts them: never through a symlink
    (a dangling link to ``/nonexistent/dir/x`` made ``/nonexistent/dir``). ``folder`` is the resolved parent."""
    if folder.exists():
        return
    written = Path(os.path.abspath(text)).parent
    missing: list[str] = []
    while not written.exists():
        missing.append(written.name)
        written = written.parent
    if folder != Path(os.path.realpath(written)).joinpath(*reversed(missing)):
        raise InputError(
            f"{what} {text}: goes through a symlink to {folder}, which does not exist; robogest makes no folder "
            "through a symlink: create the folder or give another path"
        )


def check_output_dir(path: str | os.PathLike, what: str = "output folder") -> Path:
    """Like :func:`check_output_path` for an output folder: it exists as a writable folder or can be created."""
    text = os.fspath(path)
    if not text:
        raise InputError(f"{what}: empty folder path; give a folder name")
    real = Path(os.path.realpath(text))
    if real.exists() and not real.is_dir():
        raise InputError(f"{what} {text}: is a file, not a folder; give a folder path")
    _check_writable_folder(real, what, text)
    return real


def to_jsonable(obj: object) -> object:
    """Arrays to lists, numpy scalars to Python, NaN/inf to None (strict JSON has no NaN), through dicts and lists."""
    import math

    import numpy as np

    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def check_output_parent(path: str | os.PathLike, what: str = "output") -> None:
    """The folder ``path`` (a file or a folder to be made) would go in is one robogest may write in, or can be
    made: no file stands where a folder must be. InputError naming ``what`` otherwise."""
    text = os.fspath(path)
    _check_writable_folder(Path(os.path.realpath(text)).parent, what, text)


def _check_writable_folder(folder: Path, what: str, text: str) -> None:
    """The nearest existing folder at or above ``folder`` is a folder robogest may write in."""
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"{what} {text}: {folder} is a file, not a folder; choose another path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what} {text}: the folder {folder} is not writable; choose another path")


def write_error(path: str | os.PathLike, exc: OSError) -> RobogestError:
    """One line for an output that failed while being written (disk full, I/O error); nothing was left behind."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    return RobogestError(
        f"{os.fspath(path)}: cannot write ({reason}); nothing was written, free space or choose another path"
    )


def publish(tmp: Path, path: Path) -> None:
    """Give a finished temporary file ordinary permissions (0666 minus the umask; mkstemp makes 0600) and
    move it over ``path`` atomically. For writers that cannot live inside :func:`atomic_path`.

    ``path`` is checked again (:func:`check_output_path`) as the last line of defence: a folder, device node,
    FIFO or socket is never replaced, and a symlink is written through.
    """
    real = check_output_path(path)
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(tmp, 0o666 & ~mask)
    os.replace(tmp, real)


def temp_prefix(name: str) -> str:
    """Prefix of a hidden temporary file beside the output ``name``: short enough that a name at the file system's
    limit still leaves room for the random part and the suffix."""
    return f".{name[:64]}."


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """A temporary path beside ``path``; on success it replaces ``path``, on any exception it is removed.

    The temporary name ends in ``suffix`` (``".npz"``, ``".png"``...) for writers that pick the format
    from the name. The result gets ordinary permissions (0666 minus the umask), not mkstemp's 0600.
    A symlink is written through (its target is replaced, the link stays); a folder, device node, FIFO or socket
    is refused (:func:`check_output_path`), so ``/dev/null`` is never replaced by a regular file. An OSError
    while writing (disk full) becomes one :class:`RobogestError` line naming ``path``.
    """
    real = check_output_path(path)
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=temp_prefix(real.name), suffix=suffix or ".tmp", dir=real.parent)
    except OSError as e:
        raise write_error(path, e) from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        publish(tmp, real)
    except OSError as e:
        raise write_error(path, e) from None
    finally:
        tmp.unlink(missing_ok=True)


def npz_keys(path: str | os.PathLike, what: str = "") -> list[str]:
    """Names of the arrays in an ``.npz`` without loading any (to tell a trajectory from a motion file)."""
    label = f"{what} {os.fspath(path)}".strip()
    try:
        with zipfile.ZipFile(path) as zf:
            return [n[:-4] for n in zf.namelist() if n.endswith(".npy")]
    except (OSError, zipfile.BadZipFile) as e:
        raise InputError(f"{label}: not a readable .npz ({type(e).__name__}: {e})") from None


def read_npz(
    path: str | os.PathLike, max_bytes: int = MAX_NPZ_BYTES, what: str = "", keys: Iterable[str] | None = None
) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` (only those named in ``keys``, if given; the others are neither checked nor
    loaded), no pickled objects, checked for size before any is allocated.

    Each member's header is read first: its declared size must fit the bytes stored for it (a crafted header cannot
    ask for more memory than the file holds), it may expand at most :data:`MAX_NPZ_RATIO` times from its compressed
    size (a decompression bomb cannot either), and all arrays together must fit ``max_bytes``.

    Raises
    ------
    InputError
        Missing or unreadable file, pickled objects, or sizes over the cap; the message names the file.
    """
    import numpy as np

    p = Path(path)
    label = f"{what} {p}".strip()
    if not p.is_file():
        raise InputError(f"{label}: no such file")
    out: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(p) as zf:
            total = 0
            wanted = None if keys is None else {f"{k}.npy" for k in keys}
            for info in zf.infolist():
                if not info.filename.endswith(".npy") or (wanted is not None and info.filename not in wanted):
                    continue
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(f)
                    else:
                        shape, _, dtype = np.lib.format.read_array_header_2_0(f)
                nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if dtype.hasobject:
                    raise InputError(
                        f"{label}: array {info.filename[:-4]!r} holds pickled Python objects, which "
                        "robogest never loads (they can run code); save plain numeric arrays"
                    )
                if nbytes > info.file_size:
                    raise InputError(
                        f"{label}: array {info.filename[:-4]!r} declares {nbytes} bytes but the file "
                        f"holds {info.file_size}; the file is corrupt or crafted"
                    )
                if info.file_size > max(NPZ_RATIO_FROM_BYTES, MAX_NPZ_RATIO * info.compress_size):
                    raise InputError(
                        f"{label}: array {info.filename[:-4]!r} expands from {info.compress_size} to "
                        f"{info.file_size} bytes, more than the {MAX_NPZ_RATIO}x any recorded data compresses; "
                        "a decompression bomb? Save it uncompressed (np.savez)"
                    )
                total += nbytes
                if total > max_bytes:
                    raise InputError(
                        f"{label}: arrays larger than the {max_bytes / 1024**3:.1f} GiB robogest reads "
                        "from one .npz; split the file"
                    )
        with np.load(p, allow_pickle=False) as z:
            for k in z.files:
                if wanted is None or f"{k}.npy" in wanted:
                    out[k] = z[k]
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zipfile.LargeZipFile) as e:
        raise InputError(f"{label}: not a readable .npz ({type(e).__name__}: {e})") from None
    return out


def check_input_file(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES, what: str = "file") -> None:
    """Refuse, before reading, a file that is missing, not a regular file (``/dev/zero``, a FIFO) or larger than
    ``max_bytes`` (a 3 GB sparse file), for readers that open the file themselves. InputError naming the file."""
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError as e:
        raise InputError(f"{what} {p}: cannot read ({e.strerror or e})") from None
    _check_stat(st, p, max_bytes, what)


def _check_stat(st: os.stat_result, p: Path, max_bytes: int, what: str) -> None:
    if not stat.S_ISREG(st.st_mode):
        kind = what if what.endswith("file") else f"{what} file"
        raise InputError(f"{what} {p}: not a regular file; give the path of a {kind}")
    if st.st_size > max_bytes:
        raise InputError(
            f"{what} {p}: {st.st_size / 1024**2:.1f} MiB, larger than the {max_bytes / 1024**2:.0f} MiB "
            f"robogest reads as one {what}; is it the right file?"
        )


def read_bytes_capped(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES, what: str = "file") -> bytes:
    """The bytes of a regular file of at most ``max_bytes``, checked before reading (``/dev/zero``, a FIFO or
    a 3 GB sparse file are refused at once instead of read until memory runs out).

    Raises
    ------
    InputError
        Missing, not a regular file, larger than ``max_bytes`` or unreadable; the message names the file.
    """
    p = Path(path)
    check_input_file(p, max_bytes, what)  # before opening: opening a FIFO waits for a writer
    try:
        with open(p, "rb") as f:
            _check_stat(os.fstat(f.fileno()), p, max_bytes, what)  # the file opened, should the path have changed
            data = f.read(max_bytes + 1)
    except InputError:
        raise
    except OSError as e:
        raise InputError(f"{what} {p}: cannot read ({e.strerror or e})") from None
    if len(data) > max_bytes:  # grew while being read
        raise InputError(f"{what} {p}: larger than the {max_bytes / 1024**2:.0f} MiB robogest reads as one {what}")
    return data


def read_text_capped(path: str | os.PathLike, max_bytes: int = MAX_TEXT_BYTES, what: str = "file") -> str:
    """The UTF-8 text of a regular file of at most ``max_bytes`` (:func:`read_bytes_capped`).

    Raises
    ------
    InputError
        Missing, not a regular file, larger than ``max_bytes``, unreadable or not UTF-8; the message names the file.
    """
    data = read_bytes_capped(path, max_bytes, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(
            f"{what} {path}: not UTF-8 text (byte {e.start}); save it as UTF-8, or is it a binary file?"
        ) from None


def load_yaml(text: str) -> object:
    """YAML text -> Python objects (``yaml.safe_load``), refusing a key given twice in one mapping: PyYAML keeps
    the last one silently, so a limit written twice (or a servo's ``direction`` in an entry repeated below it)
    would take effect unseen. Raises ``yaml.YAMLError`` (a ``ConstructorError`` naming the key and line)."""
    import yaml

    class _NoDuplicates(yaml.SafeLoader):
        pass

    def mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict = {}
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    problem=f"key {key!r} given twice in one mapping (lines {seen[key]} and {line}); keep one"
                )
            seen[key] = line
        return loader.construct_mapping(node, deep)

    _NoDuplicates.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    try:
        return yaml.load(text, Loader=_NoDuplicates)
    except ValueError as e:  # an integer of over 4300 digits: Python refuses to convert it (a traceback otherwise)
        raise yaml.YAMLError(f"a number too long to read ({str(e).split(';')[0]})") from None
